/* test_soft_cpu.c — the host compositor of the soft discs (pipelines/soft_cpu.c) against a
 * direct per-pixel reference: for every pixel, every disc in draw order, double precision, the
 * library cosine. Random discs of 0.3 to 25 pixels (many across the 64-pixel tile borders, some
 * partly or wholly off the frame, some with radius 0), random colours, modulation W and depths,
 * random visibility keys (a third of the pixels empty), two segments (buffer sets), one read
 * backwards. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "soft_cpu.h"
#include "testutil.h"

enum { W = 301, ROWS = 150, Y0 = 37, KB = 36, NK = ROWS + 2, N1 = 2500, N2 = 1500 };

static uint32_t rng(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

static float frand(uint32_t *s, float lo, float hi)
{
    return lo + (hi - lo) * (float)(rng(s) & 0xFFFF) / 65535.0f;
}

static uint32_t key_of(float depth)
{
    uint32_t b;
    memcpy(&b, &depth, 4);
    return ~b;
}

typedef struct scene {
    float proj[8 * (N1 + N2)];
    uint32_t order1[N1], order2[N2];
    uint32_t keys[W * NK];
    soft_cpu_seg segs[2];
} scene;

static void make_scene(scene *sc, uint32_t seed)
{
    uint32_t s = seed;
    for (int j = 0; j < N1 + N2; j++) {
        float *q = sc->proj + 8 * j;
        q[0] = frand(&s, -30.0f, W + 30.0f);
        q[1] = frand(&s, Y0 - 40.0f, Y0 + ROWS + 40.0f);
        uint32_t kind = rng(&s) % 10;
        q[2] = kind == 0 ? 0.0f : kind < 9 ? frand(&s, 0.3f, 4.0f) : frand(&s, 4.0f, 25.0f);
        q[3] = frand(&s, 1.0f, 10.0f);
        for (int c = 0; c < 3; c++) q[4 + c] = frand(&s, 0.0f, 1.0f);
        q[7] = rng(&s) % 3 == 0 ? frand(&s, 0.0f, 1.0f) : 1.0f;
    }
    /* each segment's order: a random permutation of its discs */
    for (int i = 0; i < N1; i++) sc->order1[i] = (uint32_t)i;
    for (int i = 0; i < N2; i++) sc->order2[i] = (uint32_t)i;
    for (int i = N1 - 1; i > 0; i--) {
        int j = (int)(rng(&s) % (uint32_t)(i + 1));
        uint32_t t = sc->order1[i]; sc->order1[i] = sc->order1[j]; sc->order1[j] = t;
    }
    for (int i = N2 - 1; i > 0; i--) {
        int j = (int)(rng(&s) % (uint32_t)(i + 1));
        uint32_t t = sc->order2[i]; sc->order2[i] = sc->order2[j]; sc->order2[j] = t;
    }
    for (int i = 0; i < W * NK; i++)
        sc->keys[i] = rng(&s) % 3 == 0 ? 0u : key_of(frand(&s, 1.0f, 10.0f));
    sc->segs[0] = (soft_cpu_seg){sc->proj, sc->order1, N1, 0};
    sc->segs[1] = (soft_cpu_seg){sc->proj + 8 * N1, sc->order2, N2, 1};
}

