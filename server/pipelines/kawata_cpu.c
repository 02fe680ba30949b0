/* kawata_cpu.c — kawata's passes 1 and 2 on the host (kawata_cpu.h). */
#include "kawata_cpu.h"

#include <stdlib.h>
#include <string.h>

#include "progress.h"
#include "simd.h"
#include "soft_cpu.h"

enum { BLOCK = 1 << 14 };       /* points a task */

/* The lanes of a:b (a's are 0-7, b's 8-15) at constant indices. __builtin_shufflevector is in
 * both GCC (12 on) and clang; GCC's __builtin_shuffle is not in clang. */
#define SHUF(a, b, ...) __builtin_shufflevector(a, b, __VA_ARGS__)

typedef struct run {
    const kawata_cpu_job *job;
    uint64_t k0, k1;           /* this batch: visible points [k0, k1) */
    int nt;                    /* threads */
    uint32_t npix;             /* the rectangle's pixels: (y1 - y0) (x1 - x0), row by row */
    /* each thread's depth, near and far: npix words and a spare one that the points outside
     * the rows go to; after pass 1 thread 0's depth is the merged one */
    uint32_t *arr[KAWATA_CPU_MAX_THREADS][3];
    int pass1;                 /* the projection also does pass 1 */
} run;

static inline float bits_float(uint32_t u)
{
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static inline uint32_t float_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

/* The segment holding visible point k (segk ascending, segk[0] = 0). */
static uint32_t seg_of(const kawata_cpu_job *job, uint64_t k)
{
    const uint64_t *segk = job->mem->segk;
    uint32_t lo = 0, hi = job->nsegs - 1;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo + 1) / 2;
        if (segk[mid] <= k) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

/* Projects n points at pos into pix/key: the shader's
 *   c = u_viewproj * vec4(p, 1.0); d = c.w; b = (c.xy / d * 0.5 + 0.5) * fb;
 * as ((col0 x + col1 y) + col2 z) + col3 (col3 times 1.0 is col3), each product and sum
 * rounded (precise), eight points at a time with the same operations in the same order. */
PREP_CLONES
static void project(const kawata_cpu_job *job, const float *pos, uint32_t n, uint32_t *pix,
                    uint32_t *key)
{
    const float *m = job->viewproj;
    const float fbx = (float)job->bw, fby = (float)job->bh, zn = job->znear, zf = job->zfar;
    const int bw = job->bw, bh = job->bh;
    const int x0 = job->x0, x1 = job->x1, y0 = job->y0, y1 = job->y1, rw = x1 - x0;
    uint32_t i = 0;
    for (; i + 8 <= n; i += 8) {
        prep_v8f v0, v1, v2;
        memcpy(&v0, pos + 3 * (size_t)i, 32);
        memcpy(&v1, pos + 3 * (size_t)i + 8, 32);
        memcpy(&v2, pos + 3 * (size_t)i + 16, 32);
        /* x y z of eight points out of 24 interleaved floats: lanes 0-5 (x) or 0-4 (y, z)
         * from v0:v1, the rest from v2 (indices 8-15 of the second shuffle); 0: unused */
        prep_v8f x = SHUF(SHUF(v0, v1, 0, 3, 6, 9, 12, 15, 0, 0), v2, 0, 1, 2, 3, 4, 5, 10, 13);
        prep_v8f y = SHUF(SHUF(v0, v1, 1, 4, 7, 10, 13, 0, 0, 0), v2, 0, 1, 2, 3, 4, 8, 11, 14);
        prep_v8f z = SHUF(SHUF(v0, v1, 2, 5, 8, 11, 14, 0, 0, 0), v2, 0, 1, 2, 3, 4, 9, 12, 15);
        prep_v8f cx = m[0] * x + m[4] * y + m[8] * z + m[12];
        prep_v8f cy = m[1] * x + m[5] * y + m[9] * z + m[13];
        prep_v8f d = m[3] * x + m[7] * y + m[11] * z + m[15];
        prep_v8f bx = (cx / d * 0.5f + 0.5f) * fbx, by = (cy / d * 0.5f + 0.5f) * fby;
        prep_v8i in = (d >= zn) & (d <= zf) & (bx >= 0.0f) & (by >= 0.0f) & (bx < fbx) &
                      (by < fby);
        /* the lanes left out become 0 before the conversion and the arithmetic below: a
         * point at the eye or off the frame has no integer pixel (its quotient may be inf) */
        bx = (prep_v8f)((prep_v8i)bx & in), by = (prep_v8f)((prep_v8i)by & in);
        prep_v8i qx = __builtin_convertvector(bx, prep_v8i);
        prep_v8i qy = __builtin_convertvector(by, prep_v8i);
        prep_v8i cxm = qx < bw - 1, cym = qy < bh - 1;
        qx = (qx & cxm) | ((bw - 1) & ~cxm);
        qy = (qy & cym) | ((bh - 1) & ~cym);
        in &= (qx >= x0) & (qx < x1) & (qy >= y0) & (qy < y1);
        prep_v8i q = (((qy - y0) * rw + qx - x0) & in) | ~in; /* ~0u: outside */
        memcpy(pix + i, &q, 32);
        memcpy(key + i, &d, 32);
    }
    for (; i < n; i++) {
        const float *p = pos + 3 * (size_t)i;
        float x = p[0], y = p[1], z = p[2];
        float cx = m[0] * x + m[4] * y + m[8] * z + m[12];
        float cy = m[1] * x + m[5] * y + m[9] * z + m[13];
        float d = m[3] * x + m[7] * y + m[11] * z + m[15];
        uint32_t out = ~0u;
        if (d >= zn && d <= zf) {
            float bx = (cx / d * 0.5f + 0.5f) * fbx, by = (cy / d * 0.5f + 0.5f) * fby;
            if (bx >= 0.0f && by >= 0.0f && bx < fbx && by < fby) {
                int qx = (int)bx, qy = (int)by;
                qx = qx < bw - 1 ? qx : bw - 1;
                qy = qy < bh - 1 ? qy : bh - 1;
                if (qx >= x0 && qx < x1 && qy >= y0 && qy < y1)
                    out = (uint32_t)((qy - y0) * rw + qx - x0);
            }
        }
        pix[i] = out;
        key[i] = float_bits(d);
    }
}

/* Task c: the batch's visible points [k0 + c BLOCK, ...): projected into the arrays, and with
 * pass1, pass 1 (the least key a pixel) into thread tid's depth. pix values of ~0u and rows
 * outside [y0, y1) are left out by the unsigned test against the rows' pixel count. */
static int project_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)err;
    const run *r = ctx;
    const kawata_cpu_job *job = r->job;
    const uint32_t npix = r->npix;
    uint64_t k = r->k0 + (uint64_t)c * BLOCK, end = k + BLOCK < r->k1 ? k + BLOCK : r->k1;
    uint32_t s = seg_of(job, k);
    uint32_t *pix = job->mem->pix + (k - r->k0), *key = job->mem->key + (k - r->k0);
    uint32_t *depth = r->arr[tid][0];
    while (k < end) {
        const kawata_cpu_seg *g = &job->segs[s];
        uint64_t off = k - job->mem->segk[s], left = g->count - off;
        uint32_t n = (uint32_t)(end - k < left ? end - k : left);
        project(job, g->pos + 3 * (size_t)(g->first + off), n, pix, key);
        /* without branches (which the keys' order makes unpredictable): a point outside
         * the rows goes to the spare word past them */
        for (uint32_t i = 0; r->pass1 && i < n; i++) {
            uint32_t q = pix[i] < npix ? pix[i] : npix, d = depth[q], kv = key[i];
            depth[q] = kv < d ? kv : d;
        }
        pix += n, key += n, k += n, s++;
    }
    return 0;
}

