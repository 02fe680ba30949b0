/* kawata_fit_cpu.c — kawata's plane fit on the host (kawata_fit_cpu.h). Each function mirrors
 * the one of the same name in kawata_fit.comp STAGE 2; float literals are the shader's. */
#include "kawata_fit_cpu.h"

#include <math.h>
#include <string.h>

#include "kawata_cpu.h"
#include "progress.h"
#include "simd.h"

enum { BANDS_PER_THREAD = 4 };

static const float NONE[4] = {0.0f, 0.0f, 0.0f, 0.0f};

/* Eight listed pixels at a time, one a lane (AVX2 where the CPU has it, simd.h): each lane
 * runs the shader's operations on its own pixel, and the shader's early returns become masks
 * (a lane's sums are replaced, not added to, where its point is left out, so they stay those of
 * the points taken). Vector float operations round as the scalar ones. */
typedef struct lanes {
    prep_v8f x[18], y[18], z[18], w[18]; /* neighbour k's nearest 2k, farthest 2k + 1; the
                                            pixel itself is k = 4 */
    prep_v8f pax, pay, paz, a1x, a1y, a1z, a1w, tol;
} lanes;

/* The normal-equation sums and the supporting points of a round. */
typedef struct vfit {
    prep_v8f sxx, sxy, syy, sx, sy, n, sxz, syz, sz, szz;
    prep_v8i support;
} vfit;

/* Lane by lane m ? a : b; |a|. (Macros: vectors pass by value through no function here, whose
 * ABI would differ between the AVX2 and the baseline clone, -Wpsabi.) */
#define sel(m, a, b) ((prep_v8f)(((prep_v8i)(a) & (m)) | ((prep_v8i)(b) & ~(m))))
#define vabs(a) ((prep_v8f)((prep_v8i)(a) & 0x7FFFFFFF))
/* det3 of the shader: columns (a0 a1 a2), (b0 b1 b2), (c0 c1 c2). */
#define det3(a0, a1, a2, b0, b1, b2, c0, c1, c2)                                              \
    ((a0) * ((b1) * (c2) - (c1) * (b2)) - (b0) * ((a1) * (c2) - (c1) * (a2)) +                 \
     (c0) * ((a1) * (b2) - (b1) * (a2)))

/* add_point over the 18 points: a point is taken when it exists, lies within the tolerance of
 * the nearest one and (g3 > 0, the second round) within g3 of the plane g. */
static inline void round_of(const lanes *L, const prep_v8f *g, vfit *f)
{
    const prep_v8f zero = {0}, one = zero + 1.0f;
    f->sxx = f->sxy = f->syy = f->sx = f->sy = f->n = f->sxz = f->syz = f->sz = f->szz = zero;
    f->support = (prep_v8i){0};
    for (int i = 0; i < 18; i++) {
        prep_v8i ok = (L->w[i] != 0.0f) & ~(vabs(L->z[i] - L->a1z) > L->tol);
        prep_v8f ex = L->x[i] - L->pax, ey = L->y[i] - L->pay, ez = L->z[i] - L->paz;
        prep_v8f r = ez - (g[0] * ex + g[1] * ey + g[2]);
        ok &= ~((g[3] > 0.0f) & (vabs(r) > g[3]));
        if (i != 8) f->support -= ok;
        /* a point left out adds +0 to every sum: the sums start at +0 and a rounded sum is -0
         * only when both terms are, so they never are -0, and adding +0 leaves them as they
         * were, as the shader's early return does */
        ex = (prep_v8f)((prep_v8i)ex & ok), ey = (prep_v8f)((prep_v8i)ey & ok);
        ez = (prep_v8f)((prep_v8i)ez & ok);
        f->sxx += ex * ex, f->sxy += ex * ey, f->syy += ey * ey;
        f->sx += ex, f->sy += ey, f->n += (prep_v8f)((prep_v8i)one & ok);
        f->sxz += ex * ez, f->syz += ey * ez, f->sz += ez, f->szz += ez * ez;
    }
}

