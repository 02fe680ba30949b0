/* io_laz.c — the LAZ reader: a LAZ file (or COPC, which is LAZ 1.4 with its chunks ordered as
 * an octree) into the raw cloud, its chunks decoded in parallel.
 *
 * Chunks are independent (each restarts the coder), so T threads decode T chunks at a time,
 * each into its own record buffer that grows only as points really decode. After each round
 * the calling thread grows the cloud by what was decoded, never by what the chunk table
 * claims, and the same threads then convert their records into it (xyz, intensity, class,
 * colour), each into its own range. Each thread reads the mapping under its own SIGBUS guard,
 * so a file that shrinks mid-read fails cleanly. */
#include "cloud.h"
#include "io_text.h"
#include "las_header.h"
#include "laz.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { LAZ_MAX_THREADS = 64 };

typedef struct slot {
    laz_chunk_dec *cd;
    uint8_t *buf;
    size_t cap;
    size_t chunk;        /* this round's chunk, or SIZE_MAX for none */
    size_t npts;         /* the points decoded */
    size_t at;           /* where they go in the cloud (the convert phase) */
    int rc;
    sd_err err;
} slot;

typedef struct laz_run {
    const char *path;
    const pc__file *f;
    laz_file lf;
    int threads;
    slot s[LAZ_MAX_THREADS];
    pthread_barrier_t start, done;
    pthread_mutex_t gate_mu;     /* the gate: workers wait here until every one started */
    pthread_cond_t gate_cv;
    int gate, quit;
    int convert;                 /* this phase: 0 decode, 1 convert into raw / rgb16 */
    pc_raw *raw;
    uint16_t *rgb16;             /* colours of 16 bits, scaled once all are read; or NULL */
} laz_run;

typedef struct one_job {
    laz_run *r;
    slot *s;
} one_job;

static int decode_one(void *arg)
{
    one_job *j = arg;
    slot *s = j->s;
    const laz_file *lf = &j->r->lf;
    s->npts = 0;
    int rc = laz_read_chunk(lf, s->cd, s->chunk, &s->buf, &s->cap, &s->err);
    if (!rc) s->npts = (size_t)(lf->chunk_first[s->chunk + 1] - lf->chunk_first[s->chunk]);
    return rc;
}

typedef struct worker {
    laz_run *r;
    int tid;
} worker;

/* The decoding threads: every one reads the mapping under its own SIGBUS guard; the calling
 * thread only hands out chunks and grows the cloud, so it never touches the mapping while they
 * run (a jump out of it would leave them waiting). In the convert phase each converts its
 * slot's records into the cloud range the calling thread gave it (no mapping read there). */
static void *worker_main(void *arg)
{
    worker *w = arg;
    laz_run *r = w->r;
    pthread_mutex_lock(&r->gate_mu);
    while (!r->gate) pthread_cond_wait(&r->gate_cv, &r->gate_mu);
    pthread_mutex_unlock(&r->gate_mu);
    if (r->quit) return NULL; /* not every thread started: leave before any barrier */
    for (;;) {
        pthread_barrier_wait(&r->start);
        if (r->quit) break;
        slot *s = &r->s[w->tid];
        if (s->chunk != SIZE_MAX && r->convert) {
            pc__las_convert(&r->lf.h, s->buf, s->npts, r->raw, s->at, 0, r->rgb16);
        } else if (s->chunk != SIZE_MAX) {
            one_job j = {r, s};
            s->rc = pc__guarded(r->f, r->path, decode_one, &j, &s->err);
        }
        pthread_barrier_wait(&r->done);
    }
    return NULL;
}

/* grow: room in raw (and rgb16) for the records every slot decoded, and each slot's place
 * there, in chunk order; the workers convert them next. */
static int grow(laz_run *r, pc_raw *raw, uint16_t **rgb16, size_t *rgb_cap, int has_rgb,
                sd_err *err)
{
    size_t add = 0;
    for (int t = 0; t < r->threads; t++) add += r->s[t].chunk == SIZE_MAX ? 0 : r->s[t].npts;
    if (raw->n + add > raw->cap) {
        /* grow by half what is held, never past twice what decoded (the chunk table's
         * count is only a claim until the points decode) */
        size_t need = raw->n + add, want = raw->cap + raw->cap / 2;
        if (want < need) want = need;
        if (want > 2 * need) want = 2 * need;
        if (want > r->lf.h.count) want = (size_t)r->lf.h.count;
        int rc = pc_raw_reserve(raw, want, err);
        if (rc) return rc;
        if (has_rgb && want > *rgb_cap) {
            uint16_t *nb = realloc(*rgb16, sizeof(uint16_t) * 3 * want);
            if (!nb)
                return sd_errf(err, SD_ENOMEM, "%s: no memory for the colours of %zu points",
                               r->path, want);
            *rgb16 = nb;
            *rgb_cap = want;
        }
    }
    size_t at = raw->n;
    for (int t = 0; t < r->threads; t++) {
        slot *s = &r->s[t];
        if (s->chunk == SIZE_MAX) continue;
        s->at = at;
        at += s->npts;
    }
    return 0;
}

