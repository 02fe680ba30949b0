/* io_laz.c — the LAZ reader: a LAZ file (or COPC, which is LAZ 1.4 with its chunks ordered as
 * an octree) into the raw cloud, its chunks decoded in parallel.
 *
 * Chunks are independent (each restarts the coder). T threads (the calling one and T - 1 more)
 * take work from one queue: decode the next chunk into a free record buffer (each grows only as
 * points really decode), or convert a decoded chunk into the cloud (xyz, intensity, class,
 * colour), each into its own range. A thread takes the next chunk as soon as it is free (no
 * rounds): with more threads than chunks left, the idle ones convert what the others decoded.
 * The cloud grows only by what really decoded: chunks 0 .. prefix-1 all decoded, never the
 * chunk table's claim for the rest; it grows only while no conversion writes into it. Each
 * decode reads the mapping under its thread's SIGBUS guard, so a file that shrinks mid-read
 * fails cleanly. */
#include "cloud.h"
#include "io_text.h"
#include "las_header.h"
#include "laz.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { LAZ_MAX_THREADS = 64, BUFS_PER_THREAD = 2, RGBA_SLICE = 16384 };

typedef struct recbuf {
    uint8_t *buf;
    size_t cap;
    int busy;                    /* holds a chunk being decoded or waiting to be converted */
} recbuf;

typedef struct laz_run {
    const char *path;
    const pc__file *f;
    laz_file lf;
    int threads;
    laz_chunk_dec *cd[LAZ_MAX_THREADS];
    recbuf b[LAZ_MAX_THREADS * BUFS_PER_THREAD];
    int nbufs;
    int *bufof;                  /* per chunk: its record buffer once handed out */
    pthread_mutex_t mu;          /* everything below */
    pthread_cond_t cv;           /* a task finished */
    size_t next_dec;             /* the next chunk to decode */
    size_t prefix;               /* chunks 0 .. prefix-1 are decoded */
    unsigned char *decoded;      /* per chunk */
    size_t next_conv;            /* the next chunk to convert (all below prefix can) */
    size_t converted;            /* chunks converted */
    int conv_busy;               /* conversions writing into the cloud now */
    int rc;                      /* the first error, of chunk err_chunk */
    size_t err_chunk;
    sd_err err;
    pc_raw *raw;
    uint16_t *rgb16;             /* colours of 16 bits, scaled once all are read; or NULL */
    size_t rgb_cap;
    int has_rgb;
    int wide;                    /* some colour converted so far needs more than 8 bits */
    size_t next_rgba;            /* the last phase: raw->rgba from rgb16, in slices */
} laz_run;

typedef struct dec_job {
    laz_run *r;
    laz_chunk_dec *cd;
    size_t chunk;
    recbuf *b;
    sd_err err;
} dec_job;

static int decode_one(void *arg)
{
    dec_job *j = arg;
    return laz_read_chunk(&j->r->lf, j->cd, j->chunk, &j->b->buf, &j->b->cap, &j->err);
}

/* grow: room in the cloud (and rgb16) for the points of chunks 0 .. prefix-1, all decoded:
 * twice that, never more (the chunk table's count for chunks not yet decoded is only a claim),
 * nor more than the file's count. Twice, so that a later chunk rarely needs another grow: a
 * grow waits for every conversion to end, and touches fresh pages while copying (1.7 ms on
 * autzen_trim's last chunk). Called with the lock held and no conversion running. */
static int grow(laz_run *r, sd_err *err)
{
    pc_raw *raw = r->raw;
    size_t need = (size_t)r->lf.chunk_first[r->prefix], want = 2 * need;
    if (want > r->lf.h.count) want = (size_t)r->lf.h.count;
    int rc = pc_raw_reserve(raw, want, err);
    if (rc) return rc;
    if (r->has_rgb && want > r->rgb_cap) {
        uint16_t *nb = realloc(r->rgb16, sizeof(uint16_t) * 3 * want);
        if (!nb)
            return sd_errf(err, SD_ENOMEM, "%s: no memory for the colours of %zu points",
                           r->path, want);
        r->rgb16 = nb;
        r->rgb_cap = want;
    }
    return 0;
}