/* Task c: pass 2 over the batch's visible points [k0 + c BLOCK, ...) into thread tid's near
 * and far: near, the least index of those at the pixel's least key (the merged depth); far,
 * the greatest step key of those behind it within gamma. */
static int pass2_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)err;
    const run *r = ctx;
    const kawata_cpu_job *job = r->job;
    const uint32_t npix = r->npix;
    const float gamma = job->gamma, qscale = job->qscale;
    const uint32_t ibits = job->ibits, qtop = job->qmax - 1u;
    uint64_t k = r->k0 + (uint64_t)c * BLOCK, end = k + BLOCK < r->k1 ? k + BLOCK : r->k1;
    uint32_t s = seg_of(job, k);
    const uint32_t *pix = job->mem->pix + (k - r->k0), *key = job->mem->key + (k - r->k0);
    const uint32_t *depth = r->arr[0][0];
    uint32_t *near = r->arr[tid][1], *far = r->arr[tid][2];
    while (k < end) {
        const kawata_cpu_seg *g = &job->segs[s];
        uint64_t off = k - job->mem->segk[s], left = g->count - off;
        uint32_t n = (uint32_t)(end - k < left ? end - k : left);
        uint32_t idx = (uint32_t)(g->base + g->first + off); /* cloud-wide, < 2^28 */
        /* a point at the least key (about one a pixel) takes a branch to near; the others
         * offer far their step key without one, 0 when beyond gamma (the step is clamped below
         * 2^32 before it is converted: past gamma it is not used) */
        for (uint32_t i = 0; i < n; i++, idx++) {
            uint32_t p = pix[i] < npix ? pix[i] : npix;
            uint32_t d1 = depth[p], kv = key[i];
            if (kv == d1) {
                near[p] = idx < near[p] ? idx : near[p];
                continue;
            }
            float step = bits_float(kv) - bits_float(d1);
            if (step > gamma) continue;
            uint32_t st = (uint32_t)(step * qscale);
            uint32_t fk = ((1u + (st < qtop - 1u ? st : qtop - 1u)) << ibits) | idx;
            uint32_t f0 = far[p];
            far[p] = fk > f0 ? fk : f0;
        }
        pix += n, key += n, k += n, s++;
    }
    return 0;
}