/* The reference: soft.frag per pixel, the discs in draw order, in double. */
static void reference(const scene *sc, float lambda, const uint32_t *keys, double *out)
{
    memset(out, 0, sizeof(double) * W * ROWS * 4);
    for (int s = 0; s < 2; s++) {
        const soft_cpu_seg *g = &sc->segs[s];
        for (uint32_t k = 0; k < g->n; k++) {
            const float *q = g->proj + 8 * g->order[g->rev ? g->n - 1 - k : k];
            if (!(q[2] > 0)) continue;
            int ya = (int)floor(q[1] - q[2]) - 1, yb = (int)ceil(q[1] + q[2]) + 1;
            int xa = (int)floor(q[0] - q[2]) - 1, xb = (int)ceil(q[0] + q[2]) + 1;
            for (int y = ya < Y0 ? Y0 : ya; y < Y0 + ROWS && y <= yb; y++)
                for (int x = xa < 0 ? 0 : xa; x < W && x <= xb; x++) {
                    double d = hypot(x + 0.5 - q[0], y + 0.5 - q[1]) / q[2];
                    if (!(d < 1.0)) continue;
                    if (keys) {
                        uint32_t key = keys[(y - KB) * W + x], b = ~key;
                        float kd;
                        memcpy(&kd, &b, 4);
                        if (key != 0 && q[3] >= kd) continue;
                    }
                    double phi = lambda * (cos(M_PI * d) + 1.0) * 0.5;
                    phi = (1.0 - d) * (1.0 - q[7]) + phi * q[7];
                    double *L = out + 4 * ((size_t)(y - Y0) * W + x);
                    for (int c = 0; c < 3; c++) L[c] = q[4 + c] * phi + (1 - phi) * L[c];
                    L[3] = phi + (1 - phi) * L[3];
                }
        }
    }
}

static void run(const scene *sc, float lambda, int keys, int threads, float *layer, int touched[2])
{
    soft_cpu_mem mem = {0};
    soft_cpu_job job = {.segs = sc->segs, .nsegs = 2, .lambda = lambda, .width = W, .y0 = Y0,
                        .rows = ROWS, .keys = keys ? sc->keys : NULL, .kb = KB, .nk = NK,
                        .layer = layer, .mem = &mem, .threads = threads};
    assert_int_equal(soft_cpu_composite(&job), 0);
    touched[0] = job.touched[0], touched[1] = job.touched[1];
    soft_cpu_mem_free(&mem);
}

/* Against the reference within 2e-5 (float rounding of ~10 blends a pixel and the polynomial
 * cosine, within 4.2e-6; an 8-bit step is 3.9e-3), and the same bits with 1, 2 and 5 threads.
 * touched must be the first and last row the reference changed. */
static void test_matches_reference(void **state)
{
    (void)state;
    static scene sc;
    static float a[W * ROWS * 4], b[W * ROWS * 4];
    static double ref[W * ROWS * 4];
    for (int keys = 0; keys < 2; keys++) {
        make_scene(&sc, 17u + (uint32_t)keys);
        const float lambda = 0.6f;
        reference(&sc, lambda, keys ? sc.keys : NULL, ref);
        int t1[2], t2[2];
        run(&sc, lambda, keys, 1, a, t1);
        double worst = 0;
        int changed = 0, lo = -1, hi = -1;
        for (size_t i = 0; i < (size_t)W * ROWS * 4; i++) {
            double e = fabs(a[i] - ref[i]);
            if (e > worst) worst = e;
        }
        for (int y = 0; y < ROWS; y++)
            for (int x = 0; x < W; x++)
                if (ref[4 * ((size_t)y * W + x) + 3] > 0) {
                    changed++;
                    if (lo < 0) lo = y + Y0;
                    hi = y + Y0;
                }
        printf("keys %d: %d of %d pixels reached, largest difference to the reference %.2e\n",
               keys, changed, W * ROWS, worst);
        assert_true(changed > W * ROWS / 2);
        assert_true(worst < 2e-5);
        assert_int_equal(t1[0], lo);
        assert_int_equal(t1[1], hi);
        for (int threads = 2; threads <= 5; threads += 3) {
            run(&sc, lambda, keys, threads, b, t2);
            assert_memory_equal(a, b, sizeof a);
            assert_int_equal(t1[0], t2[0]);
            assert_int_equal(t1[1], t2[1]);
        }
    }
}

/* Nothing to draw: no discs, or only discs without radius, off the rows, or with a colour that
 * is not finite (NaN, infinite: left out, not spread over the layer): the layer comes back
 * cleared and touched is -1. */
