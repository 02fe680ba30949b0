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
 * batches again gave 6055 wrong words). Both are C on one machine, so word for word is what
 * to expect; the comparison with the GL, whose precision the GLSL specification bounds less
 * tightly, is test_render_kawata's test_host_vs_gl. */
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

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_against_reference),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
