/* cache.c — prepared-cloud cache files (see cache.h), written and read through cachefile.h.
 *
 * File layout:
 *   [0, 4096)            the header page: cachefile.h's cf_head, then flat_meta (below)
 *   [4096, 4096 + len)   the prepared array block of prepared.h, verbatim: the checksummed body
 * The key's options are k; the source's content hash covers the whole file. */
#include "cache.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cachefile.h"
#include "cloud.h"
#include "prep.h"
#include "sd_hash.h"

/* The summary values of a prepared cloud, after cf_head in the header page. Every byte is a
 * value the loader checks or hands on (no padding). */
typedef struct flat_meta {
    uint32_t k, attrs;
    uint64_t n, nbatches;
    pc_summary sum;
    char scalar_name[32];
    pc_prep_stats stats;
} flat_meta;
_Static_assert(sizeof(flat_meta) == 320, "flat_meta is stored verbatim, without padding");

static void describe_k(uint64_t options, char *buf, size_t len)
{
    snprintf(buf, len, "k = %llu", (unsigned long long)options);
}

/* Bump the version when the layout of prepared.h or the meaning of any prepared value changes,
 * or the header's (6: the header of cachefile.h; 7: the sensor's rotation). */
static const cf_kind FLAT = {.what = "cache", .magic = "SPLATDC", .version = 7,
                             .meta_len = sizeof(flat_meta), .hash_how = CF_HASH_ALL,
                             .describe = describe_k};

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int cache_dir_for(const char *dir, char *buf, size_t len)
{
    return cf_dir_for(dir, buf, len);
}

int cache_path_for(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err)
{
    return cf_path(src, dir, k, CACHE_EXT, buf, len, err);
}

int cache_sweep(const char *dir, int *removed)
{
    return cf_sweep(dir, removed);
}

/* open_checked: cf_open of the cache at cpath for a source of src's size and mtime and k, and
 * the flat kind's own checks: the counts bounded by the file (before the block length they
 * imply is computed: a 64-bit sum a huge count would wrap around to a plausible value), the
 * block right after the header page with the layout's length. Returns as cf_open; *m gets the
 * meta when 1. */
static int open_checked(const char *cpath, const cf_key *src, int k, cf_file *f, flat_meta *m,
                        char *why, size_t whylen)
{
    int rc = cf_open(&FLAT, cpath, -1, src, (uint64_t)k, f, why, whylen);
    if (rc != 1) return rc;
    memcpy(m, f->meta, sizeof *m);
    uint64_t room = f->size;
    const cf_head *h = &f->head;
    if (m->k != (uint32_t)k) {
        snprintf(why, whylen, "its k (%u) disagrees with its key (%d)", m->k, k);
    } else if (m->n == 0 || m->n > room / 12 || m->nbatches == 0 || m->nbatches > m->n ||
               m->nbatches > room / sizeof(pc_batch)) {
        snprintf(why, whylen, "its counts (%llu points, %llu batches) cannot fit its %llu bytes",
                 (unsigned long long)m->n, (unsigned long long)m->nbatches,
                 (unsigned long long)room);
    } else if (h->body_off != CF_PAGE ||
               h->body_len != pc_prepared_block_len(m->n, m->attrs, m->nbatches) ||
               h->file_len != CF_PAGE + h->body_len) {
        snprintf(why, whylen, "it has a wrong size (%llu bytes, %llu expected)",
                 (unsigned long long)f->size,
                 (unsigned long long)(CF_PAGE + pc_prepared_block_len(m->n, m->attrs,
                                                                       m->nbatches)));
    } else {
        return 1;
    }
    cf_close(f);
    return -1;
}

/* Tries to map a valid cache. Returns 1 on success, 0 when there is none or it is out of date
 * (why says which), -1 when it is damaged (why says how: the caller warns). */
