/* lod_file.c — the LOD cache file through cachefile.h: meta, checks, loading, node reads, the
 * writer (lod_file.h).
 *
 * The header page holds cachefile.h's cf_head and lod_meta (below); the checksummed body is
 * the node table [table_off, file_len); the key's options fold k, grid_bits and leaf_max; the
 * source's content hash covers its first and last MiB (a whole-file hash would cost seconds
 * per OPEN at 10^9 points). The table is read into memory at open (pread, checksum on the
 * copy): the renderer's traversal never reads the file. Node data is read through the guarded
 * mapping, each node's checksum checked on the copy. */
#include "lod_file.h"

#include <errno.h>
#include <fcntl.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "cloud.h"
#include "prep.h"
#include "prepared.h"
#include "sd_hash.h"

/* The summary of a LOD cloud, after cf_head in the header page (no padding). */
typedef struct lod_meta {
    uint32_t attrs, depth;
    uint64_t n, nnodes;
    double origin[3], side, centroid[3];
    pc_summary sum;
} lod_meta;
_Static_assert(sizeof(lod_meta) == 296, "lod_meta is stored verbatim, without padding");
_Static_assert(sizeof(lod_node) == 104, "lod_node is stored verbatim");

static void describe(uint64_t o, char *buf, size_t len)
{
    snprintf(buf, len, "k = %u, grid bits %u, leaf size %u", (unsigned)(o & 0xffff),
             (unsigned)(o >> 16 & 0xff), (unsigned)(o >> 32));
}

/* Bump the version when the layout or the meaning of any value changes (4: the header of
 * cachefile.h, the grid and leaf size in the key; 5: the sensor's rotation). */
static const cf_kind LOD = {.what = "LOD cache", .magic = "SPLATDL", .version = 5,
                            .meta_len = sizeof(lod_meta), .hash_how = CF_HASH_ENDS,
                            .describe = describe};

static uint64_t fold(uint32_t k, uint32_t grid_bits, uint32_t leaf_max)
{
    return (uint64_t)(k & 0xffff) | (uint64_t)(grid_bits & 0xff) << 16 | (uint64_t)leaf_max << 32;
}

uint64_t lod__options(const lod_desc *d)
{
    int k = d && d->k > 0 ? d->k : PREP_DEFAULT_K;
    int g = d && d->grid_bits > 0 ? d->grid_bits : LOD_DEFAULT_GRID_BITS;
    if (g > 7) g = 7;
    uint32_t leaf = d && d->leaf_max ? d->leaf_max : LOD_DEFAULT_LEAF_MAX;
    return fold((uint32_t)k, (uint32_t)g, leaf);
}

uint64_t lod_node_bytes(uint32_t count)
{
    return (uint64_t)count * 40u;
}

void lod_node_get(const lod_cloud *c, uint64_t i, lod_node_data *d)
{
    lod_node_bind(c->map + c->nodes[i].offset, c->nodes[i].count, d);
}

void lod_node_bind(const void *data, uint32_t count, lod_node_data *d)
{
    uint64_t n = count;
    d->pos = data;
    d->normal = d->pos + 3 * n;
    d->radius = d->normal + 3 * n;
    d->radius_lod = d->radius + n;
    d->F = d->radius_lod + n;
    d->rgba = (const uint32_t *)(d->F + n);
}

int lod_node_verify(const lod_cloud *c, uint64_t i)
{
    const lod_node *nd = &c->nodes[i];
    return sd_hash64(c->map + nd->offset, lod_node_bytes(nd->count), 0) == nd->hash &&
           !cf_map_changed(c->file);
}

int lod_node_copy(const lod_cloud *c, uint64_t i, void *dst, sd_err *err)
{
    const lod_node *nd = &c->nodes[i];
    size_t len = (size_t)lod_node_bytes(nd->count);
    memcpy(dst, c->map + nd->offset, len); /* the reads from disk happen here */
    char detail[128];
    if (cf_map_changed(c->file)) {
        snprintf(detail, sizeof detail, "it became shorter: node %llu is gone",
                 (unsigned long long)i);
    } else if (sd_hash64(dst, len, 0) != nd->hash) {
        snprintf(detail, sizeof detail, "node %llu does not match its checksum",
                 (unsigned long long)i);
    } else {
        return 0;
    }
    return cf_changed_error(err, LOD.what, c->file ? c->file->path : "?", detail);
}

void lod_cloud_free(lod_cloud *c)
{
    if (!c) return;
    cf_map_close(c->file);
    free((void *)c->nodes);
    memset(c, 0, sizeof *c);
}

int lod_want(int mode, uint64_t size)
{
    return mode == LOD_ALWAYS || (mode == LOD_AUTO && size >= LOD_AUTO_BYTES);
}

