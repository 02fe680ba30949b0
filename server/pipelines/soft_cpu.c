/* soft_cpu.c — the soft discs composited on the CPU (soft_cpu.h). */
#include "soft_cpu.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

enum { MAX_THREADS = 16, TILE_SHIFT = 6 }; /* tiles of 64 x 64 pixels */
enum { PREFETCH = 16 };                     /* discs the gather asks for ahead */

/* cos(pi d) for d in [0, 1] as a polynomial in d^2: its Taylor series to d^14, within 4.2e-6
 * of the cosine there (the next term bounds the error), far below an 8-bit step. */
static inline float cos_pi(float d)
{
    static const float c[8] = {1.0f, -4.934802200544679f, 4.0587121264167676f,
                               -1.3352627688545893f, 0.23533063035889312f,
                               -0.025806891390014051f, 0.0019295743094039221f,
                               -0.00010463810492484565f};
    float u = d * d;
    return c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * (c[5] + u * (c[6] +
           u * c[7]))))));
}

/* floor and ceil of v for |v| < 2^31 without libm calls (the baseline x86-64 has no rounding
 * instruction: ceilf and floorf are calls there). */
#if defined(__SSE2__)
#include <emmintrin.h>
/* cos_pi on four lanes, the same operations in the same order */
static inline __m128 cos_pi4(__m128 d)
{
    static const float c[8] = {1.0f, -4.934802200544679f, 4.0587121264167676f,
                               -1.3352627688545893f, 0.23533063035889312f,
                               -0.025806891390014051f, 0.0019295743094039221f,
                               -0.00010463810492484565f};
    /* written out (not a loop: GCC kept the loop and reloaded each coefficient) */
    __m128 u = _mm_mul_ps(d, d), s = _mm_set1_ps(c[7]);
    s = _mm_add_ps(_mm_set1_ps(c[6]), _mm_mul_ps(u, s));
    s = _mm_add_ps(_mm_set1_ps(c[5]), _mm_mul_ps(u, s));
    s = _mm_add_ps(_mm_set1_ps(c[4]), _mm_mul_ps(u, s));
    s = _mm_add_ps(_mm_set1_ps(c[3]), _mm_mul_ps(u, s));
    s = _mm_add_ps(_mm_set1_ps(c[2]), _mm_mul_ps(u, s));
    s = _mm_add_ps(_mm_set1_ps(c[1]), _mm_mul_ps(u, s));
    return _mm_add_ps(_mm_set1_ps(c[0]), _mm_mul_ps(u, s));
}
#endif

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

/* Where the blend writes: pixel (x, y) at dst + 4 ((y - oy) stride + x - ox), premultiplied
 * RGBA floats: the job's layer, or a thread's tile. */
typedef struct blend_dst {
    float *dst;
    size_t stride;
    int ox, oy;
} blend_dst;

/* One disc over the pixels of rectangle [x0, x1] x [y0, y1] (inside the disc's own, and inside
 * this thread's tile, whose last column is xlim). */
