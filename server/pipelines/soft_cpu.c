/* soft_cpu.c — the soft discs composited on the CPU (soft_cpu.h). */
#include "soft_cpu.h"
#include "simd.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

enum { MAX_THREADS = 16, TILE_SHIFT = 6 }; /* tiles of 64 x 64 pixels */
enum { PREFETCH = 16 };                     /* discs the gather asks for ahead */

/* The blend works on 8 pixels at a time (GCC vector extensions, compiled for AVX2 and for the
 * baseline by PREP_CLONES). */
typedef float v8f __attribute__((vector_size(32)));
typedef int v8i __attribute__((vector_size(32)));
typedef float v8f_mem __attribute__((vector_size(32), aligned(4))); /* the planes, in memory */

/* any8: whether any lane of mask m is set */
static inline int any8(const v8i *m)
{
    uint64_t w[4];
    memcpy(w, m, sizeof w);
    return (w[0] | w[1] | w[2] | w[3]) != 0;
}

/* cos(pi d) for d in [0, 1] from u = d^2 as a polynomial in u: its Taylor series to d^14,
 * within 4.2e-6 of the cosine there (the next term bounds the error), far below an 8-bit
 * step. */
static inline void cos_pi_u(v8f *out, const v8f *up)
{
    v8f u = *up;
    const float c[8] = {1.0f, -4.934802200544679f, 4.0587121264167676f, -1.3352627688545893f,
                        0.23533063035889312f, -0.025806891390014051f, 0.0019295743094039221f,
                        -0.00010463810492484565f};
    v8f s = u * c[7] + c[6];
    s = s * u + c[5];
    s = s * u + c[4];
    s = s * u + c[3];
    s = s * u + c[2];
    s = s * u + c[1];
    *out = s * u + c[0];
}

/* floor and ceil of v for |v| < 2^31 without libm calls (the baseline x86-64 has no rounding
 * instruction: ceilf and floorf are calls there). */
static inline int ifloor(float v)
{
    int i = (int)v;
    return i - (v < (float)i);
}

static inline int iceil(float v)
{
    int i = (int)v;
    return i + (v > (float)i);
}

