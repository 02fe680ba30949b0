/* test_render_olt.c — the `olt` pipeline (One-Layer Transparency, the Soft Transparency paper's
 * comparison) on llvmpipe through the public renderer, against frames of `splat` of the layers
 * alone:
 *   - two soft planes one behind the other: olt shows lambda * front + (1 - lambda) * back with
 *     the back plane opaque, where `soft` (Express) blends the back plane too, so less of it
 *     shows through;
 *   - lambda = 0 shows only what lies behind the first soft layer (the back plane), and t = 1
 *     (nothing soft) gives exactly the `splat` image;
 *   - a solid plane in front of the soft layer hides it. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "cloud.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { W = 160, H = 160, NX = 70 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0};

/* A plane's worth of layers: layer j is an NX x NX grid at z[j], spacing 0.02, colour rgb[j],
 * field value F[j] (F[j] < 0: pseudo-random per point); only the layers whose bit is in mask
 * are put in the cloud. */
typedef struct layer {
    float z, F;
    uint8_t rgb[3];
} layer;

static uint32_t upload_layers_to(rnd_ctx *ctx, const layer *ls, int n, unsigned mask)
{
    int m = 0;
    for (int j = 0; j < n; j++) m += (mask >> j) & 1;
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)m * NX * NX, 0);
    const float h = 0.02f;
    uint64_t k = 0;
    for (int j = 0; j < n; j++) {
        if (!((mask >> j) & 1)) continue;
        for (int y = 0; y < NX; y++)
            for (int x = 0; x < NX; x++, k++) {
                pc.pos[3 * k] = (x - 0.5f * (NX - 1)) * h;
                pc.pos[3 * k + 1] = (y - 0.5f * (NX - 1)) * h;
                pc.pos[3 * k + 2] = ls[j].z;
                pc.radius[k] = 1.5f * h;
                memcpy(&pc.rgba[4 * k], ls[j].rgb, 3);
                /* F < 0: a pseudo-random F in [0, 1] per point (no pattern that repeats
                 * with the buffer sets' size) */
                pc.F[k] = ls[j].F >= 0 ? ls[j].F
                                       : (float)(((uint32_t)k * 2654435761u) >> 22) / 1023.0f;
            }
    }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(ctx, &pc);
    pc_prepared_free(&pc);
    return id;
}

static uint32_t upload_layers(const layer *ls, int n, unsigned mask)
{
    return upload_layers_to(tu_ctx, ls, n, mask);
}

static rnd_camera cam_z(double ez)
{
    rnd_camera c = {{OFF[0], OFF[1], ez + OFF[2]}, {OFF[0], OFF[1], OFF[2]}, {0, 1, 0},
                    40, 0.05f, 20.0f, W, H};
    return c;
}

/* The mean of channel c over the central 40 x 40 pixels (inside both planes). */
static double centre_mean(const rnd_frame *f, int c)
{
    double s = 0;
    for (int y = H / 2 - 20; y < H / 2 + 20; y++)
        for (int x = W / 2 - 20; x < W / 2 + 20; x++) s += f->rgba8[4 * ((size_t)y * W + x) + c];
    return s / 1600.0;
}

/* Two soft planes (F = 1, t = 0.5), red in front at z = 0.3, green behind at z = -0.3, seen
 * from z = 3. References: `splat` of the red plane alone (R) and of the green alone (G).
 * olt must give lambda R + (1 - lambda) G per channel, the back plane opaque; tolerance 3
 * levels on the centre means, and per pixel against those two frames' own bytes (the layer is
 * resolved to 8 bits like `splat`'s frame, then blended over what is behind): under 1.5 levels
 * from the exact value, the most a conforming GL may be off (the blend carried out at no less
 * than the target's 8 bits, GL 4.5 17.3.6.1, and its result converted to one of the two nearest
 * bytes, 2.3.5.2: under 1 level each), at lambda 0.5 on pixels whose exact value is a half (so
 * that both roundings are tried). Express composites every disc of both planes with eq. 19 opacities, so the
 * green that shows is (1 - a_red) a_green G with both a < 1: at lambda = 0.1 it must be at
 * least 20 levels below olt's (1 - lambda) G. lambda = 0 shows the green plane alone (olt's
 * "everything behind the first layer", tolerance 1 level) and t = 1 is `splat` of both
 * (tolerance 0). */