/* solve: Cramer's rule; *ok the lanes where the equations are not singular. */
static inline void solve(const vfit *f, prep_v8f abc[3], prep_v8i *ok)
{
    prep_v8f det = det3(f->sxx, f->sxy, f->sx, f->sxy, f->syy, f->sy, f->sx, f->sy, f->n);
    prep_v8f lim = 1e-6f * f->sxx * f->syy * f->n;
    abc[0] = det3(f->sxz, f->syz, f->sz, f->sxy, f->syy, f->sy, f->sx, f->sy, f->n) / det;
    abc[1] = det3(f->sxx, f->sxy, f->sx, f->sxz, f->syz, f->sz, f->sx, f->sy, f->n) / det;
    abc[2] = det3(f->sxx, f->sxy, f->sx, f->sxy, f->syy, f->sy, f->sxz, f->syz, f->sz) / det;
    *ok = vabs(det) > lim;
}

/* *a = sqrt(*a) lane by lane. */
static inline void vsqrt(prep_v8f *a)
{
    for (int l = 0; l < 8; l++) (*a)[l] = sqrtf((*a)[l]);
}

/* The shader's pixel() up to the normal for the eight lanes: *keep the lanes that make a
 * splat, nrm their normals. */
PREP_CLONES
static void fit8(const lanes *L, float slope, int min_support, prep_v8i *keep, prep_v8f *nrm)
{
    const prep_v8f zero = {0};
    prep_v8f g[4] = {zero, zero, zero, zero}, abc[3];
    vfit f;
    prep_v8i k = L->a1w != 0.0f;
    round_of(L, g, &f);
    k &= f.support >= min_support;
    prep_v8i ok1;
    solve(&f, abc, &ok1);
    ok1 &= k;
    prep_v8f rss = f.szz - 2.0f * (abc[0] * f.sxz + abc[1] * f.syz + abc[2] * f.sz) +
                   abc[0] * abc[0] * f.sxx + 2.0f * abc[0] * abc[1] * f.sxy +
                   abc[1] * abc[1] * f.syy + 2.0f * abc[0] * abc[2] * f.sx +
                   2.0f * abc[1] * abc[2] * f.sy + abc[2] * abc[2] * f.n;
    prep_v8f m = sel(rss > 0.0f, rss, zero);
    prep_v8f b1 = sel(ok1, m / f.n, zero), b2 = 0.0625f * slope * (-L->a1z);
    vsqrt(&b1);
    b1 = 2.5f * b1;
    prep_v8f bound = sel(b1 > b2, b1, b2);
    prep_v8f e1x = L->a1x - L->pax, e1y = L->a1y - L->pay, e1z = L->a1z - L->paz;
    prep_v8f r1 = e1z - (abc[0] * e1x + abc[1] * e1y + abc[2]);
    k &= ~(ok1 & (vabs(r1) > bound));
    ok1 &= k;
    prep_v8f one = zero + 1.0f;
    nrm[0] = zero, nrm[1] = zero, nrm[2] = one;
    int any = 0;
    for (int l = 0; l < 8; l++) any |= ok1[l];
    if (!any) {
        *keep = k;
        return;
    }
    g[0] = sel(ok1, abc[0], zero), g[1] = sel(ok1, abc[1], zero);
    g[2] = sel(ok1, abc[2], zero), g[3] = sel(ok1, bound, zero);
    round_of(L, g, &f);
    k &= ~(ok1 & (f.support < min_support));
    prep_v8i ok2;
    solve(&f, abc, &ok2);
    ok2 &= ok1 & k;
    prep_v8f len = sel(ok2, abc[0] * abc[0] + abc[1] * abc[1] + 1.0f, one);
    vsqrt(&len);
    nrm[0] = sel(ok2, -abc[0] / len, zero), nrm[1] = sel(ok2, -abc[1] / len, zero);
    nrm[2] = sel(ok2, 1.0f / len, one);
    *keep = k;
}

/* Lane l of L: listed pixel (qx, qy), its points and its 3x3 neighbourhood's ("no point"
 * outside the rectangle and where near[] has none). */