static inline float key_depth(uint32_t key)
{
    uint32_t b = ~key;
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

/* The pixel rectangle [x0, x1] x [y0, y1] whose centres can lie inside disc q, clipped to
 * columns [0, width) and rows [ylo, yhi). Returns 0 when it is empty (or the disc has no
 * radius). Floats are clamped before any conversion to int. */
static inline int disc_rect(const float *q, int width, int ylo, int yhi, int *x0, int *x1,
                            int *y0, int *y1)
{
    float r = q[2], cx = q[0], cy = q[1];
    if (!(r > 0.0f)) return 0;
    float vy0 = cy - r - 0.5f, vy1 = cy + r - 0.5f, vx0 = cx - r - 0.5f, vx1 = cx + r - 0.5f;
    if (!(vy1 >= (float)ylo && vy0 < (float)yhi && vx1 >= 0.0f && vx0 < (float)width)) return 0;
    /* clamps by comparison (fmaxf and fminf are calls on the baseline x86-64); the values are
     * not NaN here (the test above let none through) */
    float fylo = (float)ylo, fyhi = (float)(yhi - 1), fxhi = (float)(width - 1);
    *y0 = iceil(vy0 > fylo ? vy0 : fylo);
    *y1 = ifloor(vy1 < fyhi ? vy1 : fyhi);
    *x0 = iceil(vx0 > 0.0f ? vx0 : 0.0f);
    *x1 = ifloor(vx1 < fxhi ? vx1 : fxhi);
    return *x0 <= *x1 && *y0 <= *y1;
}

typedef struct worker {
    soft_cpu_job *job;
    int t, nt;
    uint64_t a, b;             /* this thread's discs of the gather and fill: [a, b), draw order */
    int ntx, nty;
    int lo, hi;                /* touched rows, this thread's */
} worker;

/* The gather: discs [a, b) of the draw order copied in sequence, each's tiles noted in rect (in
 * tiles, relative to the job's first row; none: first column past the last) and counted in
 * this thread's row of cnt. */
static void *gather_main(void *arg)
{
    worker *w = arg;
    const soft_cpu_job *job = w->job;
    soft_cpu_mem *m = job->mem;
    const int y0 = job->y0, y1 = job->y0 + job->rows, ntx = w->ntx;
    size_t ntiles = (size_t)w->ntx * (size_t)w->nty;
    uint32_t *cnt = m->cnt + (size_t)w->t * ntiles;
    memset(cnt, 0, ntiles * sizeof *cnt);
    uint64_t base = 0;
    for (int s = 0; s < job->nsegs; s++) {
        const soft_cpu_seg *g = &job->segs[s];
        uint64_t n = g->n, lo = w->a > base ? w->a : base, hi = w->b < base + n ? w->b : base + n;
        for (uint64_t k = lo; k < hi; k++) {
            uint64_t l = k - base;
            uint32_t j = g->order[g->rev ? n - 1 - l : l];
            /* the discs are read in an order that jumps about proj: ask for one ahead */
            if (k + PREFETCH < hi)
                __builtin_prefetch(g->proj + 8 * (size_t)g->order[g->rev ? n - 1 - l - PREFETCH
                                                                         : l + PREFETCH]);
            float *q = m->discs + 8 * k;
            memcpy(q, g->proj + 8 * (size_t)j, 8 * sizeof(float));
            uint16_t *rc = m->rect + 4 * k;
            int x0, x1, ya, yb;
            /* a colour that is not finite (x - x is not 0) would reach the masked lanes too
             * (col * 0): such a disc is left out */
            int finite = q[4] - q[4] == 0.0f && q[5] - q[5] == 0.0f && q[6] - q[6] == 0.0f;
            if (!finite || !disc_rect(q, job->width, y0, y1, &x0, &x1, &ya, &yb)) {
                rc[0] = 1, rc[1] = 0;
                continue;
            }
            rc[0] = (uint16_t)(x0 >> TILE_SHIFT), rc[1] = (uint16_t)(x1 >> TILE_SHIFT);
            rc[2] = (uint16_t)((ya - y0) >> TILE_SHIFT);
            rc[3] = (uint16_t)((yb - y0) >> TILE_SHIFT);
            for (int ty = rc[2]; ty <= rc[3]; ty++)
                for (int tx = rc[0]; tx <= rc[1]; tx++) cnt[ty * ntx + tx]++;
        }
        base += n;
    }
    return NULL;
}

/* The fill: discs [a, b) copied into their tiles' ranges of tiled, at this thread's offsets
 * (its row of cnt, made offsets by bin). */
static void *fill_main(void *arg)
{
    worker *w = arg;
    soft_cpu_mem *m = w->job->mem;
    const int ntx = w->ntx;
    uint32_t *at = m->cnt + (size_t)w->t * (size_t)w->ntx * (size_t)w->nty;
    for (uint64_t k = w->a; k < w->b; k++) {
        const uint16_t *rc = m->rect + 4 * k;
        for (int ty = rc[2]; ty <= rc[3] && rc[0] <= rc[1]; ty++)
            for (int tx = rc[0]; tx <= rc[1]; tx++)
                memcpy(m->tiled + 8 * (size_t)at[ty * ntx + tx]++, m->discs + 8 * k,
                       8 * sizeof(float));
    }
    return NULL;
}

/* A thread's tile: the premultiplied R, G, B and A of its pixels and the solid surface's eye
 * depth there (+inf: none), each a plane of TILE x TILE floats, row by row from the tile's
 * corner. Planes instead of RGBA quadruples so that 8 pixels blend in 8-wide operations. */
enum { TILE = 1 << TILE_SHIFT, TPIX = TILE * TILE, TPLANES = 5 };

/* tile_depth: the Z plane from the job's keys (+inf where a key is 0, outside the frame, or
 * without keys). */
static void tile_depth(const soft_cpu_job *job, float *Z, int tx0, int tx1, int ty0, int ty1)
{
    for (int i = 0; i < TPIX; i++) Z[i] = INFINITY;
    if (!job->keys) return;
    for (int y = ty0; y <= ty1; y++) {
        const uint32_t *k = job->keys + (size_t)(y - job->kb) * (size_t)job->width;
        float *z = Z + (size_t)(y - ty0) * TILE;
        for (int x = tx0; x <= tx1; x++)
            if (k[x]) z[x - tx0] = key_depth(k[x]);
    }
}

/* blend_tile: discs [e0, e1) of tiled, back to front, over the pixels of the tile whose columns
 * are [tx0, tx1] and rows [ty0, ty1] (within the job's), into the planes T (cleared, Z filled).
 * Every pixel whose centre lies inside a disc (d = |p - c| / r < 1), in front of the solid
 * surface, gets soft.frag's opacity Phi = lambda (cos(pi d) + 1) / 2 (eq. 19), modulated by eq.
 * 22 as mix(1 - d, Phi, W), and the "over" in float. Lanes outside the disc or the rectangle,
 * or hidden, have Phi 0 and stay as they were exactly (c * 0 + 1 * l = l: the planes hold
 * finite values, never -0). *lo, *hi: the rows any disc reached. */
PREP_CLONES
static void blend_tile(const soft_cpu_job *job, const float *tiled, uint32_t e0, uint32_t e1,
                       int tx0, int tx1, int ty0, int ty1, float *T, int *lo, int *hi)
{
    const float lambda = job->lambda;
    const v8f lane = {0.5f, 1.5f, 2.5f, 3.5f, 4.5f, 5.5f, 6.5f, 7.5f}; /* pixel centres */
    for (uint32_t e = e0; e < e1; e++) {
        const float *q = tiled + 8 * (size_t)e;
        int x0, x1, ya, yb;
        if (!disc_rect(q, job->width, job->y0, job->y0 + job->rows, &x0, &x1, &ya, &yb))
            continue;
        x0 = x0 > tx0 ? x0 : tx0, x1 = x1 < tx1 ? x1 : tx1;
        ya = ya > ty0 ? ya : ty0, yb = yb < ty1 ? yb : ty1;
        if (x0 > x1 || ya > yb) continue;
        const float cx = q[0], cy = q[1], r = q[2], depth = q[3], wm = q[7];
        const float r2 = r * r, inv_r = 1.0f / r, inv_r2 = inv_r * inv_r;
        const float cr = q[4], cg = q[5], cb = q[6];
        const int modulated = wm != 1.0f;
        const float fx0 = (float)x0, fx1 = (float)x1;
        /* the 8-pixel groups of the tile's rows that the columns reach */
        int g0 = (x0 - tx0) & ~7, g1 = x1 - tx0;
        for (int y = ya; y <= yb; y++) {
            float dy = (float)y + 0.5f - cy, dy2 = dy * dy;
            if (!(dy2 < r2)) continue;
            size_t row = (size_t)(y - ty0) * TILE;
            v8i any = {0};
            for (int g = g0; g <= g1; g += 8) {
                v8f xs = (float)(tx0 + g) + lane; /* x + 0.5 */
                v8f dx = xs - cx, d2 = dx * dx + dy2;
                v8f px = xs - 0.5f;
                const v8f_mem *zp = (const v8f_mem *)(T + 4 * TPIX + row + g);
                v8i in = (d2 < r2) & (px >= fx0) & (px <= fx1) & (depth < *zp);
                if (!any8(&in)) continue;
                any |= in;
                v8f u = d2 * inv_r2, cs;
                cos_pi_u(&cs, &u);
                v8f phi = lambda * (cs + 1.0f) * 0.5f;
                if (modulated) {
                    v8f d;
                    for (int l = 0; l < 8; l++) d[l] = sqrtf(d2[l] > 0.0f ? d2[l] : 0.0f);
                    d *= inv_r;
                    phi = (1.0f - d) * (1.0f - wm) + phi * wm;
                }
                phi = (v8f)((v8i)phi & in);
                v8f keep = 1.0f - phi;
                v8f_mem *R = (v8f_mem *)(T + row + g), *G = (v8f_mem *)(T + TPIX + row + g);
                v8f_mem *B = (v8f_mem *)(T + 2 * TPIX + row + g);
                *R = cr * phi + keep * *R;
                *G = cg * phi + keep * *G;
                *B = cb * phi + keep * *B;
                v8f_mem *A = (v8f_mem *)(T + 3 * (size_t)TPIX + row + g);
                *A = phi + keep * *A;
            }
            if (any8(&any)) {
                if (y < *lo) *lo = y;
                if (y > *hi) *hi = y;
            }
        }
    }
}

/* over8: the tile's planes put over the 8-bit pixels of job->rgba8 with the "over"
 * soft_resolve's blending makes (ONE, ONE_MINUS_SRC_ALPHA; alpha left alone: the frame is
 * opaque), in float on the 0..255 scale, rounded to nearest. Pixels no disc reached (alpha 0)
 * are left alone. */
static void over8(const soft_cpu_job *job, const float *T, int tx0, int tx1, int ty0, int ty1)
{
    for (int y = ty0; y <= ty1; y++) {
        size_t row = (size_t)(y - ty0) * TILE;
        uint8_t *px = job->rgba8 + 4 * ((size_t)y * (size_t)job->width + (size_t)tx0);
        for (int x = 0; x <= tx1 - tx0; x++, px += 4) {
            float a = T[3 * TPIX + row + x];
            if (a == 0.0f) continue;
            float keep = 1.0f - a;
            for (int c = 0; c < 3; c++) {
                float v = T[(size_t)c * TPIX + row + x] * 255.0f + keep * (float)px[c];
                v = v < 0.0f ? 0.0f : v > 255.0f ? 255.0f : v;
                px[c] = (uint8_t)(int)(v + 0.5f);
            }
        }
    }
}

/* to_layer: the tile's planes copied into the job's layer (RGBA quadruples). */
static void to_layer(const soft_cpu_job *job, const float *T, int tx0, int tx1, int ty0, int ty1)
{
    for (int y = ty0; y <= ty1; y++) {
        size_t row = (size_t)(y - ty0) * TILE;
        float *L = job->layer + 4 * ((size_t)(y - job->y0) * (size_t)job->width + (size_t)tx0);
        for (int x = 0; x <= tx1 - tx0; x++, L += 4)
            for (int c = 0; c < 4; c++) L[c] = T[(size_t)c * TPIX + row + x];
    }
}

/* The tiles t, t + nt, ...: each its list of discs, back to front, into this thread's planes,
 * then over the frame's pixels (job->rgba8) or into the layer. */
static void *blend_main(void *arg)
{
    worker *w = arg;
    const soft_cpu_job *job = w->job;
    const soft_cpu_mem *m = job->mem;
    const int y0 = job->y0, y1 = job->y0 + job->rows;
    int lo = y1, hi = -1;
    int ntiles = w->ntx * w->nty;
    float *T = m->tbuf + (size_t)w->t * TPLANES * TPIX;
    for (int tile = w->t; tile < ntiles; tile += w->nt) {
        if (m->first[tile] == m->first[tile + 1]) continue;
        int tx = tile % w->ntx, ty = tile / w->ntx;
        int tx0 = tx << TILE_SHIFT, tx1 = tx0 + TILE - 1;
        int ty0 = y0 + (ty << TILE_SHIFT), ty1 = ty0 + TILE - 1;
        if (tx1 >= job->width) tx1 = job->width - 1;
        if (ty1 >= y1) ty1 = y1 - 1;
        memset(T, 0, 4 * TPIX * sizeof *T);
        tile_depth(job, T + 4 * TPIX, tx0, tx1, ty0, ty1);
        int tlo = y1, thi = -1; /* the rows this tile's discs reached */
        blend_tile(job, m->tiled, m->first[tile], m->first[tile + 1], tx0, tx1, ty0, ty1, T,
                   &tlo, &thi);
        if (thi < 0) continue;
        if (job->rgba8) over8(job, T, tx0, tx1, ty0, ty1);
        else to_layer(job, T, tx0, tx1, ty0, ty1);
        lo = tlo < lo ? tlo : lo, hi = thi > hi ? thi : hi;
    }
    w->lo = lo;
    w->hi = hi;
    return NULL;
}

/* Runs fn on every worker, the first on this thread; a part whose thread cannot start runs
 * here too (the parts are independent). */
static void run_all(worker *w, int nt, void *(*fn)(void *))
{
    pthread_t th[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int t = 1; t < nt; t++) started[t] = pthread_create(&th[t], NULL, fn, &w[t]) == 0;
    fn(&w[0]);
    for (int t = 1; t < nt; t++) {
        if (started[t]) pthread_join(th[t], NULL);
        else fn(&w[t]);
    }
}

int soft_cpu_grow(void **p, size_t *cap, size_t n, size_t sz)
{
    if (n <= *cap) return 0;
    size_t c = *cap ? *cap : 4096;
    while (c < n) c *= 2;
    void *q = realloc(*p, c * sz);
    if (!q) return -1;
    *p = q;
    *cap = c;
    return 0;
}

/* The binning, a counting sort that keeps the draw order in every tile: the threads' counts
 * (gather_main) made offsets, tile by tile and within a tile thread by thread (thread t's discs
 * precede thread t + 1's in the draw order), then each thread's discs copied to them
 * (fill_main). Returns 0, or -1 when tiled cannot grow. */
static int bin(soft_cpu_job *job, worker *w, int nt, int ntx, int nty)
{
    soft_cpu_mem *m = job->mem;
    size_t ntiles = (size_t)ntx * (size_t)nty;
    uint64_t run = 0;
    for (size_t i = 0; i < ntiles; i++) {
        m->first[i] = (uint32_t)run;
        for (int t = 0; t < nt; t++) {
            uint32_t *c = m->cnt + (size_t)t * ntiles + i, here = *c;
            *c = (uint32_t)run;
            run += here;
        }
        if (run > UINT32_MAX) return -1;
    }
    m->first[ntiles] = (uint32_t)run;
    if (soft_cpu_grow((void **)&m->tiled, &m->tiled_cap, 8 * run, sizeof *m->tiled)) return -1;
    run_all(w, nt, fill_main);
    return 0;
}

/* setup: the job's thread count and tiles, and its workers (the gather's and fill's parts of
 * the draw order). Returns the number of discs. */
static uint64_t setup(soft_cpu_job *job, worker *w, int *nt_, int *ntx_, int *nty_)
{
    uint64_t n = 0;
    for (int s = 0; s < job->nsegs; s++) n += job->segs[s].n;
    int nt = job->threads < 1 ? 1 : job->threads > MAX_THREADS ? MAX_THREADS : job->threads;
    int ntx = (job->width + (1 << TILE_SHIFT) - 1) >> TILE_SHIFT;
    int nty = (job->rows + (1 << TILE_SHIFT) - 1) >> TILE_SHIFT;
    for (int t = 0; t < nt; t++)
        w[t] = (worker){job, t, nt, n * (uint64_t)t / (uint64_t)nt,
                        n * (uint64_t)(t + 1) / (uint64_t)nt, ntx, nty, 0, -1};
    *nt_ = nt, *ntx_ = ntx, *nty_ = nty;
    return job->rows > 0 && job->width > 0 ? n : 0;
}

int soft_cpu_bin(soft_cpu_job *job)
{
    worker w[MAX_THREADS];
    int nt, ntx, nty;
    uint64_t n = setup(job, w, &nt, &ntx, &nty);
    job->binned = 0;
    if (n == 0) return 0;
    size_t ntiles = (size_t)ntx * (size_t)nty;
    soft_cpu_mem *m = job->mem;
    if (n > UINT32_MAX || ntx > UINT16_MAX || nty > UINT16_MAX ||
        soft_cpu_grow((void **)&m->discs, &m->discs_cap, 8 * n, sizeof *m->discs) ||
        soft_cpu_grow((void **)&m->rect, &m->rect_cap, 4 * n, sizeof *m->rect) ||
        soft_cpu_grow((void **)&m->cnt, &m->cnt_cap, (size_t)nt * ntiles, sizeof *m->cnt) ||
        soft_cpu_grow((void **)&m->first, &m->first_cap, ntiles + 1, sizeof *m->first) ||
        soft_cpu_grow((void **)&m->tbuf, &m->tbuf_cap, (size_t)nt * TPLANES * TPIX + 8,
                      sizeof *m->tbuf))
        return -1;
    run_all(w, nt, gather_main);
    if (bin(job, w, nt, ntx, nty) != 0) return -1;
    job->binned = 1;
    return 0;
}

int soft_cpu_blend(soft_cpu_job *job)
{
    if (!job->rgba8)
        memset(job->layer, 0, (size_t)job->width * (size_t)job->rows * 4 * sizeof(float));
    job->touched[0] = job->touched[1] = -1;
    worker w[MAX_THREADS];
    int nt, ntx, nty;
    if (setup(job, w, &nt, &ntx, &nty) == 0 || !job->binned) return 0;
    run_all(w, nt, blend_main);
    int lo = job->y0 + job->rows, hi = -1;
    for (int t = 0; t < nt; t++) {
        if (w[t].hi < 0) continue;
        if (w[t].lo < lo) lo = w[t].lo;
        if (w[t].hi > hi) hi = w[t].hi;
    }
    job->touched[0] = hi >= 0 ? lo : -1;
    job->touched[1] = hi;
    return 0;
}

int soft_cpu_composite(soft_cpu_job *job)
{
    if (soft_cpu_bin(job) != 0) {
        if (!job->rgba8)
            memset(job->layer, 0, (size_t)job->width * (size_t)job->rows * 4 * sizeof(float));
        job->touched[0] = job->touched[1] = -1;
        return -1;
    }
    return soft_cpu_blend(job);
}

void soft_cpu_mem_free(soft_cpu_mem *m)
{
    free(m->discs);
    free(m->tiled);
    free(m->rect);
    free(m->cnt);
    free(m->first);
    free(m->tbuf);
    memset(m, 0, sizeof *m);
}