int lod_cache_path(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err)
{
    return cf_path(src, dir, k, LOD_EXT, buf, len, err);
}

int lod__src_key(const char *src, lod_src_key *key, sd_err *err)
{
    int rc = cf_key_stat(src, key, err);
    return rc < 0 ? rc : cf_key_hash(src, CF_HASH_ENDS, key, err);
}

/* check_table: the node table is trusted by the renderer: every node's data within the data
 * section, the tree well formed (children after their parent, in range, point counts adding
 * up to n). Returns 1, or -1 with why. */
static int check_table(const lod_node *nodes, const lod_meta *m, uint64_t table_off, char *why,
                       size_t whylen)
{
    uint64_t total = 0;
    for (uint64_t i = 0; i < m->nnodes; i++) {
        const lod_node *nd = &nodes[i];
        uint64_t end = nd->offset + lod_node_bytes(nd->count);
        int bad = nd->count == 0 || nd->offset < CF_PAGE || end > table_off ||
                  nd->offset % 4 || nd->level >= m->depth ||
                  (i == 0 ? nd->parent != UINT32_MAX : nd->parent >= i) ||
                  (nd->nchildren && (nd->first_child <= i ||
                                     (uint64_t)nd->first_child + nd->nchildren > m->nnodes));
        if (!bad && i > 0) bad = nodes[nd->parent].level + 1 != nd->level;
        if (bad) {
            snprintf(why, whylen, "node %llu of its table is malformed", (unsigned long long)i);
            return -1;
        }
        total += nd->count;
    }
    if (total != m->n) {
        snprintf(why, whylen, "its nodes hold %llu points, its header says %llu",
                 (unsigned long long)total, (unsigned long long)m->n);
        return -1;
    }
    return 1;
}

/* load: lod_load_file of the file at path (fd < 0) or of the unnamed file fd (path names it). */
static int load(const char *path, int fd, const char *src, const lod_desc *d, lod_cloud *out,
                char *why, size_t whylen)
{
    memset(out, 0, sizeof *out);
    lod_src_key key;
    sd_err e = {0};
    if (cf_key_stat(src, &key, &e) < 0) {
        snprintf(why, whylen, "source changed (%s)", e.msg);
        return 0;
    }
    uint64_t options = lod__options(d);
    cf_file f;
    int rc = cf_open(&LOD, path, fd, &key, options, &f, why, whylen);
    if (rc != 1) return rc;
    lod_meta m;
    memcpy(&m, f.meta, sizeof m);
    const cf_head *h = &f.head;
    uint32_t grid_bits = (uint32_t)(options >> 16 & 0xff);
    rc = -1;
    lod_node *nodes = NULL;
    if (m.nnodes == 0 || m.nnodes > (h->file_len - CF_PAGE) / sizeof(lod_node) ||
        h->body_len != m.nnodes * sizeof(lod_node) || h->body_off + h->body_len != h->file_len ||
        grid_bits + m.depth > 22 || m.n == 0) {
        snprintf(why, whylen, "its sizes do not agree (%llu bytes, %llu nodes)",
                 (unsigned long long)f.size, (unsigned long long)m.nnodes);
        goto out;
    }
    rc = cf_check_source(&f, src, why, whylen);
    if (rc != 1) goto out;
    rc = -1;
    nodes = malloc((size_t)h->body_len);
    if (!nodes) {
        snprintf(why, whylen, "out of memory for its %llu nodes", (unsigned long long)m.nnodes);
        goto out;
    }
    if (cf_read_body(&f, nodes, why, whylen) != 1) goto out;
    if (check_table(nodes, &m, h->body_off, why, whylen) != 1) goto out;
    out->file = cf_map_open(&f, why, whylen);
    if (!out->file) goto out;
    out->n = m.n;
    out->nnodes = m.nnodes;
    out->k = (uint32_t)(options & 0xffff);
    out->attrs = m.attrs;
    out->grid_bits = grid_bits;
    out->leaf_max = (uint32_t)(options >> 32);
    out->depth = m.depth;
    memcpy(out->origin, m.origin, sizeof m.origin);
    out->side = m.side;
    memcpy(out->centroid, m.centroid, sizeof m.centroid);
    PC_SUMMARY_COPY(out, &m.sum);
    out->nodes = nodes;
    out->map = out->file->addr;
    out->map_len = out->file->len;
    nodes = NULL;
    rc = 1;
out:
    free(nodes);
    cf_close(&f);
    return rc;
}

int lod_load_file(const char *path, const char *src, const lod_desc *d, lod_cloud *out,
                  char *why, size_t whylen)
{
    return load(path, -1, src, d, out, why, whylen);
}

