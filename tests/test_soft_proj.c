/* test_soft_proj.c — the soft discs projected through the host paths (pipelines/soft_proj.c)
 * against soft_bin.comp's PASS 0 read back (rnd_pipe_opts.soft_proj_gl), both composited by the
 * host compositor, on real scans: Guanyin.ply (157k soft discs at the defaults) in every colour
 * mode the host projects (rgb, normal, depth, intensity; field stays in the GL and must come out
 * identical), a close-up the near plane cuts, and bunnyData.pts split into buffer sets of 6000
 * points (several segments, each its own mapping).
 *
 * What a conforming GL may do differently (GLSL 4.50, 4.7.1): fuse products into sums (a few
 * units in the last place of the eye and clip coordinates), divide within 2.5 ulp (the window
 * position and radius: ~1e-4 pixel at 1280 pixels), inversesqrt within 2 ulp and pow through
 * exp2 and log2 (the shaded colour: log2's 2^-21 absolute error times 32 in the specular term
 * weighted 0.1, under 1e-5 of the colour). The compositor is the same C on both sides, in float
 * with one rounding to 8 bits: a difference of ~1e-5 moves a byte only where its float value lies
 * that close to a rounding boundary, and then by one level; opacity is continuous at the rims
 * (eq. 19 is 0 there). Tolerances: every pixel within 1 level per channel, and at most 1 pixel
 * in 1000 of the covered ones different at all: the discrete decisions left, a disc's depth
 * against the solid surface's key where the two lie within the depth's few ulp of each other,
 * and a byte at a boundary, each ~1e-5 of the pixels at most. Measured values are printed. The
 * discs are not read here (they live inside the pipeline); the frames are the discs composited
 * in float with one rounding, so a disc moved or recoloured beyond the tolerance shows. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "cloud.h"
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { FW = 640, FH = 360 };

/* Two renderers with the host paths: the discs projected by the GL ([0]) and by the host ([1]). */
static rnd_ctx *pair[2];

static int setup(void **state)
{
    (void)state;
    for (int k = 0; k < 2; k++) {
        rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                      .host_paths = RND_CAP_ON, .pipe = {.soft_proj_gl = k == 0}};
        sd_err err = {0};
        if (!(pair[k] = rnd_create(&d, &err))) {
            fprintf(stderr, "rnd_create: %s\n", err.msg);
            return -1;
        }
    }
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    for (int k = 0; k < 2; k++) rnd_destroy(pair[k]), pair[k] = NULL;
    return 0;
}

/* The discs projected by the GL and by the host, cloud ids[k] on r[k], from cam with colour
 * col: the largest channel difference (*maxd), the pixels that differ (*ndiff) and the covered
 * ones (*cov); the half-float frames' differing words and the pixels the soft discs changed
 * (against lambda 0) are printed, the latter must be at least a tenth of the covered ones (the
 * discs are there to be compared). */
static void gpu_vs_cpu(rnd_ctx *const r[2], const uint32_t ids[2], const rnd_camera *cam, int col,
                       const char *what, int *maxd, int *ndiff, int *cov)
{
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.color = col;
    rnd_frame f[3] = {{0}, {0}, {0}};
    tu_render(r[0], ids[0], cam, &p, 1, &f[0]);
    tu_render(r[1], ids[1], cam, &p, 1, &f[1]);
    float lambda = p.lambda;
    p.lambda = 0.0f;
    tu_render(r[1], ids[1], cam, &p, 0, &f[2]);
    int m = 0, n = 0, c = 0, soft = 0;
    size_t halves = 0;
    for (size_t i = 0; i < (size_t)FW * FH * 4; i++) halves += f[0].rgba16f[i] != f[1].rgba16f[i];
    for (size_t i = 0; i < (size_t)FW * FH; i++)
        soft += memcmp(f[0].rgba8 + 4 * i, f[2].rgba8 + 4 * i, 3) != 0;
    for (size_t i = 0; i < (size_t)FW * FH; i++) {
        int any = 0;
        for (int k = 0; k < 3; k++) {
            int d = abs(f[0].rgba8[4 * i + k] - f[1].rgba8[4 * i + k]);
            if (d > m) m = d;
            any |= d != 0;
        }
        n += any;
        c += f[0].rgba8[4 * i] || f[0].rgba8[4 * i + 1] || f[0].rgba8[4 * i + 2];
    }
    printf("%s: host projection vs GL: max %d levels, %d of %d covered pixels differ (%zu half "
           "floats); the soft discs (lambda %.2f) changed %d pixels\n", what, m, n, c, halves,
           (double)lambda, soft);
    assert_true(soft * 10 >= c);
    *maxd = m, *ndiff = n, *cov = c;
    rnd_frame_free(&f[0]);
    rnd_frame_free(&f[1]);
    rnd_frame_free(&f[2]);
}

static void within(int m, int n, int cov, int min_cov)
{
    assert_true(cov > min_cov);
    assert_true(m <= 1);
    assert_true((double)n <= 0.001 * cov);
}

static void test_host_matches_gl(void **state)
{
    (void)state;
    tu_scans sc;
    tu_scans_load(&sc, FW, FH);
    uint32_t idg[2]; /* intensities, so that color=intensity shows */
    for (int k = 0; k < 2; k++) idg[k] = tu_upload_intensities(pair[k], &sc.g);
    static const char *const cname[5] = {"rgb", "field", "normal", "depth", "intensity"};
    int m, n, cov;
    for (int col = SP_COLOR_RGB; col <= SP_COLOR_INTENSITY; col++) {
        char what[64];
        snprintf(what, sizeof what, "Guanyin color=%s", cname[col]);
        gpu_vs_cpu(pair, idg, &sc.cg, col, what, &m, &n, &cov);
        if (col == SP_COLOR_FIELD) assert_int_equal(n, 0); /* projected by the GL either way */
        within(m, n, cov, 20000);
    }
    gpu_vs_cpu(pair, idg, &sc.close, SP_COLOR_RGB, "Guanyin close-up", &m, &n, &cov);
    within(m, n, cov, 20000);
    rnd_ctx *r6[2];
    uint32_t id6[2];
    for (int k = 0; k < 2; k++) {
        rnd_release(pair[k], idg[k]);
        rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                      .max_set_points = 6000, .host_paths = RND_CAP_ON,
                      .pipe = {.soft_proj_gl = k == 0}};
        sd_err err = {0};
        if (!(r6[k] = rnd_create(&d, &err))) fail_msg("rnd_create: %s", err.msg);
        id6[k] = tu_upload_intensities(r6[k], &sc.b);
    }
    gpu_vs_cpu(r6, id6, &sc.cb, SP_COLOR_RGB, "bunny in 6 buffer sets", &m, &n, &cov);
    within(m, n, cov, 5000);
    gpu_vs_cpu(r6, id6, &sc.cb, SP_COLOR_INTENSITY, "bunny in 6 sets, color=intensity", &m, &n,
               &cov);
    within(m, n, cov, 5000);
    for (int k = 0; k < 2; k++) rnd_release(r6[k], id6[k]), rnd_destroy(r6[k]);
    tu_scans_free(&sc);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_host_matches_gl),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
