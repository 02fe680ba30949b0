/* e57_pages.c — E57 file header and checksummed pages (e57_pages.h). */
#include "e57_pages.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#if defined(__x86_64__)
#include <nmmintrin.h>
#endif

static uint64_t rd64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

static uint32_t rd32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

void e57__crc32c_init(uint32_t table[256])
{
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++) c = c & 1 ? c >> 1 ^ 0x82F63B78u : c >> 1;
        table[i] = c;
    }
}

uint32_t e57__crc32c_table(const uint32_t table[256], const uint8_t *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) c = table[(c ^ p[i]) & 0xFF] ^ c >> 8;
    return c ^ 0xFFFFFFFFu;
}

#if defined(__x86_64__)
__attribute__((target("sse4.2"))) static uint32_t crc32c_hw(const uint8_t *p, size_t n)
{
    uint64_t c = 0xFFFFFFFFu;
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t w;
        memcpy(&w, p + i, 8);
        c = _mm_crc32_u64(c, w);
    }
    uint32_t c32 = (uint32_t)c;
    for (; i < n; i++) c32 = _mm_crc32_u8(c32, p[i]);
    return c32 ^ 0xFFFFFFFFu;
}
#endif

uint32_t e57_crc32c(const e57_file *f, const uint8_t *p, size_t n)
{
#if defined(__x86_64__)
    if (f->hw_crc) return crc32c_hw(p, n);
#endif
    return e57__crc32c_table(f->crc_table, p, n);
}

uint64_t e57_phys_advance(const e57_file *f, uint64_t phys, uint64_t len)
{
    uint64_t data = f->page - E57_CRC_BYTES;
    uint64_t page = phys / f->page, in = phys % f->page;
    if (len > UINT64_MAX - in) return UINT64_MAX;
    uint64_t logical = in + len; /* from the start of phys's page */
    uint64_t pages = logical / data;
    if (pages > UINT64_MAX - page || page + pages > (UINT64_MAX - data) / f->page)
        return UINT64_MAX;
    return (page + pages) * f->page + logical % data;
}

uint64_t e57_logical_room(const e57_file *f, uint64_t phys)
{
    if (phys >= f->size) return 0;
    uint64_t data = f->page - E57_CRC_BYTES;
    uint64_t in = phys % f->page;
    if (in >= data) return 0;
    uint64_t pages_after = (f->size - phys + in) / f->page; /* whole pages from phys's page */
    return pages_after * data - in;
}

/* read_pages: pages [first, first + count) into f->buf with pread. */
static int read_pages(e57_file *f, uint64_t first, uint64_t count, sd_err *err)
{
    size_t len = (size_t)(count * f->page), done = 0;
    while (done < len) {
        ssize_t g = pread(f->fd, f->buf + done, len - done, (off_t)(first * f->page + done));
        if (g < 0 && errno == EINTR) continue;
        if (g < 0)
            return sd_errf(err, SD_EIO, "%s: %s reading the page at physical offset %llu", f->path,
                           strerror(errno), (unsigned long long)(first * f->page + done));
        if (g == 0)
            return sd_errf(err, SD_ETRUNC,
                           "%s: the page at physical offset %llu is truncated: "
                           "the file ends at byte %llu",
                           f->path,
                           (unsigned long long)((first * f->page + done) / f->page * f->page),
                           (unsigned long long)(first * f->page + done));
        done += (size_t)g;
    }
    return 0;
}

/* check_page: the checksum of page p (its bytes at pg) against the one it stores. */
static int check_page(e57_file *f, uint64_t p, const uint8_t *pg, sd_err *err)
{
    uint64_t data = f->page - E57_CRC_BYTES;
    uint32_t want = (uint32_t)pg[data] << 24 | (uint32_t)pg[data + 1] << 16 |
        (uint32_t)pg[data + 2] << 8 | pg[data + 3];
    uint32_t got = e57_crc32c(f, pg, (size_t)data);
    f->pages_checked++;
    if (got != want)
        return sd_errf(err, SD_EFORMAT,
                       "%s: bad checksum in the page at physical offset %llu "
                       "(stored 0x%08x, computed CRC-32C 0x%08x): the file is damaged",
                       f->path, (unsigned long long)(p * f->page), want, got);
    return 0;
}