static void blend_disc(const soft_cpu_job *job, const blend_dst *o, const float *q, int x0,
                       int x1, int y0, int y1, int xlim, int *lo, int *hi)
{
    const int width = job->width;
    float cx = q[0], cy = q[1], r = q[2], depth = q[3], cr = q[4], cg = q[5], cb = q[6];
    float wm = q[7], lambda = job->lambda;
    float r2 = r * r, inv_r = 1.0f / r;
    /* every row over the rectangle's columns: the lanes outside the disc are masked (cheaper
     * than each row's chord, its square root and roundings: 13 % less CPU on Guanyin) */
    for (int y = y0; y <= y1; y++) {
        float dy = (float)y + 0.5f - cy, dy2 = dy * dy;
        if (!(dy2 < r2)) continue;
        int xa = x0, xb = x1;
        float *row = o->dst + 4 * ((size_t)(y - o->oy) * o->stride);
        const uint32_t *krow = job->keys ? job->keys + (size_t)(y - job->kb) * (size_t)width
                                         : NULL;
        int any = 0, x = xa;
#if defined(__SSE2__)
        /* four pixels at a time, with the same operations in the same order as the loop below
         * (so the same results): lanes outside the disc or behind the solid surface are left
         * alone */
        const __m128 vcx = _mm_set1_ps(cx), vdy2 = _mm_set1_ps(dy2), vr2 = _mm_set1_ps(r2);
        const __m128 vinv = _mm_set1_ps(inv_r), one = _mm_set1_ps(1.0f), half_ = _mm_set1_ps(0.5f);
        const __m128 vdepth = _mm_set1_ps(depth), vlam = _mm_set1_ps(lambda);
        const __m128 vwm = _mm_set1_ps(wm), vomw = _mm_set1_ps(1.0f - wm);
        const __m128 col = _mm_set_ps(1.0f, cb, cg, cr);
        /* a chord is a few pixels: the last group is masked (lanes past xb), and taken so
         * while its four keys lie inside the row (else the loop below finishes it) */
        const __m128 vxb = _mm_set1_ps((float)xb), lane = _mm_set_ps(3.0f, 2.0f, 1.0f, 0.0f);
        for (; x <= xb && x + 3 < width; x += 4) {
            /* x + i in float: exact (|x| < 2^24), as the four conversions were */
            __m128 xs = _mm_add_ps(_mm_set1_ps((float)x), lane);
            __m128 dx = _mm_sub_ps(_mm_add_ps(xs, half_), vcx);
            __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), vdy2);
            __m128 in = _mm_and_ps(_mm_cmplt_ps(d2, vr2), _mm_cmple_ps(xs, vxb));
            __m128 d = _mm_mul_ps(_mm_sqrt_ps(d2), vinv);
            in = _mm_and_ps(in, _mm_cmplt_ps(d, one));
            if (krow) {
                __m128i k4 = _mm_loadu_si128((const __m128i *)(krow + x));
                __m128i empty = _mm_cmpeq_epi32(k4, _mm_setzero_si128());
                __m128 kd = _mm_castsi128_ps(_mm_xor_si128(k4, _mm_set1_epi32(-1)));
                __m128 vis = _mm_or_ps(_mm_castsi128_ps(empty), _mm_cmplt_ps(vdepth, kd));
                in = _mm_and_ps(in, vis);
            }
            int m = _mm_movemask_ps(in);
            if (!m) continue;
            any = 1;
            __m128 phi = _mm_mul_ps(_mm_mul_ps(vlam, _mm_add_ps(cos_pi4(d), one)), half_);
            phi = _mm_add_ps(_mm_mul_ps(_mm_sub_ps(one, d), vomw), _mm_mul_ps(phi, vwm));
            phi = _mm_and_ps(phi, in);
            /* the lanes are blended without a test per lane (whose branches, on where the
             * disc's edge falls, the CPU mispredicts): a masked lane has phi 0, and
             * col * 0 + 1 * l is l exactly (the layer holds finite values, never -0). Lanes
             * past the tile's last column are another thread's: those only by count. */
            int nl = x + 3 <= xlim ? 4 : xlim - x + 1;
            float *L = row + 4 * (size_t)(x - o->ox);
#define SOFT_CPU_LANE(i, sh)                                                                  \
    do {                                                                                      \
        __m128 p = _mm_shuffle_ps(phi, phi, sh), l = _mm_loadu_ps(L + 4 * (i));               \
        l = _mm_add_ps(_mm_mul_ps(col, p), _mm_mul_ps(_mm_sub_ps(one, p), l));                \
        _mm_storeu_ps(L + 4 * (i), l);                                                        \
    } while (0)
            SOFT_CPU_LANE(0, 0x00);
            if (nl > 1) SOFT_CPU_LANE(1, 0x55);
            if (nl > 2) SOFT_CPU_LANE(2, 0xaa);
            if (nl > 3) SOFT_CPU_LANE(3, 0xff);
#undef SOFT_CPU_LANE
        }
#endif
        for (; x <= xb; x++) {
            float dx = (float)x + 0.5f - cx, d2 = dx * dx + dy2;
            if (!(d2 < r2)) continue;
            float d = sqrtf(d2) * inv_r; /* soft.frag's length(...) / r */
            if (!(d < 1.0f)) continue;
            if (krow) {
                uint32_t key = krow[x];
                if (key != 0u && depth >= key_depth(key)) continue;
            }
            float phi = lambda * (cos_pi(d) + 1.0f) * 0.5f;
            phi = (1.0f - d) * (1.0f - wm) + phi * wm; /* mix(1 - d, phi, W) */
            float *L = row + 4 * (size_t)(x - o->ox), keep = 1.0f - phi;
            L[0] = cr * phi + keep * L[0];
            L[1] = cg * phi + keep * L[1];
            L[2] = cb * phi + keep * L[2];
            L[3] = phi + keep * L[3];
            any = 1;
        }
        if (any) {
            if (y < *lo) *lo = y;
            if (y > *hi) *hi = y;
        }
    }
}

/* over8: the tile's premultiplied layer (rows ty0..ty1 of tile buffer L, TILE wide, from
 * column tx0) put over the 8-bit pixels of job->rgba8 with the "over" soft_resolve's blending
 * makes (ONE, ONE_MINUS_SRC_ALPHA; alpha left alone: the frame is opaque), in float on the
 * 0..255 scale, rounded to nearest. Pixels no disc reached (alpha 0, colour 0) are skipped. */
static void over8(const soft_cpu_job *job, const float *L, int tx0, int tx1, int ty0, int ty1)
{
    for (int y = ty0; y <= ty1; y++) {
        const float *l = L + 4 * ((size_t)(y - ty0) << TILE_SHIFT);
        uint8_t *px = job->rgba8 + 4 * ((size_t)y * (size_t)job->width + (size_t)tx0);
        for (int x = tx0; x <= tx1; x++, l += 4, px += 4) {
            if (l[3] == 0.0f && l[0] == 0.0f && l[1] == 0.0f && l[2] == 0.0f) continue;
            float keep = 1.0f - l[3];
            for (int c = 0; c < 3; c++) {
                float v = l[c] * 255.0f + keep * (float)px[c];
                v = v < 0.0f ? 0.0f : v > 255.0f ? 255.0f : v;
                px[c] = (uint8_t)(int)(v + 0.5f);
            }
        }
    }
}

