/* lod_file.c — the LOD cache file: header, checks, mapping, the atomic writer (lod_file.h). */
#include "lod_file.h"

#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "cloud.h"
#include "sd_hash.h"

#define LOD_MAGIC "SPLATDL\0"
enum { HEADER_LEN = 4096 };

typedef struct lod_header {
    char magic[8];
    uint32_t version, byte_order;
    uint64_t src_size, src_hash;
    int64_t src_mtime_ns;
    uint32_t k, attrs, grid_bits, leaf_max, depth, pad;
    uint64_t n, nnodes, table_off, table_hash, file_len;
    double offset[3], bmin[3], bmax[3], origin[3], side, centroid[3];
    float sigma, F_raw_p99, F_pct[5], radius_median;
    uint64_t n_dropped;
    char format[64];
    uint64_t header_hash;     /* sd_hash64 of every byte above */
} lod_header;
_Static_assert(sizeof(lod_header) <= HEADER_LEN, "the LOD header fits its page");
_Static_assert(sizeof(lod_node) == 104, "lod_node is stored verbatim");

uint64_t lod_node_bytes(uint32_t count)
{
    return (uint64_t)count * 40u;
}

void lod_node_get(const lod_cloud *c, uint64_t i, lod_node_data *d)
{
    const lod_node *nd = &c->nodes[i];
    const uint8_t *p = c->map + nd->offset;
    uint64_t n = nd->count;
    d->pos = (const float *)p;
    d->normal = d->pos + 3 * n;
    d->radius = d->normal + 3 * n;
    d->radius_lod = d->radius + n;
    d->F = d->radius_lod + n;
    d->rgba = (const uint32_t *)(d->F + n);
}

int lod_node_verify(const lod_cloud *c, uint64_t i)
{
    const lod_node *nd = &c->nodes[i];
    return sd_hash64(c->map + nd->offset, lod_node_bytes(nd->count), 0) == nd->hash;
}

void lod_cloud_free(lod_cloud *c)
{
    if (c && c->map) munmap((void *)c->map, c->map_len);
    if (c) memset(c, 0, sizeof *c);
}

int lod_want(int mode, uint64_t size)
{
    return mode == LOD_ALWAYS || (mode == LOD_AUTO && size >= LOD_AUTO_BYTES);
}

int lod_cache_path(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err)
{
    char real[PATH_MAX], d[PATH_MAX];
    if (!realpath(src, real)) return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    if (dir && *dir) snprintf(d, sizeof d, "%s", dir);
    else cache__default_dir(real, d, sizeof d);
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", real);
    uint64_t ph = sd_hash64(real, strlen(real), 0);
    int w = snprintf(buf, len, "%s/%s.%016llx.k%d.splod", d, basename(tmp),
                     (unsigned long long)ph, k);
    if (w < 0 || (size_t)w >= len) return sd_errf(err, SD_ELIMIT, "%s: cache path too long", src);
    return 0;
}

int lod__src_key(const char *src, lod_src_key *key, sd_err *err)
{
    int fd = open(src, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) < 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        return sd_errf(err, SD_EIO, "%s: not a regular file", src);
    }
    key->size = (uint64_t)st.st_size;
    key->mtime_ns = (int64_t)st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec;
    enum { PIECE = 1 << 20 };
    uint8_t *buf = malloc(PIECE);
    if (!buf) {
        close(fd);
        return sd_errf(err, SD_ENOMEM, "out of memory");
    }
    sd_hash_state hs;
    sd_hash64_init(&hs, 0);
    uint64_t at[2] = {0, key->size > PIECE ? key->size - PIECE : 0};
    int rc = 0;
    for (int i = 0; i < 2 && rc == 0; i++) {
        size_t want = key->size - at[i] < PIECE ? (size_t)(key->size - at[i]) : PIECE;
        ssize_t g = pread(fd, buf, want, (off_t)at[i]);
        if (g != (ssize_t)want) rc = sd_errf(err, SD_EIO, "%s: cannot read it", src);
        else sd_hash64_update(&hs, buf, want);
    }
    key->hash = sd_hash64_final(&hs);
    free(buf);
    close(fd);
    return rc;
}