/* The band of the rectangle's rows [a, b) (relative to y0) that task c of nt takes. */
static void band(const run *r, size_t c, uint32_t *a, uint32_t *b)
{
    uint64_t rows = (uint64_t)(r->job->y1 - r->job->y0);
    *a = (uint32_t)(rows * c / (uint64_t)r->nt);
    *b = (uint32_t)(rows * (c + 1) / (uint64_t)r->nt);
}

/* Task c: band c of every thread's arrays cleared (depth and near ~0u, far 0); the spare
 * words with the last band. */
static int clear_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)tid, (void)err;
    const run *r = ctx;
    uint32_t a, b, rw = (uint32_t)(r->job->x1 - r->job->x0);
    band(r, c, &a, &b);
    a *= rw, b *= rw;
    if (b == r->npix) b++;
    for (int t = 0; t < r->nt; t++) {
        memset(r->arr[t][0] + a, 0xFF, (size_t)(b - a) * 4);
        memset(r->arr[t][1] + a, 0xFF, (size_t)(b - a) * 4);
        memset(r->arr[t][2] + a, 0, (size_t)(b - a) * 4);
    }
    return 0;
}

/* Task c: band c of the threads' arrays merged into the job's (the rectangle's columns of its
 * rows): after pass 1 the depth (least, also kept in thread 0's for pass 2), after pass 2 near
 * (least) and far (greatest). Threads 0 and 1 are merged in the pass that writes the job's
 * array, any further ones into it after. */
static int merge_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)tid, (void)err;
    const run *r = ctx;
    const kawata_cpu_job *job = r->job;
    const uint32_t rw = (uint32_t)(job->x1 - job->x0), bw = (uint32_t)job->bw;
    uint32_t ya, yb;
    band(r, c, &ya, &yb);
    const int t1 = r->nt > 1 ? 1 : 0;
    for (uint32_t y = ya; y < yb; y++) {
        const size_t at = (size_t)y * rw, ot = (size_t)y * bw + (size_t)job->x0;
        if (r->pass1) {
            uint32_t *d0 = r->arr[0][0] + at, *out = job->depth + ot;
            for (int t = t1; t < r->nt; t++) {
                const uint32_t *d = r->arr[t][0] + at;
                for (uint32_t x = 0; x < rw; x++) {
                    uint32_t v = d[x] < d0[x] ? d[x] : d0[x];
                    d0[x] = v, out[x] = v;
                }
            }
            continue;
        }
        uint32_t *n0 = job->near + ot, *f0 = job->far + ot;
        for (int t = t1; t < r->nt; t++) {
            const uint32_t *na = t == t1 ? r->arr[0][1] + at : n0;
            const uint32_t *fa = t == t1 ? r->arr[0][2] + at : f0;
            const uint32_t *n = r->arr[t][1] + at, *f = r->arr[t][2] + at;
            for (uint32_t x = 0; x < rw; x++) {
                n0[x] = n[x] < na[x] ? n[x] : na[x];
                f0[x] = f[x] > fa[x] ? f[x] : fa[x];
            }
        }
    }
    return 0;
}