static void fail(laz_run *r, size_t chunk, int rc, const sd_err *e)
{
    if (!r->rc || chunk < r->err_chunk) {
        r->rc = rc;
        r->err_chunk = chunk;
        r->err = *e;
    }
}

/* work: the loop of every thread (tid 0 is the calling one) until every chunk is converted or
 * one failed. A thread converts first when it is alone (the records it just decoded are
 * still in cache), else decodes first (conversion fills the time when no chunk is left). */
static void work(laz_run *r, int tid)
{
    const laz_file *lf = &r->lf;
    size_t n = lf->nchunks;
    if (!r->cd[tid]) r->cd[tid] = laz_chunk_dec_create(lf->items, lf->nitems);
    pthread_mutex_lock(&r->mu);
    if (!r->cd[tid]) {
        sd_err e;
        fail(r, 0, sd_errf(&e, SD_ENOMEM, "%s: no memory for a LAZ chunk decoder", r->path),
             &e);
    }
    for (;;) {
        if (r->rc || r->converted == n) break;
        int bi = -1;
        for (int i = 0; i < r->nbufs && r->next_dec < n; i++)
            if (!r->b[i].busy) {
                bi = i;
                break;
            }
        int can_conv = r->next_conv < r->prefix &&
                       (r->raw->cap >= lf->chunk_first[r->next_conv + 1] || !r->conv_busy);
        if (can_conv && (bi < 0 || r->threads == 1)) {
            size_t c = r->next_conv;
            if (r->raw->cap < lf->chunk_first[c + 1]) {
                sd_err e = {0};
                int rc = grow(r, &e);
                if (rc) {
                    fail(r, c, rc, &e);
                    break;
                }
            }
            r->next_conv++;
            r->conv_busy++;
            recbuf *b = &r->b[r->bufof[c]];
            pthread_mutex_unlock(&r->mu);
            size_t at = (size_t)lf->chunk_first[c];
            size_t np = (size_t)lf->chunk_first[c + 1] - at;
            pc__las_convert(&lf->h, b->buf, np, r->raw, at, 0, r->has_rgb ? r->rgb16 : NULL);
            int wide = r->has_rgb && pc__las_rgb16_wide(r->rgb16 + 3 * at, np);
            pthread_mutex_lock(&r->mu);
            b->busy = 0;
            r->wide |= wide;
            r->conv_busy--;
            r->converted++;
            pthread_cond_broadcast(&r->cv);
        } else if (bi >= 0) {
            size_t c = r->next_dec++;
            r->b[bi].busy = 1;
            r->bufof[c] = bi;
            pthread_mutex_unlock(&r->mu);
            dec_job j = {r, r->cd[tid], c, &r->b[bi], {0}};
            int rc = pc__guarded(r->f, r->path, decode_one, &j, &j.err);
            pthread_mutex_lock(&r->mu);
            if (rc) fail(r, c, rc, &j.err);
            r->decoded[c] = 1;
            while (r->prefix < n && r->decoded[r->prefix]) r->prefix++;
            pthread_cond_broadcast(&r->cv);
        } else {
            pthread_cond_wait(&r->cv, &r->mu);
        }
    }
    pthread_cond_broadcast(&r->cv); /* done or failed: wake the others to see it */
    /* every chunk converted: the colours scaled into raw->rgba, the threads taking slices (the
     * first touch of rgba's pages, serial, was 4 % of the two-thread time on autzen_trim) */
    size_t npts = (size_t)lf->h.count;
    while (!r->rc && r->has_rgb && r->next_rgba < npts) {
        size_t lo = r->next_rgba, hi = npts - lo > RGBA_SLICE ? lo + RGBA_SLICE : npts;
        r->next_rgba = hi;
        pthread_mutex_unlock(&r->mu);
        pc__las_rgb16_range(r->rgb16, lo, hi, r->wide, r->raw);
        pthread_mutex_lock(&r->mu);
    }
    pthread_mutex_unlock(&r->mu);
}

typedef struct worker {
    laz_run *r;
    int tid;
} worker;

static void *worker_main(void *arg)
{
    worker *w = arg;
    work(w->r, w->tid);
    return NULL;
}

