/* io_text.c — file mapping, number parsing and line scanning for the readers (see io_text.h). */
#include "io_text.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "sd_sigbus.h"

int pc__file_open(const char *path, pc__file *f, sd_err *err)
{
    memset(f, 0, sizeof *f);
    /* O_NONBLOCK: opening a FIFO (or a device) for reading must not wait for a writer; the
     * regular-file check below then refuses it at once. It changes nothing for regular files. */
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return sd_errf(err, SD_EIO, "%s: cannot open: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0) {
        int e = errno;
        close(fd);
        return sd_errf(err, SD_EIO, "%s: cannot stat: %s", path, strerror(e));
    }
    if (!S_ISREG(st.st_mode)) {
        close(fd);
        return sd_errf(err, SD_EIO, "%s: not a regular file", path);
    }
    if (st.st_size == 0) { /* mmap refuses length 0; an empty file is simply no bytes */
        close(fd);
        f->data = (const uint8_t *)""; /* not NULL: data + 0 on NULL is undefined in C */
        return 0;
    }
    if ((uint64_t)st.st_size > (uint64_t)SIZE_MAX / 2) {
        close(fd);
        return sd_errf(err, SD_ELIMIT, "%s: file too large to map (%lld bytes)", path,
                       (long long)st.st_size);
    }
    void *m = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    int e = errno;
    close(fd);
    if (m == MAP_FAILED) return sd_errf(err, SD_EIO, "%s: cannot map: %s", path, strerror(e));
    (void)madvise(m, (size_t)st.st_size, MADV_SEQUENTIAL | MADV_WILLNEED);
    f->map = m;
    f->data = m;
    f->size = (size_t)st.st_size;
    return 0;
}

void pc__file_close(pc__file *f)
{
    if (f->map) munmap(f->map, f->size);
    memset(f, 0, sizeof *f);
}

/* ---- SIGBUS on a mapped file, turned into an error of that load ----
 *
 * A file truncated by someone else while it is parsed leaves the pages past its new end
 * without backing: reading them raises SIGBUS, which would kill the daemon. The parse runs
 * under sd_sigbus.h's jump guard over the mapping, which ends it early instead.
 *
 * Why not read the file into memory instead: pread into a buffer costs a copy and page faults
 * on the fresh buffer, and doubles the memory held during the parse; the mapping costs nothing
 * of that (README "Security" has the measurements).
 *
 * The jump leaves the parse mid-way: everything it allocates must be reachable from its
 * argument, so the caller frees it (pc__guarded's contract). A parse only reads the mapping
 * with plain loads and memchr/memcpy/memcmp, none of which holds a lock, so jumping out of
 * them is safe. */
int pc__guarded(const pc__file *f, const char *path, int (*parse)(void *arg), void *arg,
                sd_err *err)
{
    if (!f->map) return parse(arg); /* an empty file: nothing mapped, nothing to lose */
    int faulted = 0;
    int rc = sd_sigbus_run(f->data, f->size, parse, arg, &faulted);
    if (faulted)
        return sd_errf(err, SD_EIO, "%s: the file changed while it was being read (it became "
                       "shorter); try again once it is complete", path);
    return rc;
}

const char *pc__line_end(const char *s, const char *end)
{
    const char *nl = memchr(s, '\n', (size_t)(end - s));
    return nl ? nl : end;
}

/* Exact powers of ten: every one up to 1e22 is representable in a double. */
static const double pow10_exact[23] = {
    1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
    1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
};

/* strtod on a NUL-terminated copy of [s, s+n): the slow path for long mantissas, big exponents,
 * nan and inf. Returns the end pointer in the original text or NULL. */
static const char *parse_slow(const char *s, const char *end, double *out)
{
    char buf[404];
    size_t n = (size_t)(end - s);
    if (n > 400) n = 400;
    memcpy(buf, s, n);
    buf[n] = 0;
    char *e = NULL;
    double v = strtod(buf, &e);
    if (e == buf) return NULL;
    *out = v;
    return s + (e - buf);
}

const char *pc__parse_num(const char *s, const char *end, double *out)
{
    const char *p = s;
    if (p >= end || pc__is_space((unsigned char)*p) || *p == '\n') return NULL;
    int neg = 0;
    if (*p == '+' || *p == '-') {
        neg = *p == '-';
        p++;
    }
    uint64_t m = 0;
    int nd = 0, exp10 = 0, digits = 0, dropped = 0;
    for (; p < end && (unsigned)(*p - '0') < 10; p++) {
        unsigned d = (unsigned)(*p - '0');
        digits++;
        if (m == 0 && d == 0) continue;
        if (nd < 19) {
            m = m * 10 + d;
            nd++;
        } else {
            exp10++;
            dropped = 1;
        }
    }
    if (p < end && *p == '.') {
        for (p++; p < end && (unsigned)(*p - '0') < 10; p++) {
            unsigned d = (unsigned)(*p - '0');
            digits++;
            if (m == 0 && d == 0) {
                exp10--;
            } else if (nd < 19) {
                m = m * 10 + d;
                nd++;
                exp10--;
            } else {
                dropped = 1;
            }
        }
    }
    if (digits == 0) return parse_slow(s, end, out); /* nan, inf, or not a number */
    if (p < end && (*p == 'e' || *p == 'E')) {
        const char *q = p + 1;
        int eneg = 0, e = 0, edigits = 0;
        if (q < end && (*q == '+' || *q == '-')) {
            eneg = *q == '-';
            q++;
        }
        for (; q < end && (unsigned)(*q - '0') < 10; q++) {
            if (e < 100000) e = e * 10 + (*q - '0');
            edigits++;
        }
        if (edigits) { /* "1e" alone is the number 1 followed by 'e', as for strtod */
            exp10 += eneg ? -e : e;
            p = q;
        }
    }
    if (m == 0) {
        *out = neg ? -0.0 : 0.0;
        return p;
    }
    if (!dropped && m <= (1ull << 53) && exp10 >= -22 && exp10 <= 22) {
        /* Both operands are exact, so one IEEE operation rounds correctly (Clinger 1990). */
        double v = (double)m;
        v = exp10 < 0 ? v / pow10_exact[-exp10] : v * pow10_exact[exp10];
        *out = neg ? -v : v;
        return p;
    }
    if (p - s > 400) return NULL;
    return parse_slow(s, p, out);
}