int lod__seal(const char *path, const char *src, const lod_desc *d)
{
    return cf__seal(path, src, CF_HASH_ENDS, 1, lod__options(d));
}

/* ---- the writer ---- */

int lod__writer_open(lod_writer *w, const char *cpath, const lod_desc *d, sd_err *err)
{
    memset(w, 0, sizeof *w);
    w->cf.fd = w->cf.dfd = -1;
    sd_err e1 = {0}, e2 = {0};
    if (cf_writer_open(&w->cf, cpath, &e1) < 0) {
        /* The cache directory cannot be written (read-only, full, another user's): the build
         * goes on in an unnamed file of the temporary directory, served while the cloud is
         * open and rebuilt at its next open (as a flat cloud carries on without a cache). */
        if (cf_writer_open_temp(&w->cf, cpath, &e2) < 0)
            return sd_errf(err, SD_EIO, "cannot build the LOD form: %s; nor in the temporary "
                           "directory: %s", e1.msg, e2.msg);
        if (d && d->warn) {
            char msg[sizeof e1.msg + PATH_MAX + 128];
            snprintf(msg, sizeof msg, "%s; building the LOD form in an unnamed file in %s "
                     "instead (not kept: rebuilt at the next open)", e1.msg, w->cf.dir);
            d->warn(d->user, msg);
        }
    }
    pthread_mutex_init(&w->mu, NULL);
    w->have_mu = 1;
    w->off = CF_PAGE;
    return 0;
}

int lod__writer_append(lod_writer *w, const void *data, size_t len, uint64_t *off, sd_err *err)
{
    pthread_mutex_lock(&w->mu);
    uint64_t at = (w->off + LOD_NODE_ALIGN - 1) / LOD_NODE_ALIGN * LOD_NODE_ALIGN;
    w->off = at + len;
    pthread_mutex_unlock(&w->mu);
    *off = at;
    if (cf_pwrite_all(w->cf.fd, data, len, at) < 0)
        return sd_errf(err, SD_EIO, "cannot write LOD cache %s: %s", w->cf.path, strerror(errno));
    /* start writing the node back now (asynchronously: no wait), so that the fsync at the
     * commit finds little left to write; durability still comes from that fsync alone */
    sync_file_range(w->cf.fd, (off64_t)at, (off64_t)len, SYNC_FILE_RANGE_WRITE);
    return 0;
}

int lod__writer_commit(lod_writer *w, const lod_cloud *c, const lod_src_key *key, sd_err *err)
{
    lod_meta m = {.attrs = c->attrs, .depth = c->depth, .n = c->n, .nnodes = c->nnodes,
                  .side = c->side};
    memcpy(m.origin, c->origin, sizeof m.origin);
    memcpy(m.centroid, c->centroid, sizeof m.centroid);
    PC_SUMMARY_COPY(&m.sum, c);
    uint64_t table_off = (w->off + 7) / 8 * 8, table_len = c->nnodes * sizeof(lod_node);
    cf_head h = {.src = *key, .options = fold(c->k, c->grid_bits, c->leaf_max),
                 .file_len = table_off + table_len, .body_off = table_off,
                 .body_len = table_len, .body_hash = sd_hash64(c->nodes, table_len, 0)};
    if (cf_pwrite_all(w->cf.fd, c->nodes, table_len, table_off) < 0) {
        int e = errno;
        lod__writer_abort(w);
        return sd_errf(err, SD_EIO, "cannot write LOD cache %s: %s", w->cf.path,
                       strerror(e));
    }
    return cf_writer_commit(&w->cf, &LOD, &h, &m, err);
}

int lod__load_built(const lod_writer *w, const char *src, const lod_desc *d, lod_cloud *out,
                    char *why, size_t whylen)
{
    if (!w->cf.temp) return load(w->cf.path, -1, src, d, out, why, whylen);
    char name[PATH_MAX + NAME_MAX + 16];
    snprintf(name, sizeof name, "%s/%s (unnamed)", w->cf.dir, w->cf.base);
    return load(name, w->cf.fd, src, d, out, why, whylen);
}

int lod__build_failed(const lod_writer *w, int rc, sd_err *err)
{
    if (rc != SD_EIO || !w->have_mu || !err) return rc;
    char msg[sizeof err->msg];
    snprintf(msg, sizeof msg, "%s", err->msg);
    return sd_errf(err, rc, "the LOD build in %s%s failed: %s", w->cf.dir,
                   w->cf.temp ? " (the temporary directory)" : "", msg);
}

void lod__writer_abort(lod_writer *w)
{
    cf_writer_abort(&w->cf);
    if (w->have_mu) pthread_mutex_destroy(&w->mu);
    w->have_mu = 0;
}

int lod__scratch(lod_writer *w, sd_err *err)
{
    return cf_scratch(&w->cf, err);
}