void kawata_cpu_mem_free(kawata_cpu_mem *m)
{
    free(m->pix), free(m->key), free(m->segk), free(m->priv);
    memset(m, 0, sizeof *m);
}

int kawata_cpu_raster(const kawata_cpu_job *job)
{
    kawata_cpu_mem *m = job->mem;
    if (job->y1 <= job->y0 || job->x1 <= job->x0) return 0;
    if (soft_cpu_grow((void **)&m->segk, &m->segk_cap, (size_t)job->nsegs + 1, sizeof *m->segk))
        return -1;
    uint64_t total = 0;
    for (uint32_t s = 0; s < job->nsegs; s++) m->segk[s] = total, total += job->segs[s].count;
    m->segk[job->nsegs] = total;
    size_t batch = job->batch ? job->batch : KAWATA_CPU_BATCH;
    if (total < batch) batch = (size_t)total;
    run r = {.job = job, .npix = (uint32_t)(job->y1 - job->y0) * (uint32_t)(job->x1 - job->x0)};
    /* each thread has its own three arrays: as many threads as KAWATA_CPU_PRIV_BYTES allow
     * (at least one) */
    int nt = job->threads < 1 ? 1 : job->threads;
    if (nt > KAWATA_CPU_MAX_THREADS) nt = KAWATA_CPU_MAX_THREADS;
    uint64_t tp = job->thread_points ? job->thread_points : KAWATA_CPU_THREAD_POINTS;
    if ((uint64_t)nt > 1 + total / tp) nt = (int)(1 + total / tp);
    size_t words = (size_t)r.npix + 1;
    while (nt > 1 && (uint64_t)nt * 12 * words > KAWATA_CPU_PRIV_BYTES) nt--;
    r.nt = nt;
    if (soft_cpu_grow((void **)&m->pix, &m->pix_cap, batch ? batch : 1, 4) ||
        soft_cpu_grow((void **)&m->key, &m->key_cap, batch ? batch : 1, 4) ||
        soft_cpu_grow((void **)&m->priv, &m->priv_cap, (size_t)nt * 3 * words, 4))
        return -1;
    for (int t = 0; t < nt; t++)
        for (int a = 0; a < 3; a++) r.arr[t][a] = m->priv + ((size_t)t * 3 + (size_t)a) * words;
    prep_par_for(nt, (size_t)nt, clear_task, &r, NULL, NULL);
    uint64_t nbatch = batch ? (total + batch - 1) / batch : 0;
    /* pass 1 batch by batch; pass 2 on the last batch's projection when there is one batch,
     * else batch by batch again, projected anew */
    for (int pass = 1; pass <= 2; pass++) {
        r.pass1 = pass == 1;
        for (uint64_t b = 0; b < nbatch; b++) {
            r.k0 = b * batch;
            r.k1 = r.k0 + batch < total ? r.k0 + batch : total;
            size_t nblocks = (size_t)((r.k1 - r.k0 + BLOCK - 1) / BLOCK);
            if (pass == 1 || nbatch > 1) prep_par_for(nt, nblocks, project_task, &r, NULL, NULL);
            if (pass == 2) prep_par_for(nt, nblocks, pass2_task, &r, NULL, NULL);
        }
        prep_par_for(nt, (size_t)nt, merge_task, &r, NULL, NULL);
    }
    return 0;
}

/* ---- the list and the resolve ---- */

enum { RESOLVE_BLOCK = 4096 }; /* listed pixels a task */

typedef struct resolve_run {
    const kawata_cpu_resolve_job *job;
    uint32_t n;
} resolve_run;

/* The set holding cloud-wide point i with its positions mapped, or NULL: the last set whose
 * base is at most i, else (sets sharing their buffers and first index, a LOD pool's two, of
 * which only one need be mapped) any mapped one that holds it. */
static const kawata_cpu_set *set_of(const kawata_cpu_resolve_job *job, uint32_t i)
{
    const kawata_cpu_set *sets = job->sets;
    uint32_t lo = 0, hi = job->nsets;
    if (!hi) return NULL;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (sets[mid].base <= i) lo = mid;
        else hi = mid;
    }
    const kawata_cpu_set *g = &sets[lo];
    if (g->pos && g->src && i >= g->base && i - g->base < g->n) return g;
    for (uint32_t j = 0; j < job->nsets; j++) {
        g = &sets[j];
        if (g->pos && g->src && i >= g->base && i - g->base < g->n) return g;
    }
    return NULL;
}