static int decode_all(laz_run *r, pc_raw *raw, sd_err *err)
{
    const laz_file *lf = &r->lf;
    int has_rgb = pc__las_formats[lf->h.format].rgb != 0;
    raw->attrs = PC_ATTR_INTENSITY | PC_ATTR_CLASS | (has_rgb ? PC_ATTR_RGB : 0);
    uint16_t *rgb16 = NULL;
    size_t rgb_cap = 0;
    int rc = 0;
    pthread_t th[LAZ_MAX_THREADS];
    worker w[LAZ_MAX_THREADS];
    int started = 0;
    for (int t = 0; t < r->threads; t++) {
        r->s[t].cd = laz_chunk_dec_create(lf->items, lf->nitems);
        if (!r->s[t].cd) {
            rc = sd_errf(err, SD_ENOMEM, "%s: no memory for a LAZ chunk decoder", r->path);
            goto out;
        }
    }
    /* the barriers count the decoding threads and this one; the workers pass them only once
     * the gate opens with every thread started */
    pthread_barrier_init(&r->start, NULL, (unsigned)r->threads + 1);
    pthread_barrier_init(&r->done, NULL, (unsigned)r->threads + 1);
    pthread_mutex_init(&r->gate_mu, NULL);
    pthread_cond_init(&r->gate_cv, NULL);
    for (int t = 0; t < r->threads; t++) {
        w[t] = (worker){r, t};
        if (pthread_create(&th[t], NULL, worker_main, &w[t]) != 0) break;
        started++;
    }
    pthread_mutex_lock(&r->gate_mu);
    r->quit = started < r->threads;
    r->gate = 1;
    pthread_cond_broadcast(&r->gate_cv);
    pthread_mutex_unlock(&r->gate_mu);
    if (r->quit) {
        for (int t = 0; t < started; t++) pthread_join(th[t], NULL);
        rc = sd_errf(err, SD_ENOMEM, "%s: could not start %d decoding threads", r->path,
                     r->threads);
        goto done_threads;
    }
    for (size_t c0 = 0; c0 < lf->nchunks && !rc; c0 += (size_t)r->threads) {
        for (int t = 0; t < r->threads; t++) {
            size_t c = c0 + (size_t)t;
            r->s[t].chunk = c < lf->nchunks ? c : SIZE_MAX;
            r->s[t].rc = 0;
        }
        pthread_barrier_wait(&r->start);
        pthread_barrier_wait(&r->done);
        for (int t = 0; t < r->threads && !rc; t++)
            if (r->s[t].chunk != SIZE_MAX && r->s[t].rc) {
                rc = r->s[t].rc;
                if (err) *err = r->s[t].err;
            }
        if (!rc) rc = grow(r, raw, &rgb16, &rgb_cap, has_rgb, err);
        if (!rc) {
            r->raw = raw;
            r->rgb16 = has_rgb ? rgb16 : NULL;
            r->convert = 1;
            pthread_barrier_wait(&r->start);
            pthread_barrier_wait(&r->done);
            r->convert = 0;
            for (int t = 0; t < r->threads; t++)
                if (r->s[t].chunk != SIZE_MAX) raw->n += r->s[t].npts;
        }
    }
    r->quit = 1;
    pthread_barrier_wait(&r->start);
    for (int t = 0; t < r->threads; t++) pthread_join(th[t], NULL);
done_threads:
    pthread_barrier_destroy(&r->start);
    pthread_barrier_destroy(&r->done);
    pthread_mutex_destroy(&r->gate_mu);
    pthread_cond_destroy(&r->gate_cv);
    if (!rc && has_rgb) pc__las_rgb16(rgb16, raw->n, raw);
out:
    free(rgb16);
    for (int t = 0; t < r->threads; t++) {
        laz_chunk_dec_free(r->s[t].cd);
        free(r->s[t].buf);
    }
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