int lod_load_file(const char *path, const char *src, int k, lod_cloud *out, char *why,
                  size_t whylen)
{
    memset(out, 0, sizeof *out);
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (fd < 0) {
        snprintf(why, whylen, "no cache");
        return 0;
    }
    struct stat st;
    lod_header h;
    int rc = -1;
    uint8_t *m = MAP_FAILED;
    size_t len = 0;
    if (fstat(fd, &st) < 0 || (uint64_t)st.st_size < HEADER_LEN ||
        pread(fd, &h, sizeof h, 0) != (ssize_t)sizeof h) {
        snprintf(why, whylen, "it is truncated");
        goto out;
    }
    if (memcmp(h.magic, LOD_MAGIC, 8) != 0 || h.byte_order != 0x01020304u ||
        h.header_hash != sd_hash64(&h, offsetof(lod_header, header_hash), 0)) {
        snprintf(why, whylen, "its header is damaged (magic, byte order or checksum)");
        goto out;
    }
    if (h.version != LOD_VERSION || (int)h.k != k) {
        snprintf(why, whylen, "LOD cache version %u k %u, this splatd writes %u with k %d",
                 h.version, h.k, LOD_VERSION, k);
        rc = 0;
        goto out;
    }
    lod_src_key key;
    sd_err e = {0};
    if (lod__src_key(src, &key, &e) < 0 || key.size != h.src_size ||
        key.mtime_ns != h.src_mtime_ns || key.hash != h.src_hash) {
        snprintf(why, whylen, "source changed (size, mtime or content)");
        rc = 0;
        goto out;
    }
    len = (size_t)st.st_size;
    if (h.file_len != (uint64_t)st.st_size || h.nnodes == 0 ||
        h.nnodes > (h.file_len - HEADER_LEN) / sizeof(lod_node) ||
        h.table_off < HEADER_LEN || h.table_off > h.file_len ||
        h.nnodes * sizeof(lod_node) != h.file_len - h.table_off || h.grid_bits < 1 ||
        h.grid_bits + h.depth > 22 || h.n == 0) {
        snprintf(why, whylen, "its sizes do not agree (%lld bytes, %llu nodes)",
                 (long long)st.st_size, (unsigned long long)h.nnodes);
        goto out;
    }
    m = mmap(NULL, len, PROT_READ, MAP_SHARED, fd, 0);
    if (m == MAP_FAILED) {
        snprintf(why, whylen, "it cannot be mapped: %s", strerror(errno));
        goto out;
    }
    const lod_node *nodes = (const lod_node *)(m + h.table_off);
    if (sd_hash64(nodes, h.nnodes * sizeof(lod_node), 0) != h.table_hash) {
        snprintf(why, whylen, "its node table is corrupt (checksum mismatch)");
        goto out;
    }
    /* The table is trusted by the renderer: every node's data within the data section, the
     * tree well formed (children after their parent, in range, point counts adding up). */
    uint64_t total = 0;
    for (uint64_t i = 0; i < h.nnodes; i++) {
        const lod_node *nd = &nodes[i];
        uint64_t end = nd->offset + lod_node_bytes(nd->count);
        int bad = nd->count == 0 || nd->offset < HEADER_LEN || end > h.table_off ||
                  nd->offset % 4 || nd->level >= h.depth ||
                  (i == 0 ? nd->parent != UINT32_MAX : nd->parent >= i) ||
                  (nd->nchildren && (nd->first_child <= i ||
                                     (uint64_t)nd->first_child + nd->nchildren > h.nnodes));
        if (!bad && i > 0) bad = nodes[nd->parent].level + 1 != nd->level;
        if (bad) {
            snprintf(why, whylen, "node %llu of its table is malformed", (unsigned long long)i);
            goto out;
        }
        total += nd->count;
    }
    if (total != h.n) {
        snprintf(why, whylen, "its nodes hold %llu points, its header says %llu",
                 (unsigned long long)total, (unsigned long long)h.n);
        goto out;
    }
    out->n = h.n;
    out->nnodes = h.nnodes;
    out->k = h.k;
    out->attrs = h.attrs;
    out->grid_bits = h.grid_bits;
    out->leaf_max = h.leaf_max;
    out->depth = h.depth;
    memcpy(out->offset, h.offset, sizeof h.offset);
    memcpy(out->bmin, h.bmin, sizeof h.bmin);
    memcpy(out->bmax, h.bmax, sizeof h.bmax);
    memcpy(out->origin, h.origin, sizeof h.origin);
    out->side = h.side;
    memcpy(out->centroid, h.centroid, sizeof h.centroid);
    out->sigma = h.sigma;
    out->F_raw_p99 = h.F_raw_p99;
    memcpy(out->F_pct, h.F_pct, sizeof h.F_pct);
    out->radius_median = h.radius_median;
    out->n_dropped = h.n_dropped;
    memcpy(out->format, h.format, sizeof out->format);
    out->format[sizeof out->format - 1] = 0;
    out->nodes = nodes;
    out->map = m;
    out->map_len = len;
    m = MAP_FAILED;
    rc = 1;
out:
    if (m != MAP_FAILED) munmap(m, len);
    close(fd);
    return rc;
}

