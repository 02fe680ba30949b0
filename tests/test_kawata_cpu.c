/* test_kawata_cpu.c — kawata's passes 1 and 2 on the host (pipelines/kawata_cpu.c) against a
 * direct reference written from their definition (pipe_kawata.c, kawata_raster.comp): every
 * point projected one at a time; depth = the least key of a pixel; near = the least cloud-wide
 * index of the points with exactly that key; far = the greatest (1 + min(uint(step qscale),
 * qmax - 2)) << index_bits | index over the points behind it by a step of at most gamma;
 * ~0u, ~0u, 0 where no point lands. The scene: a noisy wall (several points a pixel, depth
 * steps within gamma and beyond) and random points in and out of the frustum (behind the eye,
 * past the far plane, off the sides), in three runs of two buffer sets with gaps between them
 * (points not drawn), duplicated points (equal keys: near's tie goes to the lowest index), and
 * only the rectangle [X0, X1) x [Y0, Y1) of the buffer written (the rest of its rows left as
 * they were). Run with 1, 2 and 3 threads (at least 1000 points a thread, so that this small
 * scene uses them) and in batches of every point, 1000 and 777 (pass 2 projecting again), which
 * must all give the reference's arrays word for word (checked to fail: pass 2 not projecting its
 * batches again gave 6055 wrong words). test_fit: the plane fit on the host
 * (kawata_fit_cpu.c) on a plane with holes, an outlier and clusters at the support threshold
 * (checked to fail: a support test of <= instead of <, 4 wrong splats; the neighbours' row below
 * read two rows down, 2). The GL comparison is test_render_kawata's test_host_equals_gpu. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "kawata_cpu.h"
#include "kawata_fit_cpu.h"
#include "rng.h"
#include "testutil.h"

enum { BW = 97, BH = 61, X0 = 6, X1 = 90, Y0 = 9, Y1 = 55, NA = 12000, NB = 8000 };

static float frand(rng *g, float lo, float hi)
{
    return (float)(lo + (hi - lo) * uni(g));
}

/* Whether buffer pixel q (row-major) is inside the rectangle written. */
static int inside(long q)
{
    long x = q % BW, y = q / BW;
    return q >= 0 && x >= X0 && x < X1 && y >= Y0 && y < Y1;
}

static uint32_t bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    return u;
}

/* The reference projection, written as kawata_raster.comp reads: c = M (p, 1) summed column by
 * column, d = c.w, b = (c.xy / d * 0.5 + 0.5) * size; the pixel (row-major, whole buffer) or
 * -1. */
static long pixel_of(const float *m, const float *p, float zn, float zf, float *d)
{
    float cx = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
    float cy = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
    *d = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    if (!(*d >= zn && *d <= zf)) return -1;
    float bx = (cx / *d * 0.5f + 0.5f) * (float)BW, by = (cy / *d * 0.5f + 0.5f) * (float)BH;
    if (!(bx >= 0.0f && by >= 0.0f && bx < (float)BW && by < (float)BH)) return -1;
    int qx = (int)bx < BW - 1 ? (int)bx : BW - 1, qy = (int)by < BH - 1 ? (int)by : BH - 1;
    return (long)qy * BW + qx;
}