/* Point i (cloud-wide; ~0u: none) into out[0..3] (eye position, 1) and out[8..11] (colour, 1),
 * or zeros where it is no point of a mapped set (STAGE 1's put). */
static void put(const kawata_cpu_resolve_job *job, uint32_t i, float *out)
{
    const kawata_cpu_set *g = i == ~0u ? NULL : set_of(job, i);
    if (!g) {
        memset(out, 0, 4 * sizeof *out);
        memset(out + 8, 0, 4 * sizeof *out);
        return;
    }
    uint64_t l = (uint64_t)i - g->base;
    const float *m = job->view, *p = g->pos + 3 * l;
    float x = p[0], y = p[1], z = p[2];
    out[0] = m[0] * x + m[4] * y + m[8] * z + m[12];
    out[1] = m[1] * x + m[5] * y + m[9] * z + m[13];
    out[2] = m[2] * x + m[6] * y + m[10] * z + m[14];
    out[3] = 1.0f;
    uint32_t v = g->src[l];
    if (job->intensity) {
        float f = bits_float(v);
        f = f > 0.0f ? (f < 1.0f ? f : 1.0f) : 0.0f;
        out[8] = out[9] = out[10] = f;
    } else {
        out[8] = (float)(v & 0xFFu) / 255.0f;
        out[9] = (float)(v >> 8 & 0xFFu) / 255.0f;
        out[10] = (float)(v >> 16 & 0xFFu) / 255.0f;
    }
    out[11] = 1.0f;
}

/* Task c: listed pixels [c RESOLVE_BLOCK, ...): pts[4b] = P1, [4b + 1] = P2, [4b + 2] and
 * [4b + 3] their colours. */
static int resolve_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)tid, (void)err;
    const resolve_run *r = ctx;
    const kawata_cpu_resolve_job *job = r->job;
    uint32_t a = (uint32_t)c * RESOLVE_BLOCK;
    uint32_t b = a + RESOLVE_BLOCK < r->n ? a + RESOLVE_BLOCK : r->n;
    const uint32_t mask = (1u << job->ibits) - 1u, row0 = (uint32_t)job->y0 * (uint32_t)job->bw;
    /* the points' positions and colours are scattered: for a cloud in one set each pixel's
     * are fetched PREFETCH pixels ahead, so that the misses overlap (on the 1M scan the resolve
     * took 2.0 ms of CPU instead of 3.9) */
    enum { PREFETCH = 8 };
    for (uint32_t k = a; k < b; k++) {
        if (k + PREFETCH < b && job->nsets == 1 && job->sets[0].pos) {
            uint32_t e = job->list[k + PREFETCH];
            uint32_t q = (e >> 16) * (uint32_t)job->bw + (e & 0xFFFFu) - row0;
            uint32_t i1 = job->near[q], i2 = job->far[q] & mask;
            const kawata_cpu_set *g = &job->sets[0];
            if (i1 < g->n)
                __builtin_prefetch(g->pos + 3 * (size_t)i1), __builtin_prefetch(g->src + i1);
            if (i2 < g->n)
                __builtin_prefetch(g->pos + 3 * (size_t)i2), __builtin_prefetch(g->src + i2);
        }
        uint32_t e = job->list[k];
        uint32_t q = (e >> 16) * (uint32_t)job->bw + (e & 0xFFFFu) - row0;
        float *out = job->pts + 16 * (size_t)q;
        uint32_t fk = job->far[q];
        put(job, job->near[q], out);
        put(job, fk == 0u ? ~0u : fk & mask, out + 4);
    }
    return 0;
}

uint32_t kawata_cpu_resolve(const kawata_cpu_resolve_job *job)
{
    uint32_t n = 0;
    for (int y = job->y0; y < job->y1; y++) {
        const uint32_t *row = job->near + (size_t)(y - job->y0) * (size_t)job->bw;
        for (int x = job->x0; x < job->x1; x++)
            if (row[x] != ~0u) job->list[n++] = (uint32_t)x | (uint32_t)y << 16;
    }
    resolve_run r = {job, n};
    int nt = job->threads < 1 ? 1 : job->threads;
    if ((uint32_t)nt > 1 + n / KAWATA_CPU_THREAD_PIXELS)
        nt = (int)(1 + n / KAWATA_CPU_THREAD_PIXELS);
    prep_par_for(nt, (n + RESOLVE_BLOCK - 1) / RESOLVE_BLOCK, resolve_task, &r, NULL, NULL);
    return n;
}