/* The tiles t, t + nt, ...: each its list of discs, back to front, clipped to the tile, into
 * the layer, or (job->rgba8) into this thread's tile buffer then over the frame's pixels. */
static void *blend_main(void *arg)
{
    worker *w = arg;
    const soft_cpu_job *job = w->job;
    const soft_cpu_mem *m = job->mem;
    const int y0 = job->y0, y1 = job->y0 + job->rows;
    int lo = y1, hi = -1;
    int ntiles = w->ntx * w->nty;
    enum { TILE = 1 << TILE_SHIFT };
    float *tbuf = job->rgba8 ? m->tbuf + (size_t)w->t * TILE * TILE * 4 : NULL;
    for (int tile = w->t; tile < ntiles; tile += w->nt) {
        if (m->first[tile] == m->first[tile + 1]) continue;
        int tx = tile % w->ntx, ty = tile / w->ntx;
        int tx0 = tx << TILE_SHIFT, tx1 = tx0 + TILE - 1;
        int ty0 = y0 + (ty << TILE_SHIFT), ty1 = ty0 + TILE - 1;
        if (tx1 >= job->width) tx1 = job->width - 1;
        if (ty1 >= y1) ty1 = y1 - 1;
        blend_dst o = {job->layer, (size_t)job->width, 0, y0};
        if (tbuf) {
            o = (blend_dst){tbuf, TILE, tx0, ty0};
            memset(tbuf, 0, (size_t)TILE * TILE * 4 * sizeof *tbuf);
        }
        int tlo = y1, thi = -1; /* the rows this tile's discs reached */
        for (uint32_t e = m->first[tile]; e < m->first[tile + 1]; e++) {
            const float *q = m->tiled + 8 * (size_t)e;
            int x0, x1, ya, yb;
            if (!disc_rect(q, job->width, y0, y1, &x0, &x1, &ya, &yb)) continue;
            x0 = x0 > tx0 ? x0 : tx0, x1 = x1 < tx1 ? x1 : tx1;
            ya = ya > ty0 ? ya : ty0, yb = yb < ty1 ? yb : ty1;
            if (x0 <= x1 && ya <= yb) blend_disc(job, &o, q, x0, x1, ya, yb, tx1, &tlo, &thi);
        }
        if (tbuf && thi >= 0) over8(job, tbuf, tx0, tx1, ty0, ty1);
        if (thi >= 0) lo = tlo < lo ? tlo : lo, hi = thi > hi ? thi : hi;
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

int soft_cpu_composite(soft_cpu_job *job)
{
    if (!job->rgba8)
        memset(job->layer, 0, (size_t)job->width * (size_t)job->rows * 4 * sizeof(float));
    job->touched[0] = job->touched[1] = -1;
    uint64_t n = 0;
    for (int s = 0; s < job->nsegs; s++) n += job->segs[s].n;
    if (n == 0 || job->rows <= 0 || job->width <= 0) return 0;
    int nt = job->threads < 1 ? 1 : job->threads > MAX_THREADS ? MAX_THREADS : job->threads;
    int ntx = (job->width + (1 << TILE_SHIFT) - 1) >> TILE_SHIFT;
    int nty = (job->rows + (1 << TILE_SHIFT) - 1) >> TILE_SHIFT;
    size_t ntiles = (size_t)ntx * (size_t)nty;
    soft_cpu_mem *m = job->mem;
    if (n > UINT32_MAX || ntx > UINT16_MAX || nty > UINT16_MAX ||
        soft_cpu_grow((void **)&m->discs, &m->discs_cap, 8 * n, sizeof *m->discs) ||
        soft_cpu_grow((void **)&m->rect, &m->rect_cap, 4 * n, sizeof *m->rect) ||
        soft_cpu_grow((void **)&m->cnt, &m->cnt_cap, (size_t)nt * ntiles, sizeof *m->cnt) ||
        soft_cpu_grow((void **)&m->first, &m->first_cap, ntiles + 1, sizeof *m->first) ||
        (job->rgba8 && soft_cpu_grow((void **)&m->tbuf, &m->tbuf_cap,
                                     (size_t)nt << (2 * TILE_SHIFT + 2), sizeof *m->tbuf)))
        return -1;
    worker w[MAX_THREADS];
    for (int t = 0; t < nt; t++)
        w[t] = (worker){job, t, nt, n * (uint64_t)t / (uint64_t)nt,
                        n * (uint64_t)(t + 1) / (uint64_t)nt, ntx, nty, 0, -1};
    run_all(w, nt, gather_main);
    if (bin(job, w, nt, ntx, nty) != 0) return -1;
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
