/* kawata_fit_cpu.c — kawata's plane fit on the host (kawata_fit_cpu.h). Each function mirrors
 * the one of the same name in kawata_fit.comp STAGE 2; float literals are the shader's. */
#include "kawata_fit_cpu.h"

#include <math.h>
#include <string.h>

#include "kawata_cpu.h"
#include "progress.h"

enum { BANDS_PER_THREAD = 4 };

/* The normal-equation sums, the supporting points, the first round's plane (g[3]: the second
 * round's residual bound, 0 in the first). */
typedef struct fit {
    float sxx, sxy, syy, sx, sy, n, sxz, syz, sz, szz;
    int support;
    float g[4];
} fit;

static const float NONE[4] = {0.0f, 0.0f, 0.0f, 0.0f};

static void fit_clear(fit *f)
{
    f->sxx = f->sxy = f->syy = f->sx = f->sy = f->n = f->sxz = f->syz = f->sz = f->szz = 0.0f;
    f->support = 0;
}

static inline void add_point(const float *t, const float *pa, float z0, float tol, int self,
                             fit *f)
{
    if (t[3] == 0.0f || fabsf(t[2] - z0) > tol) return;
    float ex = t[0] - pa[0], ey = t[1] - pa[1], ez = t[2] - pa[2];
    float r = ez - (f->g[0] * ex + f->g[1] * ey + f->g[2]);
    if (f->g[3] > 0.0f && fabsf(r) > f->g[3]) return;
    if (!self) f->support++;
    f->sxx += ex * ex, f->sxy += ex * ey, f->syy += ey * ey;
    f->sx += ex, f->sy += ey, f->n += 1.0f;
    f->sxz += ex * ez, f->syz += ey * ez, f->sz += ez, f->szz += ez * ez;
}

/* det3 of the shader: columns a, b, c. */
static inline float det3(const float *a, const float *b, const float *c)
{
    return a[0] * (b[1] * c[2] - c[1] * b[2]) - b[0] * (a[1] * c[2] - c[1] * a[2]) +
           c[0] * (a[1] * b[2] - b[1] * a[2]);
}

static int solve(const fit *f, float abc[3])
{
    abc[0] = abc[1] = abc[2] = 0.0f;
    const float cx[3] = {f->sxx, f->sxy, f->sx}, cy[3] = {f->sxy, f->syy, f->sy};
    const float cn[3] = {f->sx, f->sy, f->n}, cz[3] = {f->sxz, f->syz, f->sz};
    float det = det3(cx, cy, cn);
    float lim = 1e-6f * f->sxx * f->syy * f->n;
    if (!(fabsf(det) > lim)) return 0;
    abc[0] = det3(cz, cy, cn) / det;
    abc[1] = det3(cx, cz, cn) / det;
    abc[2] = det3(cx, cy, cz) / det;
    return 1;
}

/* One round over the 18 points v[0..17] (neighbour k's nearest 2k, farthest 2k + 1; the pixel
 * itself is k = 4). */
static void round_of(const float *const v[18], const float *pa, float z0, float tol, fit *f)
{
    fit_clear(f);
    for (int i = 0; i < 18; i++) add_point(v[i], pa, z0, tol, i == 8, f);
}

/* Buffer pixel (qx, qy) of the list: its splat, its tiles marked; returns 1 for a splat. */
static int pixel(const kawata_fit_job *job, int qx, int qy)
{
    const int w = job->bw;
    const size_t row0 = (size_t)job->y0 * (size_t)w;
    const size_t b = (size_t)qy * (size_t)w + (size_t)qx - row0;
    const float *a1 = job->pts + 16 * b, *a2 = a1 + 4;
    if (a1[3] == 0.0f) return 0;
    float pa[3];
    for (int i = 0; i < 3; i++) pa[i] = a2[3] > 0.0f ? 0.5f * (a1[i] + a2[i]) : a1[i];
    float tol = job->gamma + job->slope * (-a1[2]);
    const float *v[18];
    for (int k = 0, dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++, k += 2) {
            int rx = qx + dx, ry = qy + dy;
            if (rx < job->x0 || ry < job->y0 || rx >= job->x1 || ry >= job->y1) {
                v[k] = v[k + 1] = NONE;
                continue;
            }
            size_t r = (size_t)ry * (size_t)w + (size_t)rx - row0;
            if (job->near[r] == 0xFFFFFFFFu) {
                v[k] = v[k + 1] = NONE;
                continue;
            }
            v[k] = job->pts + 16 * r, v[k + 1] = job->pts + 16 * r + 4;
        }
    fit f;
    f.g[0] = f.g[1] = f.g[2] = f.g[3] = 0.0f;
    round_of(v, pa, a1[2], tol, &f);
    if (f.support < job->min_support) return 0;
    float nrm[3] = {0.0f, 0.0f, 1.0f}, abc[3];
    if (solve(&f, abc)) {
        float rss = f.szz - 2.0f * (abc[0] * f.sxz + abc[1] * f.syz + abc[2] * f.sz) +
                    abc[0] * abc[0] * f.sxx + 2.0f * abc[0] * abc[1] * f.sxy +
                    abc[1] * abc[1] * f.syy + 2.0f * abc[0] * abc[2] * f.sx +
                    2.0f * abc[1] * abc[2] * f.sy + abc[2] * abc[2] * f.n;
        float m = rss > 0.0f ? rss : 0.0f;
        float b1 = 2.5f * sqrtf(m / f.n), b2 = 0.0625f * job->slope * (-a1[2]);
        float bound = b1 > b2 ? b1 : b2;
        float e1x = a1[0] - pa[0], e1y = a1[1] - pa[1], e1z = a1[2] - pa[2];
        float r1 = e1z - (abc[0] * e1x + abc[1] * e1y + abc[2]);
        if (fabsf(r1) > bound) return 0;
        f.g[0] = abc[0], f.g[1] = abc[1], f.g[2] = abc[2], f.g[3] = bound;
        round_of(v, pa, a1[2], tol, &f);
        if (f.support < job->min_support) return 0;
        if (solve(&f, abc)) {
            float len = sqrtf(abc[0] * abc[0] + abc[1] * abc[1] + 1.0f);
            nrm[0] = -abc[0] / len, nrm[1] = -abc[1] / len, nrm[2] = 1.0f / len;
        }
    }
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
    return 1;
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
    uint32_t count = 0;
    for (uint32_t k = list_row(job, ya), e; k < job->n && (e = job->list[k]) >> 16 < yb; k++)
        count += (uint32_t)pixel(job, (int)(e & 0xFFFFu), (int)(e >> 16));
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