static void test_nothing(void **state)
{
    (void)state;
    static float layer[W * ROWS * 4];
    const float inf = INFINITY, nan = NAN;
    const int y = Y0 + ROWS / 2;
    float proj[32] = {10, 10, 0, 1, 1, 1, 1, 1, /* radius 0 */ 10, 500, 5, 1, 1, 1, 1, 1,
                      20, y, 6, 1, nan, 1, 1, 1, /* NaN red */ 40, y, 6, 1, 1, 1, inf, 1};
    uint32_t order[4] = {0, 1, 2, 3};
    soft_cpu_seg seg = {proj, order, 4, 0};
    soft_cpu_mem mem = {0};
    memset(layer, 0xFF, sizeof layer);
    soft_cpu_job job = {.segs = &seg, .nsegs = 1, .lambda = 1, .width = W, .y0 = Y0,
                        .rows = ROWS, .layer = layer, .mem = &mem, .threads = 2};
    assert_int_equal(soft_cpu_composite(&job), 0);
    assert_int_equal(job.touched[0], -1);
    assert_int_equal(job.touched[1], -1);
    for (size_t i = 0; i < sizeof layer / sizeof *layer; i++) assert_true(layer[i] == 0.0f);
    soft_cpu_mem_free(&mem);
}

/* The same discs over an opaque 8-bit frame (job.rgba8, soft_host.c soft__after's form), binned and
 * blended apart (soft_cpu_bin, then soft_cpu_blend with the keys): each pixel the reference reached
 * must be round(255 L + (1 - a) background) within 1 level (float against double rounding at a
 * half), at most 1 % of them off by 1; alpha and every pixel the discs did not reach unchanged,
 * rows outside the job's included; the same bytes with 1 and 3 threads. */
static void test_over_frame(void **state)
{
    (void)state;
    enum { FH = Y0 + ROWS + 5 };
    static scene sc;
    static double ref[W * ROWS * 4];
    static uint8_t bg[W * FH * 4], f1[W * FH * 4], f3[W * FH * 4];
    make_scene(&sc, 29u);
    const float lambda = 0.7f;
    reference(&sc, lambda, sc.keys, ref);
    uint32_t seed = 5;
    for (size_t i = 0; i < sizeof bg; i++) bg[i] = (uint8_t)(rng(&seed) & 255);
    for (int threads = 1; threads <= 3; threads += 2) {
        uint8_t *f = threads == 1 ? f1 : f3;
        memcpy(f, bg, sizeof bg);
        soft_cpu_mem mem = {0};
        soft_cpu_job job = {.segs = sc.segs, .nsegs = 2, .width = W, .y0 = Y0, .rows = ROWS,
                            .mem = &mem, .threads = threads};
        assert_int_equal(soft_cpu_bin(&job), 0);
        job.lambda = lambda, job.keys = sc.keys, job.kb = KB, job.nk = NK, job.rgba8 = f;
        assert_int_equal(soft_cpu_blend(&job), 0);
        soft_cpu_mem_free(&mem);
    }
    assert_memory_equal(f1, f3, sizeof f1);
    int reached = 0, off1 = 0, worst = 0;
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < W; x++) {
            size_t o = 4 * ((size_t)y * W + x);
            const double *L = y >= Y0 && y < Y0 + ROWS ? ref + 4 * ((size_t)(y - Y0) * W + x)
                                                       : NULL;
            assert_int_equal(f1[o + 3], bg[o + 3]);
            if (!L || L[3] == 0) {
                assert_memory_equal(f1 + o, bg + o, 3);
                continue;
            }
            reached++;
            for (int c = 0; c < 3; c++) {
                double v = L[c] * 255 + (1 - L[3]) * bg[o + c];
                int e = (int)floor((v < 0 ? 0 : v > 255 ? 255 : v) + 0.5);
                int d = abs((int)f1[o + c] - e);
                if (d > worst) worst = d;
                off1 += d > 0;
            }
        }
    printf("over the frame: %d pixels reached, %d channels off by 1, worst %d\n", reached, off1,
           worst);
    assert_true(reached > W * ROWS / 2);
    assert_true(worst <= 1);
    assert_true(off1 <= 3 * reached / 100);
}

