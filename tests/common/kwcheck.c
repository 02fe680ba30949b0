/* kwcheck.c — see kwcheck.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "kwcheck.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"

#define U_ROUND 0x1p-24 /* u: the relative error of one correctly rounded float operation */

/* The buffer pixel of one axis for a quotient q (the shader's b = (q * 0.5 + 0.5) * size, each
 * operation rounded: float arithmetic, compiled without contraction), or -1 outside [0, size). */
static int axis_pixel(float q, int size)
{
    float b = (q * 0.5f + 0.5f) * (float)size;
    if (!(b >= 0.0f && b < (float)size)) return -1;
    int k = (int)b;
    return k < size - 1 ? k : size - 1;
}

/* The pixels one axis may get for the quotient a / d of two floats: a conforming division is
 * within 2.5 ulp of it (the host's within 0.5), and b grows with q, so the candidates are the
 * pixels of the least and the greatest float within 2.5 ulp (one more ulp each way for the ulp
 * changing at a power of two). *lo, *hi: the pixels (-1: outside). */
static void axis_range(float a, float d, int size, int *lo, int *hi)
{
    double q = (double)a / (double)d;
    float qf = (float)q;
    double ulp = (double)nextafterf(fabsf(qf), INFINITY) - (double)fabsf(qf);
    float qlo = nextafterf((float)(q - 2.5 * ulp), -INFINITY);
    float qhi = nextafterf((float)(q + 2.5 * ulp), INFINITY);
    *lo = axis_pixel(qlo, size);
    *hi = axis_pixel(qhi, size);
}

/* 1 when float words a and b lie within `ulps` units in the last place of each other (as
 * values: +0 and -0 are equal). */
static int within_ulps(uint32_t a, uint32_t b, uint32_t ulps)
{
    float fa, fb;
    memcpy(&fa, &a, 4), memcpy(&fb, &b, 4);
    if (fa == fb) return 1;
    float m = fmaxf(fabsf(fa), fabsf(fb));
    double ulp = (double)nextafterf(m, INFINITY) - (double)m;
    return fabs((double)fa - (double)fb) <= ulps * ulp;
}

/* pts entry (4 floats) of a point: eye position x, y, z within 2 E_c of each other, w equal.
 * The point is pos[idx] when pos is not NULL, else any point whose coordinates are at most pmax
 * in magnitude (its index addresses no array the test has: a LOD pool's). */
static int eye_ok(const uint32_t *g, const uint32_t *h, const float *pos, uint32_t idx,
                  uint64_t n, double pmax, const float view[16])
{
    if (pos && idx >= n) return memcmp(g, h, 16) == 0;
    const float *p = pos ? pos + 3 * (size_t)idx : NULL;
    const double g4 = 4 * U_ROUND / (1 - 4 * U_ROUND);
    for (int r = 0; r < 3; r++) {
        double terms = fabs((double)view[12 + r]);
        for (int j = 0; j < 3; j++) terms += fabs((double)view[4 * j + r]) * (p ? fabs(p[j]) : pmax);
        float a, b;
        memcpy(&a, g + r, 4), memcpy(&b, h + r, 4);
        if (!(fabs((double)a - (double)b) <= 2 * g4 * terms)) return 0;
    }
    return g[3] == h[3];
}

/* Whether a buffer pixel within reach (Chebyshev distance) of (qx, qy) has a differing input. */
static int within_reach(const uint8_t *bad, int bw, int bh, int qx, int qy, int reach)
{
    for (int dy = -reach; dy <= reach; dy++)
        for (int dx = -reach; dx <= reach; dx++) {
            int ax = qx + dx, ay = qy + dy;
            if (ax >= 0 && ay >= 0 && ax < bw && ay < bh && bad[(size_t)ay * bw + ax]) return 1;
        }
    return 0;
}