static int decode_all(laz_run *r, pc_raw *raw, sd_err *err)
{
    const laz_file *lf = &r->lf;
    r->has_rgb = pc__las_formats[lf->h.format].rgb != 0;
    raw->attrs = PC_ATTR_INTENSITY | PC_ATTR_CLASS | (r->has_rgb ? PC_ATTR_RGB : 0);
    r->raw = raw;
    int rc = 0;
    /* per chunk: nchunks is bounded by the bytes between the first chunk and the table */
    r->bufof = calloc(lf->nchunks, sizeof *r->bufof);
    r->decoded = calloc(lf->nchunks, 1);
    if (!r->bufof || !r->decoded) {
        rc = sd_errf(err, SD_ENOMEM, "%s: no memory for the LAZ reader", r->path);
        goto out;
    }
    /* this thread's decoder; the others make theirs in their own thread (work), so that
     * the two decoders' models, written every symbol, never share a cache line */
    r->cd[0] = laz_chunk_dec_create(lf->items, lf->nitems);
    if (!r->cd[0]) {
        rc = sd_errf(err, SD_ENOMEM, "%s: no memory for a LAZ chunk decoder", r->path);
        goto out;
    }
    r->nbufs = BUFS_PER_THREAD * r->threads;
    pthread_mutex_init(&r->mu, NULL);
    pthread_cond_init(&r->cv, NULL);
    pthread_t th[LAZ_MAX_THREADS];
    worker w[LAZ_MAX_THREADS];
    int started = 1; /* the calling thread is worker 0; the queue works with any that start */
    for (int t = 1; t < r->threads; t++) {
        w[t] = (worker){r, t};
        if (pthread_create(&th[t], NULL, worker_main, &w[t]) != 0) break;
        started++;
    }
    work(r, 0);
    for (int t = 1; t < started; t++) pthread_join(th[t], NULL);
    pthread_mutex_destroy(&r->mu);
    pthread_cond_destroy(&r->cv);
    rc = r->rc;
    if (rc) {
        if (err) *err = r->err;
    } else {
        raw->n = (size_t)lf->h.count;
    }
out:
    free(r->rgb16);
    free(r->bufof);
    free(r->decoded);
    for (int t = 0; t < r->threads; t++) laz_chunk_dec_free(r->cd[t]);
    for (int i = 0; i < r->nbufs; i++) free(r->b[i].buf);
    return rc;
}

typedef struct open_job {
    laz_file *lf;
    const char *path;
    const pc__file *f;
    sd_err *err;
} open_job;

static int open_guarded(void *arg)
{
    open_job *j = arg;
    return laz_open(j->lf, j->path, j->f->data, j->f->size, j->err);
}

int pc_read_laz_threads(const char *path, pc_raw *raw, int threads, sd_err *err)
{
    pc__file file;
    int rc = pc__file_open(path, &file, err);
    if (rc) return rc;
    laz_run *r = calloc(1, sizeof *r);
    if (!r) {
        pc__file_close(&file);
        return sd_errf(err, SD_ENOMEM, "%s: no memory for the LAZ reader", path);
    }
    r->path = path;
    r->f = &file;
    open_job oj = {&r->lf, path, &file, err};
    /* a jump out of laz_open leaves its chunk table allocated: close frees it either way */
    rc = pc__guarded(&file, path, open_guarded, &oj, err);
    if (!rc) {
        if (threads < 1) {
            long n = sysconf(_SC_NPROCESSORS_ONLN);
            threads = n < 1 ? 1 : (int)n;
        }
        if (threads > LAZ_MAX_THREADS) threads = LAZ_MAX_THREADS;
        if ((size_t)threads > r->lf.nchunks) threads = (int)r->lf.nchunks;
        r->threads = threads;
        rc = decode_all(r, raw, err);
        if (!rc)
            snprintf(raw->format, sizeof raw->format, "%s 1.%u format %u", r->lf.copc_info ?
                     "COPC LAZ" : "LAZ", r->lf.h.minor, r->lf.h.format);
    }
    laz_close(&r->lf);
    free(r);
    pc__file_close(&file);
    return rc;
}

int pc_read_laz(const char *path, pc_raw *raw, sd_err *err)
{
    return pc_read_laz_threads(path, raw, 0, err);
}