static void load_lane(const kawata_fit_job *job, int qx, int qy, int l, lanes *L)
{
    const int w = job->bw;
    const size_t row0 = (size_t)job->y0 * (size_t)w;
    const size_t b = (size_t)qy * (size_t)w + (size_t)qx - row0;
    const float *a1 = job->pts + 16 * b, *a2 = a1 + 4;
    for (int k = 0, dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++, k += 2) {
            int rx = qx + dx, ry = qy + dy;
            const float *p = NONE, *p2 = NONE;
            if (rx >= job->x0 && ry >= job->y0 && rx < job->x1 && ry < job->y1) {
                size_t r = (size_t)ry * (size_t)w + (size_t)rx - row0;
                if (job->near[r] != 0xFFFFFFFFu) p = job->pts + 16 * r, p2 = p + 4;
            }
            L->x[k][l] = p[0], L->y[k][l] = p[1], L->z[k][l] = p[2], L->w[k][l] = p[3];
            L->x[k + 1][l] = p2[0], L->y[k + 1][l] = p2[1];
            L->z[k + 1][l] = p2[2], L->w[k + 1][l] = p2[3];
        }
    float pa[3];
    for (int i = 0; i < 3; i++) pa[i] = a2[3] > 0.0f ? 0.5f * (a1[i] + a2[i]) : a1[i];
    L->pax[l] = pa[0], L->pay[l] = pa[1], L->paz[l] = pa[2];
    L->a1x[l] = a1[0], L->a1y[l] = a1[1], L->a1z[l] = a1[2], L->a1w[l] = a1[3];
    L->tol[l] = job->gamma + job->slope * (-a1[2]);
}

/* An empty lane (past the list's end): no splat. */
static void empty_lane(int l, lanes *L)
{
    L->a1w[l] = 0.0f, L->a1z[l] = 0.0f, L->tol[l] = 0.0f;
    for (int k = 0; k < 18; k++) L->w[k][l] = 0.0f;
}

/* The rest of the shader's pixel() for a kept pixel: colour, shading, the splat, the tiles. */
static void finish(const kawata_fit_job *job, int qx, int qy, const float nrm[3])
{
    const int w = job->bw;
    const size_t b = (size_t)qy * (size_t)w + (size_t)qx - (size_t)job->y0 * (size_t)w;
    const float *a1 = job->pts + 16 * b, *a2 = a1 + 4;
    float pa[3];
    for (int i = 0; i < 3; i++) pa[i] = a2[3] > 0.0f ? 0.5f * (a1[i] + a2[i]) : a1[i];
    const float *c1 = a1 + 8, *c2 = a1 + 12;
    float col[3];
    for (int i = 0; i < 3; i++) col[i] = a2[3] > 0.0f ? 0.5f * (c1[i] + c2[i]) : c1[i];
    const float *m = job->view;
    if (job->color == 2) {
        for (int i = 0; i < 3; i++) {
            float ln = m[4 * i] * nrm[0] + m[4 * i + 1] * nrm[1] + m[4 * i + 2] * nrm[2];
            col[i] = ln * 0.5f + 0.5f;
        }
    } else if (job->color == 3) {
        float t = (-pa[2] - job->znear) / (job->zfar - job->znear);
        t = t > 0.0f ? t : 0.0f;
        t = t < 1.0f ? t : 1.0f;
        col[0] = col[1] = col[2] = 1.0f - t;
    } else {
        const float *l = job->light;
        float ndl = nrm[0] * l[0] + nrm[1] * l[1] + nrm[2] * l[2];
        float s = 0.2f + 0.8f * (ndl > 0.0f ? ndl : 0.0f);
        for (int i = 0; i < 3; i++) col[i] *= s;
    }
    const float *p = job->proj;
    float cx = p[0] * pa[0] + p[4] * pa[1] + p[8] * pa[2] + p[12];
    float cy = p[1] * pa[0] + p[5] * pa[1] + p[9] * pa[2] + p[13];
    float cw = p[3] * pa[0] + p[7] * pa[1] + p[11] * pa[2] + p[15];
    float *s = job->splats + 8 * b;
    s[0] = (cx / cw * 0.5f + 0.5f) * (float)job->fw;
    s[1] = (cy / cw * 0.5f + 0.5f) * (float)job->fh;
    s[2] = -pa[2], s[3] = 1.0f;
    s[4] = col[0], s[5] = col[1], s[6] = col[2], s[7] = 1.0f;
    /* the 8x8 tiles of buffer pixels q - 3 .. q + 3 (at most 2x2) */
    int tw = (job->bw + 7) >> 3;
    int tx0 = (qx - 3 > 0 ? qx - 3 : 0) >> 3, ty0 = (qy - 3 > 0 ? qy - 3 : 0) >> 3;
    int tx1 = (qx + 3 < job->bw - 1 ? qx + 3 : job->bw - 1) >> 3;
    int ty1 = (qy + 3 < job->bh - 1 ? qy + 3 : job->bh - 1) >> 3;
    __atomic_store_n(&job->tiles[ty0 * tw + tx0], 1u, __ATOMIC_RELAXED);
    __atomic_store_n(&job->tiles[ty0 * tw + tx1], 1u, __ATOMIC_RELAXED);
    __atomic_store_n(&job->tiles[ty1 * tw + tx0], 1u, __ATOMIC_RELAXED);
    __atomic_store_n(&job->tiles[ty1 * tw + tx1], 1u, __ATOMIC_RELAXED);
}