static void test_against_reference(void **state)
{
    (void)state;
    rng seed = {11};
    float *pa = malloc(3 * sizeof(float) * NA), *pb = malloc(3 * sizeof(float) * NB);
    assert_non_null(pa);
    assert_non_null(pb);
    for (int i = 0; i < NA + NB; i++) {
        float *p = i < NA ? pa + 3 * i : pb + 3 * (i - NA);
        if (i % 10 < 7) { /* a noisy wall 5 in front of the eye: several points a pixel */
            p[0] = frand(&seed, -3.0f, 3.0f), p[1] = frand(&seed, -2.0f, 2.0f);
            p[2] = -5.0f + frand(&seed, -0.3f, 0.3f);
        } else { /* scattered, some behind the eye, some past the far plane, some aside */
            p[0] = frand(&seed, -6.0f, 6.0f), p[1] = frand(&seed, -4.0f, 4.0f);
            p[2] = frand(&seed, -25.0f, 2.0f);
        }
        if (i % 7 == 3 && i > 0) memcpy(p, p - 3, 3 * sizeof *p); /* duplicates: equal keys */
    }
    /* a perspective camera at the origin looking down -z (eye depth = -z) */
    const float zn = 0.5f, zf = 20.0f, f = 1.0f / tanf(0.5f * 0.9f), asp = (float)BW / BH;
    const float m[16] = {f / asp, 0, 0, 0, 0, f, 0, 0, 0.01f, -0.02f, (zf + zn) / (zn - zf), -1,
                         0, 0, 2 * zf * zn / (zn - zf), 0};
    /* set A (base 0): points [100, 5600) and [6000, 12000); set B (base NA): [0, 7000) */
    const kawata_cpu_seg segs[3] = {{pa, 0, 100, 5500}, {pa, 0, 6000, 6000},
                                    {pb, NA, 0, 7000}};
    const uint32_t ibits = 14, qmax = (1u << (32 - ibits)) - 1u;
    const float gamma = 0.4f, qscale = (float)(qmax - 1) / gamma;

    uint32_t ref[3][BW * BH];
    for (int p = 0; p < BW * BH; p++) ref[0][p] = ~0u, ref[1][p] = ~0u, ref[2][p] = 0;
    for (int pass = 1; pass <= 2; pass++)
        for (int s = 0; s < 3; s++)
            for (uint32_t j = 0; j < segs[s].count; j++) {
                uint32_t i = segs[s].first + j;
                float d;
                long q = pixel_of(m, segs[s].pos + 3 * i, zn, zf, &d);
                if (!inside(q)) continue;
                uint32_t key = bits(d), idx = (uint32_t)segs[s].base + i;
                if (pass == 1) {
                    if (key < ref[0][q]) ref[0][q] = key;
                } else if (key == ref[0][q]) {
                    if (idx < ref[1][q]) ref[1][q] = idx;
                } else {
                    float d1;
                    uint32_t u = ref[0][q];
                    memcpy(&d1, &u, 4);
                    float step = d - d1;
                    if (step > gamma) continue;
                    uint32_t st = (uint32_t)(step * qscale);
                    uint32_t fk = ((1u + (st < qmax - 2u ? st : qmax - 2u)) << ibits) | idx;
                    if (fk > ref[2][q]) ref[2][q] = fk;
                }
            }
    size_t covered = 0, farred = 0, ties = 0;
    for (int p = 0; p < BW * BH; p++) covered += ref[1][p] != ~0u, farred += ref[2][p] != 0;
    for (int i = 3; i < NA; i += 7) { /* a duplicate nearest: near holds the earlier point */
        float d;
        long q = pixel_of(m, pa + 3 * i, zn, zf, &d);
        if (inside(q) && ref[1][q] == (uint32_t)i - 1) ties++;
    }
    printf("reference: %zu of %d pixels covered, %zu with a farthest point, %zu won by the lower "
           "of two equal points\n", covered, (Y1 - Y0) * (X1 - X0), farred, ties);
    assert_true(covered > 2000 && farred > 1000 && ties > 20);

    const int threads[3] = {1, 2, 3};
    const size_t batches[3] = {0, 1000, 777};
    for (int t = 0; t < 3; t++)
        for (int b = 0; b < 3; b++) {
            size_t rw = (size_t)BW * (Y1 - Y0); /* the rows' words, an array */
            uint32_t *out = malloc(3 * 4 * rw);
            assert_non_null(out);
            memset(out, 0x5A, 3 * 4 * rw); /* the rectangle written, the rest left as it is */
            kawata_cpu_mem mem = {0};
            kawata_cpu_job job = {.segs = segs, .nsegs = 3, .bw = BW, .bh = BH, .znear = zn,
                                  .zfar = zf, .gamma = gamma, .qscale = qscale, .ibits = ibits,
                                  .qmax = qmax, .x0 = X0, .x1 = X1, .y0 = Y0, .y1 = Y1,
                                  .depth = out,
                                  .near = out + rw, .far = out + 2 * rw, .threads = threads[t],
                                  .batch = batches[b], .thread_points = 1000, .mem = &mem};
            memcpy(job.viewproj, m, sizeof m);
            assert_int_equal(kawata_cpu_raster(&job), 0);
            size_t differ = 0;
            for (int a = 0; a < 3; a++)
                for (size_t p = 0; p < rw; p++)
                    differ += out[a * rw + p] != (inside((long)((size_t)Y0 * BW + p))
                                                      ? ref[a][(size_t)Y0 * BW + p]
                                                      : 0x5A5A5A5Au);
            printf("threads %d, batch %zu: %zu words differ\n", threads[t], batches[b], differ);
            assert_int_equal(differ, 0);
            kawata_cpu_mem_free(&mem);
            free(out);
        }
    free(pa);
    free(pb);
}

/* ---- the fit (kawata_fit_cpu.c) ---- */