static int try_load(const char *cpath, const char *src, const cf_key *key, int k,
                    pc_prepared *out, char *why, size_t whylen)
{
    cf_file f;
    flat_meta m;
    /* The cheap checks first (header, version, k, the source's size and time): the source's
     * content is hashed only for a cache that could be used, never for one that is stale
     * anyway, nor before the source's own header has been looked at (cache_open_cloud). */
    int rc = open_checked(cpath, key, k, &f, &m, why, whylen);
    if (rc != 1) return rc;
    if (!cf_check_source(&f, src, why, whylen)) {
        cf_close(&f);
        return 0;
    }
    cf_map *map = cf_map_open(&f, why, whylen);
    uint64_t body_hash = f.head.body_hash, block_len = f.head.body_len;
    cf_close(&f);
    if (!map) return -1;
    const uint8_t *block = map->addr + CF_PAGE;
    /* Read through the guarded mapping: a file cut meanwhile reads as zeros, and says so. */
    int bad = sd_hash64(block, (size_t)block_len, 0) != body_hash;
    if (cf_map_changed(map)) {
        snprintf(why, whylen, "it became shorter while it was being read");
        bad = 1;
    } else if (bad) {
        snprintf(why, whylen, "its data is corrupt (checksum mismatch)");
    }
    /* The batches must tile [0, n) in order, as prep writes them: the count in the header and
     * the batches then agree (a count off by one within a section's alignment padding would
     * otherwise be taken as it is, and the renderer trusts the batches). */
    pc_prepared where = {.n = m.n, .attrs = m.attrs, .nbatches = m.nbatches};
    pc_prepared_bind(&where, (void *)block);
    const pc_batch *bt = where.batches;
    uint64_t next = 0;
    for (uint64_t i = 0; i < m.nbatches && !bad; i++) {
        if (bt[i].first != next || bt[i].count == 0 || bt[i].count > m.n - next) {
            snprintf(why, whylen, "batch %llu [%u, +%u) does not follow the previous one in its "
                     "%llu points", (unsigned long long)i, bt[i].first, bt[i].count,
                     (unsigned long long)m.n);
            bad = 1;
        }
        next += bt[i].count;
    }
    if (!bad && next != m.n) {
        snprintf(why, whylen, "its batches hold %llu points, its header says %llu",
                 (unsigned long long)next, (unsigned long long)m.n);
        bad = 1;
    }
    if (bad) {
        cf_map_close(map);
        return -1;
    }
    memset(out, 0, sizeof *out);
    out->n = m.n;
    out->attrs = m.attrs;
    out->k = m.k;
    out->nbatches = m.nbatches;
    PC_SUMMARY_COPY(out, &m.sum);
    memcpy(out->scalar_name, m.scalar_name, sizeof out->scalar_name);
    out->scalar_name[sizeof out->scalar_name - 1] = 0;
    out->stats = m.stats;
    out->map = (void *)map->addr;
    out->map_len = map->len;
    out->file = map;
    pc_prepared_bind(out, (void *)block);
    return 1;
}

int cache_probe(const char *src, const char *dir, int k)
{
    return cache_probe_points(src, dir, k, NULL);
}

int cache_probe_points(const char *src, const char *dir, int k, uint64_t *points)
{
    if (k <= 0) k = PREP_DEFAULT_K;
    char cpath[4096], why[256];
    cf_key key;
    if (cache_path_for(src, dir, k, cpath, sizeof cpath, NULL) != 0 ||
        cf_key_stat(src, &key, NULL) != 0)
        return 0;
    cf_file f;
    flat_meta m;
    if (open_checked(cpath, &key, k, &f, &m, why, sizeof why) != 1) return 0;
    cf_close(&f);
    if (points) *points = m.n;
    return 1;
}

/* Writes p to cpath through a cf_writer (cachefile.h: a new file, fsynced, renamed over
 * cpath). Returns 0 or SD_EIO with err. */
