/* laz_stream.c — a LAZ file's points decoded a round of chunks at a time (laz_stream.h). */
#include "laz_stream.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "cloud.h"
#include "io_text.h"
#include "las_header.h"
#include "laz.h"

enum { MAX_THREADS = 16, LAS_FORMAT_BYTE = 104 };

typedef struct slot {
    pc_laz_stream *s;
    laz_chunk_dec *cd;
    uint8_t *buf;            /* the chunk's LAS records */
    size_t cap;
    pc_raw raw;              /* its points (xyz, intensity, class) */
    uint16_t *rgb16;         /* its 16-bit colours, when the format has them */
    size_t rgb_cap;
    size_t chunk, npts;
    int rc;
    sd_err err;
} slot;

struct pc_laz_stream {
    char path[4096];
    pc__file f;
    laz_file lf;
    int threads, has_rgb;
    char format[64];
    slot slot[MAX_THREADS];
    int nslots;              /* slots of the held round */
    uint64_t first, end;     /* its points */
};

/* 1 when the mapped file starts as a LAS file whose format byte has the compression bits. */
static int is_laz(void *arg)
{
    const pc_laz_stream *s = arg;
    return s->f.size > LAS_FORMAT_BYTE && memcmp(s->f.data, "LASF", 4) == 0 &&
           (s->f.data[LAS_FORMAT_BYTE] & 0xC0) != 0;
}

typedef struct open_job {
    pc_laz_stream *s;
    sd_err *err;
} open_job;

static int open_guarded(void *arg)
{
    open_job *j = arg;
    return laz_open(&j->s->lf, j->s->path, j->s->f.data, j->s->f.size, j->err);
}

int pc_laz_stream_open(const char *path, int threads, pc_laz_stream **out, sd_err *err)
{
    *out = NULL;
    pc_laz_stream *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    snprintf(s->path, sizeof s->path, "%s", path);
    int rc = pc__file_open(path, &s->f, err);
    open_job oj = {s, err};
    if (rc == 0 && (rc = pc__guarded(&s->f, path, is_laz, s, err)) == 1)
        rc = pc__guarded(&s->f, path, open_guarded, &oj, err);
    else if (rc == 0)
        rc = 1; /* not LAZ */
    if (rc != 0) {
        pc_laz_stream_close(s);
        return rc == 1 ? 0 : rc;
    }
    if (threads < 1) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        threads = n < 1 ? 1 : (int)n;
    }
    if (threads > MAX_THREADS) threads = MAX_THREADS;
    if ((size_t)threads > s->lf.nchunks) threads = (int)s->lf.nchunks;
    s->threads = threads;
    s->has_rgb = pc__las_formats[s->lf.h.format].rgb != 0;
    for (int t = 0; t < threads; t++) {
        slot *sl = &s->slot[t];
        sl->s = s;
        sl->raw.attrs = PC_ATTR_INTENSITY | PC_ATTR_CLASS;
    }
    snprintf(s->format, sizeof s->format, "%s 1.%u format %u",
             s->lf.copc_info ? "COPC LAZ" : "LAZ", s->lf.h.minor, s->lf.h.format);
    *out = s;
    return 1;
}

void pc_laz_stream_close(pc_laz_stream *s)
{
    if (!s) return;
    for (int t = 0; t < MAX_THREADS; t++) {
        slot *sl = &s->slot[t];
        laz_chunk_dec_free(sl->cd);
        free(sl->buf);
        pc_raw_free(&sl->raw);
        free(sl->rgb16);
    }
    laz_close(&s->lf);
    pc__file_close(&s->f);
    free(s);
}

uint64_t pc_laz_stream_count(const pc_laz_stream *s)
{
    return s->lf.chunk_first[s->lf.nchunks];
}

int pc_laz_stream_has_rgb(const pc_laz_stream *s)
{
    return s->has_rgb;
}

const char *pc_laz_stream_format(const pc_laz_stream *s)
{
    return s->format;
}

static int decode_guarded(void *arg)
{
    slot *sl = arg;
    return laz_read_chunk(&sl->s->lf, sl->cd, sl->chunk, &sl->buf, &sl->cap, &sl->err);
}

/* One slot's chunk: decoded under the guard, then converted as pc_read_laz converts, into the
 * slot's own arrays grown by the points that really decoded. */