static void test_two_soft_layers(void **state)
{
    (void)state;
    const layer ls[2] = {{0.3f, 1.0f, {255, 0, 0}}, {-0.3f, 1.0f, {0, 255, 0}}};
    uint32_t both = upload_layers(ls, 2, 3), red = upload_layers(ls, 2, 1),
             green = upload_layers(ls, 2, 2);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame fr = {0}, fg = {0}, fb = {0};
    tu_render(tu_ctx, red, &cam, &p, 0, &fr);
    tu_render(tu_ctx, green, &cam, &p, 0, &fg);
    tu_render(tu_ctx, both, &cam, &p, 0, &fb);
    double R = centre_mean(&fr, 0), G = centre_mean(&fg, 1);
    assert_true(R > 100 && G > 100);
    const float lambdas[3] = {0.1f, 0.5f, 0.0f};
    for (int i = 0; i < 3; i++) {
        p.t = 0.5f, p.lambda = lambdas[i];
        rnd_frame fo = {0}, fe = {0};
        p.pipeline = SP_PIPE_OLT;
        tu_render(tu_ctx, both, &cam, &p, 0, &fo);
        p.pipeline = SP_PIPE_SOFT;
        tu_render(tu_ctx, both, &cam, &p, 0, &fe);
        double or_ = centre_mean(&fo, 0), og = centre_mean(&fo, 1);
        double er = centre_mean(&fe, 0), eg = centre_mean(&fe, 1);
        double wr = p.lambda * R, wg = (1 - p.lambda) * G;
        /* pixel by pixel: v = lambda layer + (1 - lambda) behind, the two 8-bit frames' bytes */
        double worst = 0;
        int halves = 0;
        for (int y = H / 2 - 20; y < H / 2 + 20; y++)
            for (int x = W / 2 - 20; x < W / 2 + 20; x++)
                for (int c = 0; c < 3; c++) {
                    size_t o = 4 * ((size_t)y * W + x) + c;
                    double v = p.lambda * fr.rgba8[o] + (1.0 - p.lambda) * fg.rgba8[o];
                    worst = fmax(worst, fabs(fo.rgba8[o] - v));
                    halves += fabs(v - floor(v) - 0.5) < 1e-6;
                }
        printf("lambda %.1f: olt (%.1f, %.1f), want (%.1f, %.1f); express (%.1f, %.1f); per "
               "channel within %.2f of lambda layer + (1 - lambda) behind (%d exact halves)\n",
               p.lambda, or_, og, wr, wg, er, eg, worst, halves);
        assert_true(fabs(or_ - wr) <= 3.0 && fabs(og - wg) <= 3.0);
        assert_true(worst < 1.5);
        if (i == 1) assert_true(halves > 100);
        if (i == 0) assert_true(eg <= og - 20.0);
        rnd_frame_free(&fo), rnd_frame_free(&fe);
    }
    p.pipeline = SP_PIPE_OLT, p.t = 1.0f, p.lambda = 0.5f;
    rnd_frame f1 = {0};
    tu_render(tu_ctx, both, &cam, &p, 0, &f1);
    assert_memory_equal(f1.rgba8, fb.rgba8, (size_t)W * H * 4);
    rnd_frame_free(&f1);
    rnd_frame_free(&fr), rnd_frame_free(&fg), rnd_frame_free(&fb);
    rnd_release(tu_ctx, both), rnd_release(tu_ctx, red), rnd_release(tu_ctx, green);
}