static int write_cache(const char *cpath, const cf_key *key, const pc_prepared *p, sd_err *err)
{
    flat_meta m = {.k = p->k, .attrs = p->attrs, .n = p->n, .nbatches = p->nbatches,
                   .stats = p->stats};
    PC_SUMMARY_COPY(&m.sum, p);
    memcpy(m.scalar_name, p->scalar_name, sizeof m.scalar_name);
    cf_head h = {.src = *key, .options = p->k, .file_len = CF_PAGE + p->block_len,
                 .body_off = CF_PAGE, .body_len = p->block_len,
                 .body_hash = sd_hash64(p->block, p->block_len, 0)};
    cf_writer w;
    int rc = cf_writer_open(&w, cpath, err);
    if (rc < 0) return rc;
    if (cf_pwrite_all(w.fd, p->block, p->block_len, CF_PAGE) < 0) {
        int e = errno;
        cf_writer_abort(&w);
        return sd_errf(err, SD_EIO, "cannot write cache %s: %s", cpath, strerror(e));
    }
    rc = cf_writer_commit(&w, &FLAT, &h, &m, err);
    cf_writer_abort(&w);
    return rc;
}

int cache_open_cloud(const char *src, const cache_desc *d, pc_prepared *out, cache_result *res,
                     sd_err *err)
{
    cache_desc dd = d ? *d : (cache_desc){0};
    if (dd.k <= 0) dd.k = PREP_DEFAULT_K;
    cache_result rr;
    memset(&rr, 0, sizeof rr);
    memset(out, 0, sizeof *out);
    int rc;

    double t0 = now_s();
    cf_key key = {0};
    if ((rc = cf_key_stat(src, &key, err)) < 0) return rc;
    rr.file_size = key.size;
    if ((rc = cache_path_for(src, dd.dir, dd.k, rr.path, sizeof rr.path, err)) < 0) return rc;

    int got = dd.force ? 0 : try_load(rr.path, src, &key, dd.k, out, rr.why, sizeof rr.why);
    if (cf_loaded(dd.force, got, FLAT.what, rr.path, rr.why, sizeof rr.why, dd.warn, dd.user)) {
        rr.hit = 1;
        rr.t_read = now_s() - t0;
        if (res) *res = rr;
        return 0;
    }

    /* The reader checks the file's header before it reads the rest, so a file that is no cloud
     * fails at once; the content hash for the new cache's key is taken after a successful
     * parse (the bytes are then in the page cache), from a file of the same size and time. */
    pc_cloud cloud;
    if ((rc = pc_load_threads(src, dd.threads, &cloud, err)) < 0) return rc;
    if ((rc = cf_key_hash(src, CF_HASH_ALL, &key, err)) < 0) {
        pc_cloud_free(&cloud);
        return rc;
    }
    rr.t_read = now_s() - t0;

    double t1 = now_s();
    prep_desc pd = {.k = dd.k, .threads = dd.threads, .progress = dd.progress, .user = dd.user};
    rc = prep_run(&cloud, &pd, out, err);
    pc_cloud_free(&cloud);
    if (rc < 0) return rc;
    rr.t_prep = now_s() - t1;

    double t2 = now_s();
    sd_err werr = {0};
    if (write_cache(rr.path, &key, out, &werr) < 0) {
        rr.write_failed = 1;
        snprintf(rr.write_error, sizeof rr.write_error, "%s", werr.msg);
        if (dd.warn) {
            char msg[700];
            snprintf(msg, sizeof msg, "%s (continuing without a cache)", werr.msg);
            dd.warn(dd.user, msg);
        }
    }
    rr.t_write = now_s() - t2;
    if (res) *res = rr;
    return 0;
}

int cache__set_version(const char *cache_path, uint32_t version)
{
    return cf__set_version(cache_path, version);
}

int cache__seal(const char *cache_path, const char *src)
{
    return cf__seal(cache_path, src, CF_HASH_ALL, 0, 0);
}

int cache__load(const char *cache_path, const char *src, int k, pc_prepared *out, char *why,
                size_t whylen)
{
    cf_key key = {0};
    sd_err err = {0};
    if (cf_key_stat(src, &key, &err) < 0) {
        snprintf(why, whylen, "%s", err.msg);
        return -1;
    }
    return try_load(cache_path, src, &key, k, out, why, whylen);
}