typedef struct fit_run {
    const kawata_fit_job *job;
    int bands;
    uint32_t count;            /* splats, summed atomically */
} fit_run;

/* The first list entry at row y or after. */
static uint32_t list_row(const kawata_fit_job *job, uint32_t y)
{
    uint32_t lo = 0, hi = job->n;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (job->list[mid] >> 16 < y) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Task c: band c of the rectangle's rows: their splats cleared over the rectangle's columns,
 * then the listed pixels in them fitted. */
static int fit_task(void *ctx, size_t c, int tid, sd_err *err)
{
    (void)tid, (void)err;
    fit_run *r = ctx;
    const kawata_fit_job *job = r->job;
    uint64_t rows = (uint64_t)(job->y1 - job->y0);
    uint32_t ya = (uint32_t)job->y0 + (uint32_t)(rows * c / (uint64_t)r->bands);
    uint32_t yb = (uint32_t)job->y0 + (uint32_t)(rows * (c + 1) / (uint64_t)r->bands);
    size_t rw = (size_t)(job->x1 - job->x0);
    for (uint32_t y = ya; y < yb; y++) {
        size_t at = ((size_t)(y - (uint32_t)job->y0) * (size_t)job->bw + (size_t)job->x0) * 8;
        memset(job->splats + at, 0, rw * 8 * sizeof(float));
    }
    uint32_t count = 0, k0 = list_row(job, ya), k1 = list_row(job, yb);
    lanes L;
    for (uint32_t k = k0; k < k1; k += 8) {
        for (uint32_t l = 0; l < 8; l++) {
            uint32_t e = k + l < k1 ? job->list[k + l] : 0;
            if (k + l < k1) load_lane(job, (int)(e & 0xFFFFu), (int)(e >> 16), (int)l, &L);
            else empty_lane((int)l, &L);
        }
        prep_v8i keep;
        prep_v8f nrm[3];
        fit8(&L, job->slope, job->min_support, &keep, nrm);
        for (uint32_t l = 0; l < 8 && k + l < k1; l++) {
            if (!keep[l]) continue;
            uint32_t e = job->list[k + l];
            const float nl[3] = {nrm[0][l], nrm[1][l], nrm[2][l]};
            finish(job, (int)(e & 0xFFFFu), (int)(e >> 16), nl);
            count++;
        }
    }
    __atomic_fetch_add(&r->count, count, __ATOMIC_RELAXED);
    return 0;
}

uint32_t kawata_fit_cpu(const kawata_fit_job *job)
{
    if (job->y1 <= job->y0 || job->x1 <= job->x0) return 0;
    uint32_t tp = job->thread_pixels ? job->thread_pixels : KAWATA_CPU_THREAD_PIXELS;
    int nt = job->threads < 1 ? 1 : job->threads;
    if ((uint32_t)nt > 1 + job->n / tp) nt = (int)(1 + job->n / tp);
    fit_run r = {job, nt > 1 ? nt * BANDS_PER_THREAD : 1, 0};
    if (r.bands > job->y1 - job->y0) r.bands = job->y1 - job->y0;
    prep_par_for(nt, (size_t)r.bands, fit_task, &r, NULL, NULL);
    return r.count;
}