/* A solid blue plane (F = 0) at z = 0.6 in front of the soft red plane at z = 0.3 and the green
 * at z = -0.3: the frame equals `splat` of the blue plane where the blue plane covers (its
 * centre; tolerance 1 level: only the soft layer's pass is added, and it is discarded there). */
static void test_solid_in_front(void **state)
{
    (void)state;
    const layer ls[3] = {{0.6f, 0.0f, {0, 0, 255}}, {0.3f, 1.0f, {255, 0, 0}},
                         {-0.3f, 1.0f, {0, 255, 0}}};
    uint32_t all = upload_layers(ls, 3, 7), blue = upload_layers(ls, 3, 1);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame fb = {0}, fo = {0};
    tu_render(tu_ctx, blue, &cam, &p, 0, &fb);
    p.pipeline = SP_PIPE_OLT, p.t = 0.5f, p.lambda = 0.5f;
    tu_render(tu_ctx, all, &cam, &p, 0, &fo);
    for (int c = 0; c < 3; c++) {
        double a = centre_mean(&fb, c), b = centre_mean(&fo, c);
        printf("solid in front, channel %d: splat of the plane %.2f, olt %.2f\n", c, a, b);
        assert_true(fabs(a - b) <= 1.0);
    }
    rnd_frame_free(&fb), rnd_frame_free(&fo);
    rnd_release(tu_ctx, all), rnd_release(tu_ctx, blue);
}

/* A cloud in several buffer sets (rnd_desc.max_set_points = 2000: the two planes' 9800 points
 * in 5 sets, as a LOD cloud's node pool or a cloud over GL_MAX_TEXTURE_BUFFER_SIZE / 3 points
 * is): each set's field buffer is bound as splat's passes make the set current, so the frame
 * equals the one-set frame. Tolerance: 1 level in any pixel (the same splats; float sums added
 * set by set instead of in one dispatch). With set 0's field buffer read for every set, the
 * points of the other sets take set 0's F values, and which red points are soft changes. */
static void test_buffer_sets(void **state)
{
    (void)state;
    rnd_desc dd = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                   .max_set_points = 2000};
    sd_err err = {0};
    rnd_ctx *r5 = rnd_create(&dd, &err);
    if (!r5) fail_msg("rnd_create: %s", err.msg);
    /* a red plane of pseudo-random F (about half of it soft at t = 0.5: each point's F, from
     * its set's field buffer, decides) over a soft green plane */
    const layer ls[2] = {{0.3f, -1.0f, {255, 0, 0}}, {-0.3f, 1.0f, {0, 255, 0}}};
    uint32_t id1 = upload_layers(ls, 2, 3), id5 = upload_layers_to(r5, ls, 2, 3);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_OLT, p.t = 0.5f;
    const float lambdas[2] = {0.3f, 0.0f};
    for (int l = 0; l < 2; l++) {
        p.lambda = lambdas[l];
        rnd_frame a = {0}, b = {0};
        tu_render(tu_ctx, id1, &cam, &p, 0, &a);
        tu_render(r5, id5, &cam, &p, 0, &b);
        int m = 0, n = 0;
        for (size_t i = 0; i < (size_t)W * H * 4; i++) {
            int dv = abs((int)a.rgba8[i] - (int)b.rgba8[i]);
            if (dv > m) m = dv;
            n += dv > 0;
        }
        printf("olt, 5 buffer sets, lambda %.1f: max difference to one set %d levels (%d "
               "channel values)\n", p.lambda, m, n);
        assert_true(m <= 1);
        rnd_frame_free(&a);
        rnd_frame_free(&b);
    }
    rnd_release(tu_ctx, id1);
    rnd_release(r5, id5);
    rnd_destroy(r5);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_two_soft_layers),
        cmocka_unit_test(test_solid_in_front),
        cmocka_unit_test(test_buffer_sets),
    };
    return cmocka_run_group_tests(tests, tu_egl_group_setup, tu_egl_group_teardown);
}