/* ---- the writer ---- */

int lod__writer_open(lod_writer *w, const char *cpath, sd_err *err)
{
    memset(w, 0, sizeof *w);
    w->fd = w->dfd = -1;
    char dir[PATH_MAX];
    snprintf(w->path, sizeof w->path, "%s", cpath);
    snprintf(dir, sizeof dir, "%s", cpath);
    char *slash = strrchr(dir, '/');
    if (slash) {
        *slash = 0;
        snprintf(w->base, sizeof w->base, "%s", slash + 1);
    } else {
        snprintf(dir, sizeof dir, ".");
        snprintf(w->base, sizeof w->base, "%s", cpath);
    }
    w->dfd = cache__open_dir(dir, err);
    if (w->dfd < 0) return SD_EIO;
    w->fd = cache__create_tmp(w->dfd, w->base, w->tmp, sizeof w->tmp, &w->named);
    if (w->fd < 0) {
        int e = errno;
        close(w->dfd);
        w->dfd = -1;
        return sd_errf(err, SD_EIO, "cannot write LOD cache %s: %s", cpath, strerror(e));
    }
    pthread_mutex_init(&w->mu, NULL);
    w->off = HEADER_LEN;
    return 0;
}

int lod__pwrite_all(int fd, const void *p, size_t len, uint64_t off)
{
    const uint8_t *b = p;
    while (len) {
        ssize_t g = pwrite(fd, b, len, (off_t)off);
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0) return -1;
        b += g;
        len -= (size_t)g;
        off += (uint64_t)g;
    }
    return 0;
}

int lod__pread_all(int fd, void *p, size_t len, uint64_t off)
{
    uint8_t *q = p;
    while (len) {
        ssize_t g = pread(fd, q, len, (off_t)off);
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0) return -1;
        q += g;
        len -= (size_t)g;
        off += (uint64_t)g;
    }
    return 0;
}

int lod__writer_append(lod_writer *w, const void *data, size_t len, uint64_t *off, sd_err *err)
{
    pthread_mutex_lock(&w->mu);
    uint64_t at = (w->off + LOD_NODE_ALIGN - 1) / LOD_NODE_ALIGN * LOD_NODE_ALIGN;
    w->off = at + len;
    pthread_mutex_unlock(&w->mu);
    *off = at;
    if (lod__pwrite_all(w->fd, data, len, at) < 0)
        return sd_errf(err, SD_EIO, "cannot write LOD cache %s: %s", w->path, strerror(errno));
    /* start writing the node back now (asynchronously: no wait), so that the fsync at the
     * commit finds little left to write; durability still comes from that fsync alone */
    sync_file_range(w->fd, (off64_t)at, (off64_t)len, SYNC_FILE_RANGE_WRITE);
    return 0;
}