enum { FW_ = 40, FH_ = 30, FX0 = 3, FX1 = 36, FY0 = 2, FY1 = 27, OX = 17, OY = 11 };

/* A plane z = A x + B y + C in eye space sampled one point a buffer pixel over the rectangle
 * [FX0, FX1) x [FY0, FY1), a second point on it in every other pixel, a hole at (8, 8), an empty
 * corner (x < 12, y >= 14: the 8x8 tile at (0, 3) is out of every splat's reach) holding a 2x2
 * block of single points (each with exactly the 3 supporters a splat needs: kept) and a pair
 * (1 supporter each: dropped, and marking no tile), and an
 * outlier 1 in front of the plane at (OX, OY): the fit's splats, against the plane's analytic
 * normal (color=normal with the identity view: (n + 1) / 2; the plane's points are exact, so
 * only rounding separates them: 1e-4), Lambert colours, positions (projected in double:
 * 1e-3 frame pixels), depths (-pa.z, exact), the outlier dropped for want of support (its
 * neighbours' fits leave it out: their normals stay exact), the hole's neighbours kept, the tile
 * marks (a tile is marked exactly when a splat's q - 3 .. q + 3 reaches it), the columns outside
 * the rectangle left as they were, and 1, 2 and 3 threads giving the same words. */