/* Byte-exact rounding of the "over" onto the frame's 8-bit pixels (soft_cpu_blend with rgba8):
 * out = 255 L + (1 - a) px on the 0..255 scale, rounded to nearest with halves up, clamped.
 * Discs of radius 2 centred on pixel centres, so that the centre pixel's distance is 0 and its
 * opacity exactly lambda (cos 0 = 1), one disc per case, hand values whose exact result lands
 * on a quarter or a half, where truncation, rounding down at halves or a second rounding would
 * each give another byte (every number here is exact in float but the last):
 *   lambda 0.5, black over 101: 50.5 -> 51;   over 100: 50 -> 50
 *   lambda 0.5, white over 2: 127.5 + 1 = 128.5 -> 129;   over 255: 255 -> 255
 *   lambda 0.25, black over 5: 3.75 -> 4;   over 3: 2.25 -> 2;   over 2: 1.5 -> 2
 *   lambda 0.25, grey 0.4 over 0: 25.5 in reals, but 0.4 is 0.40000000596 in float, so
 *   25.5000004 -> 26 (the float value decides, not the tie rule: a double reference would too). */
static void test_rounding_hand_values(void **state)
{
    (void)state;
    static const struct {
        float lambda, colour;
        uint8_t px, want;
    } cases[] = {
        {0.5f, 0.0f, 101, 51}, {0.5f, 0.0f, 100, 50}, {0.5f, 1.0f, 2, 129}, {0.5f, 1.0f, 255, 255},
        {0.25f, 0.0f, 5, 4},   {0.25f, 0.0f, 3, 2},   {0.25f, 0.0f, 2, 2},  {0.25f, 0.4f, 0, 26},
    };
    enum { FW = 64, FH = 8, NC = sizeof cases / sizeof *cases };
    static uint8_t frame[FW * FH * 4];
    for (size_t k = 0; k < NC; k++) {
        memset(frame, 0, sizeof frame);
        float proj[8] = {8.5f + 6.0f * (float)k, 4.5f, 2.0f, 1.0f,
                         cases[k].colour, cases[k].colour, cases[k].colour, 1.0f};
        uint32_t order[1] = {0};
        soft_cpu_seg seg = {proj, order, 1, 0};
        size_t o = 4 * (4 * FW + 8 + 6 * k);
        frame[o] = frame[o + 1] = frame[o + 2] = cases[k].px, frame[o + 3] = 255;
        soft_cpu_mem mem = {0};
        soft_cpu_job job = {.segs = &seg, .nsegs = 1, .width = FW, .y0 = 0, .rows = FH,
                            .mem = &mem, .threads = 1};
        assert_int_equal(soft_cpu_bin(&job), 0);
        job.lambda = cases[k].lambda, job.rgba8 = frame;
        assert_int_equal(soft_cpu_blend(&job), 0);
        soft_cpu_mem_free(&mem);
        printf("lambda %.2f, colour %.1f over %3d: %3d (want %3d)\n", (double)cases[k].lambda,
               (double)cases[k].colour, cases[k].px, frame[o], cases[k].want);
        for (int c = 0; c < 3; c++) assert_int_equal(frame[o + c], cases[k].want);
        assert_int_equal(frame[o + 3], 255);
    }
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_matches_reference),
        cmocka_unit_test(test_nothing),
        cmocka_unit_test(test_over_frame),
        cmocka_unit_test(test_rounding_hand_values),
    };
    return cmocka_run_group_tests_name("soft_cpu", tests, NULL, NULL);
}