static void *slot_run(void *arg)
{
    slot *sl = arg;
    pc_laz_stream *s = sl->s;
    sl->npts = 0;
    /* each slot's decoder is made by the first thread that decodes with it, so its models
     * (updated at every symbol) come from that thread's heap, not beside another thread's
     * (io_laz.c measured the difference: 1.67 against 1.86x on two threads) */
    if (!sl->cd && !(sl->cd = laz_chunk_dec_create(s->lf.items, s->lf.nitems))) {
        sl->rc = sd_errf(&sl->err, SD_ENOMEM, "%s: no memory for a LAZ chunk decoder", s->path);
        return NULL;
    }
    sl->rc = pc__guarded(&s->f, s->path, decode_guarded, sl, &sl->err);
    if (sl->rc) return NULL;
    size_t n = (size_t)(s->lf.chunk_first[sl->chunk + 1] - s->lf.chunk_first[sl->chunk]);
    sl->rc = pc_raw_reserve(&sl->raw, n, &sl->err);
    if (sl->rc) return NULL;
    if (s->has_rgb && n > sl->rgb_cap) {
        uint16_t *nb = realloc(sl->rgb16, 3 * n * sizeof *nb);
        if (!nb) {
            sl->rc = sd_errf(&sl->err, SD_ENOMEM, "%s: no memory for the colours of chunk %zu",
                             s->path, sl->chunk);
            return NULL;
        }
        sl->rgb16 = nb;
        sl->rgb_cap = n;
    }
    pc__las_convert(&s->lf.h, sl->buf, n, &sl->raw, 0, 0, s->has_rgb ? sl->rgb16 : NULL);
    sl->npts = n;
    return NULL;
}

/* Gives the decoded chunks' pages back: the mapping stays, the resident size does not grow
 * with the file. */
static void release_pages(const pc_laz_stream *s, size_t c0, size_t c1)
{
    long pg = sysconf(_SC_PAGESIZE);
    if (pg <= 0) return;
    uintptr_t base = (uintptr_t)s->f.data;
    uintptr_t a = base + (uintptr_t)s->lf.chunk_start[c0];
    uintptr_t b = base + (uintptr_t)s->lf.chunk_start[c1];
    a = (a + (uintptr_t)pg - 1) & ~((uintptr_t)pg - 1);
    b &= ~((uintptr_t)pg - 1);
    if (b > a) (void)madvise((void *)a, b - a, MADV_DONTNEED);
}

/* Decodes the round of chunks starting at c0 (one per thread), the calling thread taking the
 * first. */
static int decode_round(pc_laz_stream *s, size_t c0, sd_err *err)
{
    const laz_file *lf = &s->lf;
    int n = 0;
    while (n < s->threads && c0 + (size_t)n < lf->nchunks) {
        s->slot[n].chunk = c0 + (size_t)n;
        n++;
    }
    pthread_t th[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int t = 1; t < n; t++)
        started[t] = pthread_create(&th[t], NULL, slot_run, &s->slot[t]) == 0;
    slot_run(&s->slot[0]);
    for (int t = 1; t < n; t++) {
        if (started[t]) pthread_join(th[t], NULL);
        else slot_run(&s->slot[t]); /* no thread: decode it here */
    }
    s->nslots = 0;
    s->first = s->end = lf->chunk_first[c0];
    for (int t = 0; t < n; t++)
        if (s->slot[t].rc) {
            if (err) *err = s->slot[t].err;
            return s->slot[t].rc;
        }
    release_pages(s, c0, c0 + (size_t)n);
    s->nslots = n;
    s->end = lf->chunk_first[c0 + (size_t)n];
    return 0;
}

/* The chunk holding point p (p below the count): the last whose first point is <= p, which
 * skips empty chunks. */
static size_t chunk_of(const laz_file *lf, uint64_t p)
{
    size_t lo = 0, hi = lf->nchunks; /* chunk_first[lo] <= p < chunk_first[hi] */
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (lf->chunk_first[mid] <= p) lo = mid;
        else hi = mid;
    }
    return lo;
}

int pc_laz_stream_read(pc_laz_stream *s, uint64_t first, size_t m, double *xyz, uint16_t *rgb16,
                       sd_err *err)
{
    uint64_t count = pc_laz_stream_count(s);
    if (first > count || m > count - first)
        return sd_errf(err, SD_EINVAL, "%s: points %llu to %llu asked of %llu", s->path,
                       (unsigned long long)first, (unsigned long long)(first + m),
                       (unsigned long long)count);
    while (m > 0) {
        if (first < s->first || first >= s->end) {
            size_t c = s->end == first && s->nslots ? s->slot[s->nslots - 1].chunk + 1
                                                     : chunk_of(&s->lf, first);
            int rc = decode_round(s, c, err);
            if (rc) return rc;
            continue;
        }
        uint64_t at = s->first; /* the slots' points follow each other from s->first */
        for (int t = 0; t < s->nslots && m > 0; t++) {
            const slot *sl = &s->slot[t];
            if (first >= at + sl->npts) {
                at += sl->npts;
                continue;
            }
            size_t i = (size_t)(first - at), k = sl->npts - i < m ? sl->npts - i : m;
            memcpy(xyz, sl->raw.xyz + 3 * i, 3 * k * sizeof *xyz);
            if (rgb16 && s->has_rgb) {
                memcpy(rgb16, sl->rgb16 + 3 * i, 3 * k * sizeof *rgb16);
                rgb16 += 3 * k;
            }
            xyz += 3 * k;
            first += k;
            m -= k;
            at += sl->npts;
        }
    }
    return 0;
}