static void test_fit(void **state)
{
    (void)state;
    const float A = 0.3f, B = -0.2f, C = -5.0f, h = 0.05f;
    size_t rows = FY1 - FY0, rw = (size_t)FW_ * rows;
    uint32_t *near = malloc(4 * rw), *list = malloc(4 * rw);
    float *pts = calloc(16 * rw, 4);
    assert_non_null(near), assert_non_null(list), assert_non_null(pts);
    uint32_t n = 0;
    for (int y = FY0; y < FY1; y++)
        for (int x = 0; x < FW_; x++) {
            size_t q = (size_t)(y - FY0) * FW_ + (size_t)x;
            int block = (x == 3 || x == 4) && (y == 15 || y == 16);
            int pair = y == 26 && (x == 8 || x == 9);
            int on = (x >= FX0 && x < FX1 && !(x == 8 && y == 8) && !(x < 12 && y >= 14)) ||
                     block || pair;
            near[q] = on ? (uint32_t)q : 0xFFFFFFFFu;
            if (!on) continue;
            list[n++] = (uint32_t)x | (uint32_t)y << 16;
            float *p = pts + 16 * q;
            p[0] = (float)(x - FW_ / 2) * h, p[1] = (float)(y - FH_ / 2) * h;
            p[2] = A * p[0] + B * p[1] + C, p[3] = 1.0f;
            if (x == OX && y == OY) p[2] += 1.0f;
            if ((x + y) % 2 == 0 && !block && !pair) {
                p[4] = p[0] + 0.3f * h, p[5] = p[1] + 0.2f * h;
                p[6] = A * p[4] + B * p[5] + C, p[7] = 1.0f;
                p[12] = 0.6f, p[13] = 0.4f, p[14] = 0.2f, p[15] = 1.0f;
            }
            p[8] = 0.2f, p[9] = 0.4f, p[10] = 0.6f, p[11] = 1.0f;
        }
    const float zn = 1.0f, zf = 20.0f, f = 2.0f, asp = (float)FW_ / FH_;
    const float proj[16] = {f / asp, 0, 0, 0, 0, f, 0, 0, 0, 0, (zf + zn) / (zn - zf), -1,
                            0, 0, 2 * zf * zn / (zn - zf), 0};
    size_t ntile = (size_t)((FW_ + 7) / 8) * (size_t)((FH_ + 7) / 8);
    double len = sqrt((double)A * A + (double)B * B + 1.0);
    const double nrm[3] = {-A / len, -B / len, 1.0 / len};
    float *first = NULL;
    for (int color = 0; color <= 2; color += 2)
        for (int t = 1; t <= 3; t++) {
            float *spl = malloc(32 * rw);
            uint32_t *tiles = calloc(ntile, 4);
            assert_non_null(spl), assert_non_null(tiles);
            memset(spl, 0x5A, 32 * rw);
            kawata_fit_job job = {.bw = FW_, .bh = FH_, .fw = 4 * FW_, .fh = 4 * FH_,
                                  .x0 = FX0, .x1 = FX1, .y0 = FY0, .y1 = FY1, .near = near,
                                  .pts = pts, .list = list, .n = n, .gamma = 0.05f,
                                  .slope = 0.01f, .znear = zn, .zfar = zf,
                                  .light = {0.0f, 0.0f, 1.0f}, .min_support = 3,
                                  .color = color, .splats = spl, .tiles = tiles,
                                  .threads = t, .thread_pixels = 50};
            const float view[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
            memcpy(job.view, view, sizeof view);
            memcpy(job.proj, proj, sizeof proj);
            uint32_t count = kawata_fit_cpu(&job);
            size_t splats = 0, bad = 0, untouched = 0, tbad = 0, marked = 0;
            double worst_n = 0, worst_xy = 0;
            for (int y = FY0; y < FY1; y++)
                for (int x = 0; x < FW_; x++) {
                    size_t q = (size_t)(y - FY0) * FW_ + (size_t)x;
                    const float *s = spl + 8 * q;
                    if (x < FX0 || x >= FX1) {
                        uint32_t w[8];
                        memcpy(w, s, sizeof w);
                        int same = 1;
                        for (int i = 0; i < 8; i++) same &= w[i] == 0x5A5A5A5Au;
                        untouched += (size_t)same;
                        continue;
                    }
                    int want = near[q] != 0xFFFFFFFFu && !(x == OX && y == OY) &&
                               !(y == 26 && (x == 8 || x == 9));
                    if (!want) {
                        bad += s[3] != 0.0f;
                        continue;
                    }
                    if (s[3] != 1.0f) {
                        bad++;
                        continue;
                    }
                    splats++;
                    const float *p = pts + 16 * q;
                    double pa[3];
                    for (int i = 0; i < 3; i++)
                        pa[i] = p[7] > 0 ? 0.5 * ((double)p[i] + p[4 + i]) : p[i];
                    double cw = -pa[2], sx = (proj[0] * pa[0] / cw * 0.5 + 0.5) * 4 * FW_;
                    double sy = (proj[5] * pa[1] / cw * 0.5 + 0.5) * 4 * FH_;
                    worst_xy = fmax(worst_xy, fmax(fabs(s[0] - sx), fabs(s[1] - sy)));
                    bad += s[2] != (float)-(p[7] > 0 ? 0.5f * (p[2] + p[6]) : p[2]);
                    for (int i = 0; i < 3; i++) {
                        double c = p[15] > 0 ? 0.5 * ((double)p[8 + i] + p[12 + i]) : p[8 + i];
                        double want_c = color == 2 ? nrm[i] * 0.5 + 0.5
                                                   : c * (0.2 + 0.8 * nrm[2]);
                        worst_n = fmax(worst_n, fabs(s[4 + i] - want_c));
                    }
                }
            /* tiles: marked exactly where some splat's q - 3 .. q + 3 reaches */
            for (size_t ti = 0; ti < ntile; ti++) {
                int tx = (int)(ti % ((FW_ + 7) / 8)), ty = (int)(ti / ((FW_ + 7) / 8)), reach = 0;
                for (int y = FY0; y < FY1 && !reach; y++)
                    for (int x = FX0; x < FX1 && !reach; x++) {
                        size_t q = (size_t)(y - FY0) * FW_ + (size_t)x;
                        if (spl[8 * q + 3] != 1.0f) continue;
                        reach = x + 3 >= 8 * tx && x - 3 < 8 * tx + 8 && y + 3 >= 8 * ty &&
                                y - 3 < 8 * ty + 8;
                    }
                tbad += tiles[ti] != (uint32_t)reach;
                marked += tiles[ti] != 0;
            }
            printf("fit, color %d, %d threads: %u splats (%zu checked), %zu wrong, %zu columns "
                   "outside left, worst colour/normal error %.2g, position %.2g px, %zu of %zu "
                   "tiles marked, %zu wrongly\n", color, t, count, splats, bad, untouched,
                   worst_n, worst_xy, marked, ntile, tbad);
            assert_int_equal(count, splats);
            assert_int_equal(splats, (size_t)n - 3);
            assert_true(marked > 0 && marked < ntile);
            assert_int_equal(bad, 0);
            assert_int_equal(untouched, rows * (size_t)(FW_ - (FX1 - FX0)));
            assert_true(worst_n < 1e-4 && worst_xy < 1e-3);
            assert_int_equal(tbad, 0);
            if (t == 1) {
                free(first);
                first = malloc(32 * rw);
                assert_non_null(first);
                memcpy(first, spl, 32 * rw);
            } else {
                assert_memory_equal(first, spl, 32 * rw);
            }
            free(spl);
            free(tiles);
        }
    free(first);
    free(near), free(list), free(pts);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_against_reference),
        cmocka_unit_test(test_fit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
