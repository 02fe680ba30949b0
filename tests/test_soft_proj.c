/* test_soft_proj.c — the soft discs projected on the host (soft_proj=cpu, pipelines/soft_proj.c)
 * against soft_bin.comp's PASS 0 read back (soft_proj=gpu), both composited by order=cpu on
 * llvmpipe, on real scans: Guanyin.ply (157k soft discs at the defaults) in every colour mode
 * the host projects (rgb, normal, depth, intensity; field stays in the GL and must come out
 * identical), a close-up the near plane cuts, and bunnyData.pts split into buffer sets of 6000
 * points (several segments, each its own mapping).
 *
 * The host repeats the shader's float operations in its order, but llvmpipe may fuse products
 * into sums and has its own inversesqrt and pow, so a disc's centre may move by a few units in
 * the last place (~1e-4 pixel at 1280 pixels) and its shaded colour by ~1e-6. A pixel whose
 * centre lies that close to a disc's rim can gain or lose that disc, and a colour can round the
 * other way to 8 bits. Tolerances: every pixel within 1 level per channel of the GL's, and at
 * most 1 pixel in 1000 of the covered ones different at all; measured values are printed. The
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

/* soft_proj=gpu and =cpu of cloud id from cam with colour col: the largest channel difference
 * (*maxd), the pixels that differ (*ndiff) and the covered ones (*cov); the half-float frames'
 * differing words and the pixels the soft discs changed (against lambda 0) are printed, the
 * latter must be at least a tenth of the covered ones (the discs are there to be compared). */
static void gpu_vs_cpu(rnd_ctx *r, uint32_t id, const rnd_camera *cam, int col, const char *what,
                       int *maxd, int *ndiff, int *cov)
{
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.order = SP_ORDER_CPU, p.color = col;
    rnd_frame f[3] = {{0}, {0}, {0}};
    p.soft_proj = SP_SOFT_PROJ_GPU;
    tu_render(r, id, cam, &p, 1, &f[0]);
    p.soft_proj = SP_SOFT_PROJ_CPU;
    tu_render(r, id, cam, &p, 1, &f[1]);
    float lambda = p.lambda;
    p.lambda = 0.0f;
    tu_render(r, id, cam, &p, 0, &f[2]);
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
    printf("%s: soft_proj cpu vs gpu: max %d levels, %d of %d covered pixels differ (%zu half "
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
    uint32_t idg = tu_upload_intensities(tu_ctx, &sc.g); /* so that color=intensity shows */
    static const char *const cname[5] = {"rgb", "field", "normal", "depth", "intensity"};
    int m, n, cov;
    for (int col = SP_COLOR_RGB; col <= SP_COLOR_INTENSITY; col++) {
        char what[64];
        snprintf(what, sizeof what, "Guanyin color=%s", cname[col]);
        gpu_vs_cpu(tu_ctx, idg, &sc.cg, col, what, &m, &n, &cov);
        if (col == SP_COLOR_FIELD) assert_int_equal(n, 0); /* projected by the GL either way */
        within(m, n, cov, 20000);
    }
    gpu_vs_cpu(tu_ctx, idg, &sc.close, SP_COLOR_RGB, "Guanyin close-up", &m, &n, &cov);
    within(m, n, cov, 20000);
    rnd_release(tu_ctx, idg);
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                  .max_set_points = 6000};
    sd_err err = {0};
    rnd_ctx *r6 = rnd_create(&d, &err);
    if (!r6) fail_msg("rnd_create: %s", err.msg);
    uint32_t id6 = tu_upload_intensities(r6, &sc.b);
    gpu_vs_cpu(r6, id6, &sc.cb, SP_COLOR_RGB, "bunny in 6 buffer sets", &m, &n, &cov);
    within(m, n, cov, 5000);
    gpu_vs_cpu(r6, id6, &sc.cb, SP_COLOR_INTENSITY, "bunny in 6 sets, color=intensity", &m, &n,
               &cov);
    within(m, n, cov, 5000);
    rnd_release(r6, id6);
    rnd_destroy(r6);
    tu_scans_free(&sc);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_host_matches_gl),
    };
    return cmocka_run_group_tests(tests, tu_egl_group_setup, tu_egl_group_teardown);
}