int e57_file_read(e57_file *f, uint64_t phys, void *out, size_t len, sd_err *err)
{
    uint8_t *o = out;
    uint64_t data = f->page - E57_CRC_BYTES;
    if (len == 0) return 0;
    if (phys % f->page >= data)
        return sd_errf(err, SD_EFORMAT, "%s: physical offset %llu points into a page checksum",
                       f->path, (unsigned long long)phys);
    if (e57_logical_room(f, phys) < len)
        return sd_errf(err, SD_ETRUNC,
                       "%s: %zu bytes at physical offset %llu run past the end "
                       "of the file (%llu bytes)",
                       f->path, len, (unsigned long long)phys, (unsigned long long)f->size);
    uint64_t p = phys / f->page, in = phys % f->page;
    while (len > 0) {
        const uint8_t *pg;
        if (p == f->cached_page) {
            pg = f->cache;
        } else {
            /* every page the rest of the run touches, up to E57_READ_PAGES at once */
            uint64_t need = (in + len + data - 1) / data;
            uint64_t count = need < E57_READ_PAGES ? need : E57_READ_PAGES;
            int rc = read_pages(f, p, count, err);
            if (rc < 0) return rc;
            for (uint64_t k = 0; k < count; k++)
                if ((rc = check_page(f, p + k, f->buf + k * f->page, err)) < 0) return rc;
            memcpy(f->cache, f->buf + (count - 1) * f->page, (size_t)f->page);
            f->cached_page = p + count - 1;
            /* copy all but the last page from buf; the last through the cache below */
            for (uint64_t k = 0; k + 1 < count; k++, p++, in = 0) {
                size_t m = (size_t)(data - in) < len ? (size_t)(data - in) : len;
                memcpy(o, f->buf + k * f->page + in, m);
                o += m;
                len -= m;
            }
            pg = f->cache;
            if (len == 0) break;
        }
        size_t m = (size_t)(data - in) < len ? (size_t)(data - in) : len;
        memcpy(o, pg + in, m);
        o += m;
        len -= m;
        p++;
        in = 0;
    }
    return 0;
}

int e57_file_open(const char *path, e57_file *f, sd_err *err)
{
    memset(f, 0, sizeof *f);
    f->fd = -1;
    f->cached_page = UINT64_MAX;
    f->path = strdup(path);
    if (!f->path) return sd_errf(err, SD_ENOMEM, "out of memory");
    e57__crc32c_init(f->crc_table);
#if defined(__x86_64__)
    f->hw_crc = __builtin_cpu_supports("sse4.2");
#endif
    f->fd = open(path, O_RDONLY | O_CLOEXEC);
    if (f->fd < 0) return sd_errf(err, SD_EIO, "%s: %s", path, strerror(errno));
    struct stat st;
    if (fstat(f->fd, &st) < 0) return sd_errf(err, SD_EIO, "%s: %s", path, strerror(errno));
    if (!S_ISREG(st.st_mode)) return sd_errf(err, SD_EIO, "%s: not a regular file", path);
    f->size = (uint64_t)st.st_size;
    uint8_t h[E57_HEADER_BYTES];
    ssize_t g = f->size >= E57_HEADER_BYTES ? pread(f->fd, h, sizeof h, 0) : 0;
    if (g != (ssize_t)sizeof h || memcmp(h, "ASTM-E57", 8) != 0)
        return sd_errf(err, SD_EFORMAT,
                       "%s: not an E57 file: it does not start with the "
                       "48-byte header whose signature at offset 0 is 'ASTM-E57'",
                       path);
    f->major = rd32(h + 8);
    f->minor = rd32(h + 12);
    uint64_t flen = rd64(h + 16);
    f->xml_off = rd64(h + 24);
    f->xml_len = rd64(h + 32);
    f->page = rd64(h + 40);
    if (f->major != 1)
        return sd_errf(err, SD_EUNSUP,
                       "%s: E57 version %u.%u at offset 8 (this reader knows "
                       "version 1)",
                       path, f->major, f->minor);
    if (f->page < 64 || f->page > (1u << 20) || f->page % 4)
        return sd_errf(err, SD_EFORMAT,
                       "%s: page size %llu at offset 40 (want a multiple of 4 "
                       "in [64, 1048576]; writers use 1024)",
                       path, (unsigned long long)f->page);
    if (flen != f->size)
        return sd_errf(err, flen > f->size ? SD_ETRUNC : SD_EFORMAT,
                       "%s: the header at offset "
                       "16 says the file is %llu bytes long, it is %llu",
                       path, (unsigned long long)flen, (unsigned long long)f->size);
    if (f->size % f->page)
        return sd_errf(err, SD_ETRUNC,
                       "%s: the page at physical offset %llu is truncated (%llu "
                       "of %llu bytes)",
                       path, (unsigned long long)(f->size / f->page * f->page),
                       (unsigned long long)(f->size % f->page), (unsigned long long)f->page);
    f->buf = malloc((size_t)f->page * E57_READ_PAGES);
    f->cache = malloc((size_t)f->page);
    if (!f->buf || !f->cache) return sd_errf(err, SD_ENOMEM, "%s: out of memory", path);
    uint8_t chk[E57_HEADER_BYTES];
    int rc = e57_file_read(f, 0, chk, sizeof chk, err); /* page 0's checksum */
    if (rc < 0) return rc;
    if (f->xml_off % f->page >= f->page - E57_CRC_BYTES ||
        e57_logical_room(f, f->xml_off) < f->xml_len || f->xml_len == 0)
        return sd_errf(err, SD_EFORMAT,
                       "%s: the XML section the header names (physical offset "
                       "%llu, %llu logical bytes, at offsets 24 and 32) is %s",
                       path, (unsigned long long)f->xml_off, (unsigned long long)f->xml_len,
                       f->xml_len == 0 ? "empty" : "not inside the file");
    return 0;
}

void e57_file_close(e57_file *f)
{
    if (f->path && f->fd >= 0) close(f->fd); /* path is set first: an opened file */
    free(f->path);
    free(f->buf);
    free(f->cache);
    memset(f, 0, sizeof *f);
    f->fd = -1;
}