int lod__writer_commit(lod_writer *w, const lod_cloud *c, const lod_src_key *key, sd_err *err)
{
    lod_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, LOD_MAGIC, 8);
    h.version = LOD_VERSION;
    h.byte_order = 0x01020304u;
    h.src_size = key->size;
    h.src_hash = key->hash;
    h.src_mtime_ns = key->mtime_ns;
    h.k = c->k;
    h.attrs = c->attrs;
    h.grid_bits = c->grid_bits;
    h.leaf_max = c->leaf_max;
    h.depth = c->depth;
    h.n = c->n;
    h.nnodes = c->nnodes;
    h.table_off = (w->off + 7) / 8 * 8;
    h.table_hash = sd_hash64(c->nodes, c->nnodes * sizeof(lod_node), 0);
    h.file_len = h.table_off + c->nnodes * sizeof(lod_node);
    memcpy(h.offset, c->offset, sizeof h.offset);
    memcpy(h.bmin, c->bmin, sizeof h.bmin);
    memcpy(h.bmax, c->bmax, sizeof h.bmax);
    memcpy(h.origin, c->origin, sizeof h.origin);
    h.side = c->side;
    memcpy(h.centroid, c->centroid, sizeof h.centroid);
    h.sigma = c->sigma;
    h.F_raw_p99 = c->F_raw_p99;
    memcpy(h.F_pct, c->F_pct, sizeof h.F_pct);
    h.radius_median = c->radius_median;
    h.n_dropped = c->n_dropped;
    memcpy(h.format, c->format, sizeof h.format);
    h.header_hash = sd_hash64(&h, offsetof(lod_header, header_hash), 0);
    static const uint8_t zero[HEADER_LEN];
    int bad = lod__pwrite_all(w->fd, c->nodes, c->nnodes * sizeof(lod_node), h.table_off) ||
              lod__pwrite_all(w->fd, zero, HEADER_LEN, 0) ||
              lod__pwrite_all(w->fd, &h, sizeof h, 0);
    bad = cache__publish(w->fd, w->dfd, w->base, w->tmp, sizeof w->tmp, w->named, bad) < 0;
    int saved = errno;
    w->fd = -1;     /* closed by cache__publish */
    w->named = 0;   /* renamed, or removed */
    lod__writer_abort(w);
    if (bad) return sd_errf(err, SD_EIO, "cannot write LOD cache %s: %s", w->path,
                            strerror(saved));
    return 0;
}

void lod__writer_abort(lod_writer *w)
{
    if (w->fd >= 0) close(w->fd);
    if (w->named && w->dfd >= 0) unlinkat(w->dfd, w->tmp, 0);
    if (w->dfd >= 0) {
        close(w->dfd);
        pthread_mutex_destroy(&w->mu);
    }
    w->fd = w->dfd = -1;
    w->named = 0;
}

int lod__scratch(lod_writer *w, sd_err *err)
{
    int fd = openat(w->dfd, ".", O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    for (int tries = 0; fd < 0 && tries < 16; tries++) { /* no O_TMPFILE: unlinked at once */
        char name[64];
        snprintf(name, sizeof name, ".lod-scratch.%ld.%d.%d", (long)getpid(), tries, rand());
        fd = openat(w->dfd, name, O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
        if (fd >= 0) unlinkat(w->dfd, name, 0);
    }
    if (fd < 0) return sd_errf(err, SD_EIO, "cannot create a scratch file beside %s: %s",
                               w->path, strerror(errno));
    return fd;
}