void kw_compare(const rnd_frame *gl, const rnd_frame *host, const float *pos, uint64_t n,
                int indexed, uint64_t cloud_n, const double offset[3], const double bmin[3],
                const double bmax[3], const rnd_camera *cam, const char *what, kw_cmp *out)
{
    memset(out, 0, sizeof *out);
    assert_non_null(gl->kawata_arrays);
    assert_non_null(host->kawata_arrays);
    assert_int_equal(gl->buffer_w, host->buffer_w);
    assert_int_equal(gl->buffer_h, host->buffer_h);
    assert_int_equal(gl->width, host->width);
    assert_int_equal(gl->height, host->height);
    const int bw = gl->buffer_w, bh = gl->buffer_h, fw = gl->width, fh = gl->height;
    const size_t nb = (size_t)bw * (size_t)bh;
    float lo[3], hi[3];
    for (int a = 0; a < 3; a++)
        lo[a] = (float)(bmin[a] - offset[a]), hi[a] = (float)(bmax[a] - offset[a]);
    rnd_view v;
    sd_err err = {0};
    if (rnd__view_setup(cam, offset, lo, hi, &v, &err) != 0) fail_msg("view: %s", err.msg);
    v.width = bw, v.height = bh;

    /* open[q]: a point may land in buffer pixel q on one side and not on the other */
    uint8_t *open = calloc(nb ? nb : 1, 1), *bad = calloc(nb ? nb : 1, 1);
    assert_non_null(open);
    assert_non_null(bad);
    const float *m = v.viewproj;
    size_t ambiguous = 0;
    double pmax = 0;
    for (uint64_t i = 0; i < n; i++) {
        const float *p = pos + 3 * (size_t)i;
        for (int a = 0; a < 3; a++) pmax = fmax(pmax, fabs(p[a]));
        float x = p[0], y = p[1], z = p[2];
        float cx = m[0] * x + m[4] * y + m[8] * z + m[12];
        float cy = m[1] * x + m[5] * y + m[9] * z + m[13];
        float d = m[3] * x + m[7] * y + m[11] * z + m[15];
        if (!(d >= v.znear && d <= v.zfar)) continue; /* the same d on both sides */
        int x0, x1, y0, y1;
        axis_range(cx, d, bw, &x0, &x1);
        axis_range(cy, d, bh, &y0, &y1);
        if (x0 == x1 && y0 == y1) continue;
        ambiguous++;
        for (int qy = y0 < 0 ? 0 : y0; qy <= y1; qy++)
            for (int qx = x0 < 0 ? 0 : x0; qx <= x1; qx++) open[(size_t)qy * bw + qx] = 1;
    }

    const uint32_t *g = gl->kawata_arrays, *h = host->kawata_arrays;
    uint32_t ibits = 1; /* pipe_kawata.c's index_bits */
    while (ibits < 32 && ((uint64_t)1 << ibits) - 1 < cloud_n) ibits++;
    const float *ipos = indexed ? pos : NULL;
    size_t unexplained = 0, pts_bad = 0;
    for (size_t q = 0; q < nb; q++) {
        out->covered += h[nb + q] != 0xFFFFFFFFu && h[q] != 0;
        out->open += open[q];
        int raster = g[q] != h[q] || g[nb + q] != h[nb + q] || g[2 * nb + q] != h[2 * nb + q];
        int listed = h[nb + q] != 0xFFFFFFFFu && h[q] != 0;
        const uint32_t *gp = g + 3 * nb + 16 * q, *hp = h + 3 * nb + 16 * q;
        int pts = listed && memcmp(gp, hp, 64) != 0;
        if (pts && !raster) { /* the same two points: their own bounds */
            uint32_t fk = h[2 * nb + q], far = fk ? fk & ((1u << ibits) - 1u) : ~0u;
            int ok = eye_ok(gp, hp, ipos, h[nb + q], n, pmax, v.view) &&
                     eye_ok(gp + 4, hp + 4, ipos, far, n, pmax, v.view);
            for (int c = 8; c < 16; c++) ok &= within_ulps(gp[c], hp[c], 3);
            pts_bad += !ok;
        }
        if (raster || pts) {
            out->differ++;
            bad[q] = 1;
            unexplained += raster && !open[q];
        }
    }
    /* splats: one that differs needs a differing input within one buffer pixel */
    size_t splat_bad = 0;
    for (int qy = 0; qy < bh; qy++)
        for (int qx = 0; qx < bw; qx++) {
            size_t q = (size_t)qy * bw + qx;
            if (!memcmp(g + 19 * nb + 8 * q, h + 19 * nb + 8 * q, 32)) continue;
            splat_bad += !within_reach(bad, bw, bh, qx, qy, 1);
        }
    /* frame pixels: one that differs needs a differing input within 4 buffer pixels of its own */
    size_t frame_bad = 0;
    for (int y = 0; y < fh; y++)
        for (int x = 0; x < fw; x++) {
            size_t i = (size_t)y * fw + x;
            if (!memcmp(gl->rgba8 + 4 * i, host->rgba8 + 4 * i, 4)) continue;
            out->pixels++;
            int bx = (int)floor((x + 0.5) * bw / fw), by = (int)floor((y + 0.5) * bh / fh);
            frame_bad += !within_reach(bad, bw, bh, bx, by, 4);
        }
    printf("kawata host vs gl, %s: buffer %dx%d, %zu covered, %zu points ambiguous (%zu pixels "
           "open); differ: %zu buffer pixels (%zu not open, %zu pts beyond their bounds), %zu "
           "frame pixels; out of reach of a differing input: %zu splats, %zu frame pixels\n",
           what, bw, bh, out->covered, ambiguous, out->open, out->differ, unexplained, pts_bad,
           out->pixels, splat_bad, frame_bad);
    free(open);
    free(bad);
    assert_int_equal(unexplained, 0);
    assert_int_equal(pts_bad, 0);
    assert_int_equal(splat_bad, 0);
    assert_int_equal(frame_bad, 0);
}
