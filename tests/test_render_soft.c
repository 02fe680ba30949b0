/* test_render_soft.c — the `soft` pipeline (Soft Transparency, Express-Model) on llvmpipe
 * through the public renderer (render.h), against analytic expectations:
 *   - t = 1 (nothing soft) gives exactly the `splat` image;
 *   - lambda = 0 makes the soft points invisible: the image equals `splat` of the solid points;
 *   - one soft disc facing the camera has eq. 19's opacity at every pixel of its footprint;
 *   - two soft discs of known colours composite as premultiplied "over", front over back, from
 *     both view directions, and soft discs behind a solid surface are hidden by it;
 *   - transparency modulation (eq. 22): the colour step at the solid/soft boundary of a plane
 *     whose F ramps across t is at least 2x smaller with l_m than without;
 *   - field=height on a real scan: lambda = 0 equals `splat` of the points at most half way up,
 *     and t, lambda and field change between frames of one upload.
 * Each check states its tolerance. Timings are in `make bench` (render_bench --pipelines
 * points,splat,soft), not here. */
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
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { W = 192, H = 192 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0}; /* a UTM-like offset */

/* A camera at local (0, 0, ez) looking at the local origin, up +y, fov 40, explicit clip
 * distances (so that clouds with other bounds get the same projection). */
static rnd_camera cam_z(double ez)
{
    rnd_camera c = {{OFF[0], OFF[1], ez + OFF[2]}, {OFF[0], OFF[1], OFF[2]}, {0, 1, 0},
                    40, 0.05f, 20.0f, W, H};
    return c;
}

/* The screen radius in pixels of a face-on disc of radius r at eye depth z (fov 40, H rows). */
static double disc_px(double r, double z)
{
    return r / tan(20.0 * M_PI / 180.0) * 0.5 * H / z;
}

static const uint8_t *pix(const rnd_frame *f, int x, int y)
{
    return f->rgba8 + 4 * ((size_t)y * f->width + x);
}

/* max_diff: the largest channel difference (RGB) between two frames, and *ndiff the pixels
 * that differ at all. */
static int max_diff(const rnd_frame *a, const rnd_frame *b, int *ndiff)
{
    int m = 0, n = 0;
    for (size_t i = 0; i < (size_t)a->width * a->height; i++) {
        int any = 0;
        for (int c = 0; c < 3; c++) {
            int d = abs(a->rgba8[4 * i + c] - b->rgba8[4 * i + c]);
            if (d > m) m = d;
            any |= d != 0;
        }
        n += any;
    }
    if (ndiff) *ndiff = n;
    return m;
}

static uint64_t rng_next(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s >> 33;
}

static float rng01(uint64_t *s)
{
    return (float)rng_next(s) / (float)(1u << 31);
}

/* A plane of nx x ny points z = 0, spacing h, radius 1.5 h, random colours and F (seeded). */
static void random_plane(pc_prepared *pc, int nx, int ny, float h, uint64_t seed)
{
    tu_new_cloud(pc, (uint64_t)nx * ny, 0);
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            uint64_t k = (uint64_t)j * nx + i;
            pc->pos[3 * k] = (i - 0.5f * (nx - 1)) * h;
            pc->pos[3 * k + 1] = (j - 0.5f * (ny - 1)) * h;
            pc->pos[3 * k + 2] = 0.0f;
            pc->radius[k] = 1.5f * h;
            for (int c = 0; c < 3; c++) pc->rgba[4 * k + c] = (uint8_t)(rng_next(&seed) & 255);
            pc->F[k] = rng01(&seed);
        }
}

/* The group's renderer: EGL with the host paths on whatever the back end, so that order=auto is
 * the host compositor here on a GPU too (tu_ctx, freed by tu_egl_group_teardown). */
static int setup_host(void **state)
{
    (void)state;
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                  .host_paths = RND_CAP_ON};
    sd_err err = {0};
    tu_ctx = rnd_create(&d, &err);
    if (!tu_ctx) fprintf(stderr, "rnd_create: %s\n", err.msg);
    return tu_ctx ? 0 : -1;
}

/* ---- tests ---- */

/* t = 1: every F in [0, 1] is solid, so soft runs exactly the splat passes over exactly the
 * frame's chunks: the images must be identical (tolerance 0), whatever lambda and l_m are. */
static void test_t1_equals_splat(void **state)
{
    (void)state;
    pc_prepared pc;
    random_plane(&pc, 90, 90, 0.02f, 1);
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(3.0);
    cam.eye[0] += 0.7; /* an oblique view */
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame a = {0}, b = {0};
    tu_render(tu_ctx, id, &cam, &p, 0, &a);
    const float lambdas[2] = {0.5f, 1.0f};
    for (int i = 0; i < 2; i++) {
        p.pipeline = SP_PIPE_SOFT, p.t = 1.0f, p.lambda = lambdas[i], p.l_m = 1.0f;
        tu_render(tu_ctx, id, &cam, &p, 0, &b);
        int n, m = max_diff(&a, &b, &n);
        printf("t = 1, lambda %.1f: max difference to splat %d (%d pixels)\n", lambdas[i], m, n);
        assert_int_equal(m, 0);
        rnd_frame_free(&b);
    }
    rnd_frame_free(&a);
    rnd_release(tu_ctx, id);
}

/* lambda = 0 (and no modulation): the soft points are invisible, and the solid ones are drawn
 * by the splat passes as a cloud of only them would be. The soft points (random F > t) are
 * lifted 0.1 in front of the solid ones' plane, so that they would show if drawn. The reference is `splat` of a second
 * cloud holding just the solid points, in the same order, with the same offset and clip
 * distances. Tolerance: at most 1 level in at most 0.5 % of the pixels — the splat passes read
 * the same points but the weight sums are float atomics whose order can differ between the
 * two dispatches; measured 0. The same frame with lambda = 0.5 must differ (the soft points
 * are there) in at least 5 % of the pixels. */
static void test_lambda0_is_solid_splat(void **state)
{
    (void)state;
    enum { NX = 90 };
    pc_prepared pc, solid;
    random_plane(&pc, NX, NX, 0.02f, 2);
    const float t = 0.6f;
    uint64_t m = 0;
    for (uint64_t i = 0; i < pc.n; i++) {
        m += pc.F[i] <= t;
        if (pc.F[i] > t) pc.pos[3 * i + 2] = 0.1f; /* soft points in front of the solid ones */
    }
    tu_new_cloud(&solid, m, 0);
    for (uint64_t i = 0, j = 0; i < pc.n; i++) {
        if (pc.F[i] > t) continue;
        memcpy(&solid.pos[3 * j], &pc.pos[3 * i], 12);
        memcpy(&solid.normal[3 * j], &pc.normal[3 * i], 12);
        memcpy(&solid.rgba[4 * j], &pc.rgba[4 * i], 4);
        solid.radius[j] = pc.radius[i], solid.F[j] = pc.F[i];
        j++;
    }
    tu_finish_cloud(&pc, OFF);
    tu_finish_cloud(&solid, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc), sid = tu_upload(tu_ctx, &solid);
    printf("lambda = 0: %llu solid of %llu points\n", (unsigned long long)m,
           (unsigned long long)pc.n);
    pc_prepared_free(&pc);
    pc_prepared_free(&solid);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame ref = {0}, f = {0};
    tu_render(tu_ctx, sid, &cam, &p, 0, &ref);
    p.pipeline = SP_PIPE_SOFT, p.t = t, p.lambda = 0.0f;
    tu_render(tu_ctx, id, &cam, &p, 0, &f);
    int n, md = max_diff(&ref, &f, &n);
    printf("lambda = 0: max difference to splat of the solid points %d (%d pixels)\n", md, n);
    assert_true(md <= 1);
    assert_true(n <= W * H / 200);
    rnd_frame_free(&f);
    p.lambda = 0.5f;
    tu_render(tu_ctx, id, &cam, &p, 0, &f);
    md = max_diff(&ref, &f, &n);
    printf("lambda = 0.5: %d pixels differ from splat of the solid points\n", n);
    assert_true(n >= W * H / 20);
    rnd_frame_free(&f);
    rnd_frame_free(&ref);
    rnd_release(tu_ctx, id);
    rnd_release(tu_ctx, sid);
}

/* One cloud of soft single points (F = 1, t = 0.5): (x, y, z, radius, rgb). */
typedef struct disc {
    float x, y, z, r;
    uint8_t rgb[3];
    float F;
} disc;

static uint32_t upload_discs(const disc *d, int n)
{
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)n, 1);
    for (int i = 0; i < n; i++) {
        pc.pos[3 * i] = d[i].x, pc.pos[3 * i + 1] = d[i].y, pc.pos[3 * i + 2] = d[i].z;
        pc.radius[i] = d[i].r;
        memcpy(&pc.rgba[4 * i], d[i].rgb, 3);
        pc.F[i] = d[i].F;
    }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    return id;
}

/* Eq. 19 at normalised distance d. */
static double phi19(double lambda, double d)
{
    return d < 1.0 ? lambda * (cos(M_PI * d) + 1.0) / 2.0 : 0.0;
}

/* A white soft disc facing the camera on black: each pixel's colour is the composited alpha,
 * which must be eq. 19 at the pixel centre's distance from the disc's centre. Tolerance: 1 level
 * of 8 bits (the blend's result is rounded to RGBA8 once), over every pixel whose distance is
 * under 0.97 r (the rim, where the sprite's cut-off and the analytic radius may disagree by a
 * fraction of a pixel, is left out); the centre pixel and the pixels nearest d = r / 2 are
 * reported. */
/* The three ways of compositing the Express-Model's discs (the analytic tests run each): on the
 * group's renderer, which has the host paths (setup below), order=auto is the host compositor. */
static const int orders[3] = {SP_ORDER_AXIS, SP_ORDER_TILE, SP_ORDER_AUTO};
static const char *const onames[3] = {"axis", "tile", "auto (the host compositor)"};

static void test_disc_opacity_eq19(void **state)
{
    (void)state;
    const disc d[1] = {{0, 0, 0, 0.5f, {255, 255, 255}, 1.0f}};
    uint32_t id = upload_discs(d, 1);
    rnd_camera cam = cam_z(4.0);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.5f, p.lambda = 0.7f;
    /* the light along the view axis: the shading of the disc (its normal faces the camera) is
     * exactly 1, so the colour is eq. 19's opacity alone */
    p.light[0] = 0.0f, p.light[1] = 0.0f, p.light[2] = 1.0f;
    for (int oi = 0; oi < 3; oi++) {
    p.order = orders[oi];
    rnd_frame f = {0};
    tu_render(tu_ctx, id, &cam, &p, 0, &f);
    double rpx = disc_px(0.5, 4.0), cx = 0.5 * W, cy = 0.5 * H;
    int worst = 0, nin = 0;
    double at_half = -1, best_half = 1e9;
    int half_px = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double dn = hypot(x + 0.5 - cx, y + 0.5 - cy) / rpx;
            int got = pix(&f, x, y)[0];
            if (dn >= 0.97 && dn <= 1.03) continue;
            int want = (int)lround(255.0 * phi19(p.lambda, dn));
            int e = abs(got - want);
            if (e > worst) worst = e;
            nin += dn < 1.0;
            if (fabs(dn - 0.5) < best_half) best_half = fabs(dn - 0.5), at_half = dn, half_px = got;
        }
    int c0 = pix(&f, W / 2, H / 2)[0];
    double dc = hypot(0.5, 0.5) / rpx;
    printf("soft disc, order=%s: %.1f px radius, %d pixels inside; centre pixel %d (eq. 19: "
           "%.2f), at d = %.3f r %d (eq. 19: %.2f); largest error %d levels\n",
           onames[oi], rpx, nin, c0, 255.0 * phi19(p.lambda, dc), at_half, half_px,
           255.0 * phi19(p.lambda, at_half), worst);
    assert_true(nin > 1000);
    assert_true(worst <= 1);
    rnd_frame_free(&f);
    }
    rnd_release(tu_ctx, id);
}

/* Two soft discs on the z axis, red at z = +0.3 and green at z = -0.3, both larger than the
 * frame's centre region, seen from +z and from -z. At a pixel the front one's alpha aF and the
 * back one's aB (eq. 19, known from the pixel's distance), the premultiplied "over" gives
 * front colour aF cF + (1 - aF) aB cB. Tolerance: 2 levels (each of the two blends rounds to 8
 * bits once). The wrong order would put aB in the back colour's channel and (1 - aB) aF in the
 * front one's: with the alphas used here that is off by more than 40 levels. Also: a soft
 * disc behind a solid plane (F = 0) is hidden where the plane is (that pixel equals the frame
 * with lambda = 0, the plane alone, tolerance 0), and one in front of it blends over the plane's
 * colour (tolerance 2 levels, as above). */
static void test_two_layers_order(void **state)
{
    (void)state;
    const disc d[2] = {{0, 0, 0.3f, 0.6f, {255, 0, 0}, 1.0f}, {0, 0, -0.3f, 0.6f, {0, 255, 0}, 1.0f}};
    uint32_t id = upload_discs(d, 2);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.5f, p.lambda = 0.8f;
    p.light[0] = 0.0f, p.light[1] = 0.0f, p.light[2] = 1.0f; /* shading 1 (test_disc_opacity_eq19) */
    for (int side = 0; side < 6; side++) {
        p.order = orders[side / 2]; /* axis, tile, then cpu */
        double ez = side % 2 == 0 ? 4.0 : -4.0;
        rnd_camera cam = cam_z(ez);
        rnd_frame f = {0};
        tu_render(tu_ctx, id, &cam, &p, 0, &f);
        int worst = 0, wrong_min = 255;
        const int xs[3] = {W / 2, W / 2 + 10, W / 2 + 20};
        for (int q = 0; q < 3; q++) {
            int x = xs[q], y = H / 2;
            double off = hypot(x + 0.5 - 0.5 * W, y + 0.5 - 0.5 * H);
            double zr = fabs(ez - 0.3), zg = fabs(ez + 0.3);
            double ar = phi19(p.lambda, off / disc_px(0.6, zr));
            double ag = phi19(p.lambda, off / disc_px(0.6, zg));
            double r, g, rw, gw; /* right and wrong order */
            if (side % 2 == 0) r = ar, g = (1 - ar) * ag, rw = (1 - ag) * ar, gw = ag;
            else g = ag, r = (1 - ag) * ar, gw = (1 - ar) * ag, rw = ar;
            const uint8_t *px = pix(&f, x, y);
            int er = abs(px[0] - (int)lround(255 * r)), eg = abs(px[1] - (int)lround(255 * g));
            worst = er > worst ? er : worst;
            worst = eg > worst ? eg : worst;
            int wr = abs((int)lround(255 * rw) - (int)lround(255 * r)) +
                     abs((int)lround(255 * gw) - (int)lround(255 * g));
            if (wr < wrong_min) wrong_min = wr;
            printf("two layers, order=%s, from %s z, pixel (%d, %d): got (%d, %d), over gives "
                   "(%.1f, %.1f), the other order (%.1f, %.1f)\n", onames[side / 2],
                   side % 2 == 0 ? "+" : "-", x, y, px[0], px[1],
                   255 * r, 255 * g, 255 * rw, 255 * gw);
        }
        assert_true(worst <= 2);
        assert_true(wrong_min > 40); /* the check can tell the two orders apart */
        rnd_frame_free(&f);
    }
    rnd_release(tu_ctx, id);
    p.order = SP_ORDER_AXIS;

    /* A solid plane at z = 0 (blue, F = 0) over x < 0.6, a soft red disc behind it at x = 0.2
     * and a soft green disc in front of it at x = -0.2 (both off the plane's right edge by
     * design of their radius), seen from +z. */
    enum { NX = 80 };
    pc_prepared pc;
    tu_new_cloud(&pc, NX * NX + 2, 0);
    const float h = 0.02f;
    for (int j = 0; j < NX; j++)
        for (int i = 0; i < NX; i++) {
            uint64_t k = (uint64_t)j * NX + i;
            pc.pos[3 * k] = (i - 0.5f * (NX - 1)) * h;
            pc.pos[3 * k + 1] = (j - 0.5f * (NX - 1)) * h;
            pc.radius[k] = 1.5f * h;
            pc.rgba[4 * k] = 0, pc.rgba[4 * k + 1] = 0, pc.rgba[4 * k + 2] = 255;
            pc.F[k] = 0.0f;
        }
    const float sx[2] = {0.4f, -0.4f}, sz[2] = {-0.3f, 0.3f};
    for (int s = 0; s < 2; s++) {
        uint64_t k = NX * NX + (uint64_t)s;
        pc.pos[3 * k] = sx[s], pc.pos[3 * k + 1] = 0, pc.pos[3 * k + 2] = sz[s];
        pc.radius[k] = 0.15f;
        pc.rgba[4 * k] = s == 0 ? 255 : 0, pc.rgba[4 * k + 1] = s == 1 ? 255 : 0;
        pc.rgba[4 * k + 2] = 0;
        pc.F[k] = 1.0f;
    }
    tu_finish_cloud(&pc, OFF);
    uint32_t pid = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(3.0);
    rnd_frame fs = {0}, ft = {0};
    sp_params ps = p;
    ps.lambda = 0.0f; /* the plane alone */
    tu_render(tu_ctx, pid, &cam, &ps, 0, &fs);
    tu_render(tu_ctx, pid, &cam, &p, 0, &ft);
    /* The disc centres' pixels. */
    double f1 = 1.0 / tan(20.0 * M_PI / 180.0);
    int bx = (int)floor((0.4 * f1 / 3.3 + 1) * 0.5 * W), gx = (int)floor((-0.4 * f1 / 2.7 + 1) * 0.5 * W);
    const uint8_t *behind_s = pix(&fs, bx, H / 2), *behind_t = pix(&ft, bx, H / 2);
    const uint8_t *front_s = pix(&fs, gx, H / 2), *front_t = pix(&ft, gx, H / 2);
    double ag = phi19(p.lambda, hypot(gx + 0.5 - (-0.4 * f1 / 2.7 + 1) * 0.5 * W, 0.5) /
                                    disc_px(0.15, 2.7));
    printf("behind the solid plane: lambda 0 (%d, %d, %d), 0.8 (%d, %d, %d); in front: lambda 0 (%d, "
           "%d, %d), soft (%d, %d, %d), over gives green %.1f, blue %.1f\n", behind_s[0],
           behind_s[1], behind_s[2], behind_t[0], behind_t[1], behind_t[2], front_s[0],
           front_s[1], front_s[2], front_t[0], front_t[1], front_t[2], 255 * ag,
           (1 - ag) * front_s[2]);
    assert_true(behind_s[2] > 100); /* the plane is there */
    assert_memory_equal(behind_s, behind_t, 3);
    assert_true(abs(front_t[1] - (int)lround(255 * ag)) <= 2);
    assert_true(abs(front_t[2] - (int)lround((1 - ag) * front_s[2])) <= 2);
    rnd_frame_free(&fs);
    rnd_frame_free(&ft);
    rnd_release(tu_ctx, pid);
}

/* Modulation (eq. 22): a dense white plane whose F ramps linearly from 0 at the left edge to 1
 * at the right, t = 0.4, lambda = 0.3. Along the middle row, the largest colour step between
 * neighbouring pixels over the inner part of the plane (away from its edges) is measured
 * without modulation (l_m = 0) and with l_m = 0.8; the second must be at most half the first
 * (the criterion). The steps are also required to be real: at least 20 levels without
 * modulation. */
static void test_modulation(void **state)
{
    (void)state;
    enum { NX = 160, NY = 40 };
    pc_prepared pc;
    tu_new_cloud(&pc, NX * NY, 0);
    const float h = 0.01f;
    for (int j = 0; j < NY; j++)
        for (int i = 0; i < NX; i++) {
            uint64_t k = (uint64_t)j * NX + i;
            pc.pos[3 * k] = (i - 0.5f * (NX - 1)) * h;
            pc.pos[3 * k + 1] = (j - 0.5f * (NY - 1)) * h;
            pc.radius[k] = 1.5f * h;
            pc.F[k] = (float)i / (NX - 1);
        }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(2.2);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.4f, p.lambda = 0.3f;
    double half_w = 0.5 * (NX - 1) * h * (1.0 / tan(20.0 * M_PI / 180.0)) / 2.2 * 0.5 * H;
    int x0 = (int)ceil(0.5 * W - half_w) + 6, x1 = (int)floor(0.5 * W + half_w) - 6;
    int steps[2];
    const float lms[2] = {0.0f, 0.8f};
    for (int m = 0; m < 2; m++) {
        p.l_m = lms[m];
        rnd_frame f = {0};
        tu_render(tu_ctx, id, &cam, &p, 0, &f);
        int worst = 0, wx = 0;
        for (int x = x0; x < x1; x++) {
            int s = 0;
            for (int c = 0; c < 3; c++) {
                int dd = abs(pix(&f, x + 1, H / 2)[c] - pix(&f, x, H / 2)[c]);
                if (dd > s) s = dd;
            }
            if (s > worst) worst = s, wx = x;
        }
        steps[m] = worst;
        printf("modulation l_m = %.1f: largest step %d levels at x = %d (plane x %d..%d; "
               "left %d, right %d)\n", lms[m], worst, wx, x0, x1, pix(&f, x0, H / 2)[0],
               pix(&f, x1, H / 2)[0]);
        rnd_frame_free(&f);
    }
    assert_true(steps[0] >= 20);
    assert_true(2 * steps[1] <= steps[0]);
    rnd_release(tu_ctx, id);
}

/* field=height on a real scan (bun000.ply, prepared here): F = (z - zmin) / (zmax - zmin). With
 * lambda = 0 and t = 0.8 the frame equals `splat` of a cloud of the points with F <= t (same order, offset,
 * camera and clip distances; tolerance as test_lambda0_is_solid_splat: at most 1 level in at
 * most 0.5 % of the pixels). Then, on the same upload, lambda = 0.5 changes the frame, and
 * field=uncertainty gives a different frame again (t, lambda and field are live). */
static void test_field_height(void **state)
{
    (void)state;
    pc_prepared pc;
    tu_prep_data("bun000.ply", &pc);
    const float t = 0.8f; /* the scan's points are mostly near the far end of its z range */
    float zmin = INFINITY, zmax = -INFINITY;
    for (uint64_t i = 0; i < pc.n; i++)
        zmin = fminf(zmin, pc.pos[3 * i + 2]), zmax = fmaxf(zmax, pc.pos[3 * i + 2]);
    uint64_t m = 0;
    for (uint64_t i = 0; i < pc.n; i++) m += (pc.pos[3 * i + 2] - zmin) / (zmax - zmin) <= t;
    pc_prepared solid;
    tu_new_cloud(&solid, m, 0);
    for (uint64_t i = 0, j = 0; i < pc.n; i++) {
        if (!((pc.pos[3 * i + 2] - zmin) / (zmax - zmin) <= t)) continue;
        memcpy(&solid.pos[3 * j], &pc.pos[3 * i], 12);
        memcpy(&solid.normal[3 * j], &pc.normal[3 * i], 12);
        if (pc.rgba) memcpy(&solid.rgba[4 * j], &pc.rgba[4 * i], 4);
        solid.radius[j] = pc.radius[i], solid.F[j] = pc.F[i];
        j++;
    }
    tu_finish_cloud(&solid, pc.offset);
    rnd_camera cam;
    tu_camera_box(pc.bmin, pc.bmax, 256, 256, &cam);
    cam.znear = 0.01f, cam.zfar = 10.0f;
    printf("bun000: %llu points, %llu with F <= t = 0.8 in z\n", (unsigned long long)pc.n,
           (unsigned long long)m);
    assert_true(m > pc.n / 10 && m < pc.n - pc.n / 10);
    uint32_t id = tu_upload(tu_ctx, &pc), sid = tu_upload(tu_ctx, &solid);
    pc_prepared_free(&pc);
    pc_prepared_free(&solid);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame ref = {0}, f0 = {0}, f1 = {0}, f2 = {0};
    tu_render(tu_ctx, sid, &cam, &p, 0, &ref);
    p.pipeline = SP_PIPE_SOFT, p.field = SP_FIELD_HEIGHT, p.t = t, p.lambda = 0.0f;
    tu_render(tu_ctx, id, &cam, &p, 0, &f0);
    int n0, m0 = max_diff(&ref, &f0, &n0);
    p.lambda = 0.5f;
    tu_render(tu_ctx, id, &cam, &p, 0, &f1);
    int n1;
    max_diff(&f0, &f1, &n1);
    p.field = SP_FIELD_UNCERTAINTY;
    tu_render(tu_ctx, id, &cam, &p, 0, &f2);
    int n2;
    max_diff(&f1, &f2, &n2);
    printf("field=height: lambda 0 vs splat of the solid points: max %d (%d pixels); lambda 0.5 "
           "changes %d pixels; field=uncertainty then changes %d\n", m0, n0, n1, n2);
    assert_true(m0 <= 1 && n0 <= 256 * 256 / 200);
    assert_true(n1 > 500);
    assert_true(n2 > 500);
    rnd_frame_free(&ref), rnd_frame_free(&f0), rnd_frame_free(&f1), rnd_frame_free(&f2);
    rnd_release(tu_ctx, id);
    rnd_release(tu_ctx, sid);
}

/* A random plane whose soft points (F > 0.4) are lifted in front by 0.05 + 0.1 F: several soft
 * layers per pixel (test_tile_matches_axis, test_cpu_bands). Returns the uploaded cloud. */
static void layered_plane(pc_prepared *pc)
{
    random_plane(pc, 90, 90, 0.02f, 3);
    for (uint64_t i = 0; i < pc->n; i++)
        if (pc->F[i] > 0.4f) pc->pos[3 * i + 2] = 0.05f + 0.1f * pc->F[i];
    tu_finish_cloud(pc, OFF);
}

static uint32_t upload_layered_plane_to(rnd_ctx *r)
{
    pc_prepared pc;
    layered_plane(&pc);
    uint32_t id = tu_upload(r, &pc);
    pc_prepared_free(&pc);
    return id;
}

/* disc_layers: per pixel of cam's frame (W x H), the soft discs (F > t) of pc whose footprint
 * holds the pixel's centre, one pixel more of radius for the sprites' rasterisation (computed
 * in double from the renderer's own view: rnd__view_setup). */
static void disc_layers(const pc_prepared *pc, float t, const rnd_camera *cam, int *count)
{
    rnd_view v;
    sd_err err = {0};
    float lo[3], hi[3];
    for (int a = 0; a < 3; a++)
        lo[a] = (float)(pc->bmin[a] - pc->offset[a]), hi[a] = (float)(pc->bmax[a] - pc->offset[a]);
    if (rnd__view_setup(cam, pc->offset, lo, hi, &v, &err) != 0) fail_msg("%s", err.msg);
    memset(count, 0, sizeof(int) * W * H);
    const float *m = v.viewproj;
    for (uint64_t i = 0; i < pc->n; i++) {
        if (!(pc->F[i] > t)) continue;
        const float *q = pc->pos + 3 * i;
        double c[4];
        for (int r = 0; r < 4; r++)
            c[r] = (double)m[r] * q[0] + (double)m[4 + r] * q[1] + (double)m[8 + r] * q[2] + m[12 + r];
        double px = (c[0] / c[3] * 0.5 + 0.5) * W, py = (c[1] / c[3] * 0.5 + 0.5) * H;
        double rpx = pc->radius[i] * v.proj[5] * 0.5 * H / c[3] + 1.0;
        for (int y = (int)floor(py - rpx); y <= (int)ceil(py + rpx); y++)
            for (int x = (int)floor(px - rpx); x <= (int)ceil(px + rpx); x++)
                if (x >= 0 && y >= 0 && x < W && y < H &&
                    hypot(x + 0.5 - px, y + 0.5 - py) <= rpx)
                    count[y * W + x]++;
    }
}

/* Over every pixel, the largest channel difference between a and b less the pixel's layers
 * (count; at least 1): > 0 where the difference exceeds what count 8-bit blends allow. */
static int over_layers(const rnd_frame *a, const rnd_frame *b, const int *count)
{
    int worst = -1000;
    for (size_t i = 0; i < (size_t)W * H; i++)
        for (int c = 0; c < 3; c++) {
            int d = abs(a->rgba8[4 * i + c] - b->rgba8[4 * i + c]);
            int allow = count[i] > 1 ? count[i] : 1;
            worst = d - allow > worst ? d - allow : worst;
        }
    return worst;
}

static uint32_t upload_layered_plane(void)
{
    return upload_layered_plane_to(tu_ctx);
}

/* layered_scene: the layered plane on tu_ctx, seen obliquely, soft at t 0.4, lambda 0.5, l_m 0.6. */
static uint32_t layered_scene(rnd_camera *cam, sp_params *p)
{
    *cam = cam_z(3.0);
    cam->eye[0] += 1.0, cam->eye[1] += 0.5;
    sp_params_defaults(p);
    p->pipeline = SP_PIPE_SOFT, p->t = 0.4f, p->lambda = 0.5f, p->l_m = 0.6f;
    return upload_layered_plane();
}

/* order=tile and the host compositor composite the same discs in the same order as order=axis,
 * in float with one rounding to 8 bits where the sprites blend into the 8-bit target disc by
 * disc. On a random plane (soft points lifted in front by 0.05 + 0.1 F, lambda 0.5, l_m 0.6:
 * several soft layers per pixel, seen obliquely) the images may differ by that rounding only.
 * Tolerance, derived from what a conforming GL may do: each blend into RGBA8 is carried out at
 * no less than 8 bits and converted to one of the two nearest bytes (GL 4.5, 17.3.6.1 and
 * 2.3.5.2): less than 1 level each, which the discs over it scale by 1 - alpha <= 1, so at a
 * pixel under L discs axis may be up to L levels from the float result (disc_layers counts L;
 * llvmpipe rounds to nearest and stays near half of it). Tile against the host compositor: both
 * in float, each within 1 level after their one conversion (the host rounds to nearest: 0.5),
 * and their float sums within far less than a level of each other (products and sums correctly
 * rounded; eq. 19's cosine is the one operation whose precision GLSL leaves open, on every GL
 * within 1e-6 of the true value, a 4e-4 of a level): at most 1 level apart. */
static void test_tile_matches_axis(void **state)
{
    (void)state;
    rnd_camera cam;
    sp_params p;
    uint32_t id = layered_scene(&cam, &p);
    pc_prepared lp;
    layered_plane(&lp);
    int *layers = malloc(sizeof(int) * W * H), maxl = 0;
    assert_non_null(layers);
    disc_layers(&lp, p.t, &cam, layers);
    pc_prepared_free(&lp);
    for (int i = 0; i < W * H; i++) maxl = layers[i] > maxl ? layers[i] : maxl;
    rnd_frame a = {0}, b = {0}, c = {0}, u = {0};
    p.order = SP_ORDER_AXIS;
    tu_render(tu_ctx, id, &cam, &p, 0, &a);
    p.order = SP_ORDER_TILE;
    tu_render(tu_ctx, id, &cam, &p, 0, &b);
    int n, m = max_diff(&a, &b, &n), cov = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) cov += a.rgba8[4 * i] || a.rgba8[4 * i + 1] || a.rgba8[4 * i + 2];
    int ot = over_layers(&a, &b, layers);
    printf("order=tile vs axis, random plane: max difference %d levels (%d of %d covered pixels "
           "differ), up to %d discs a pixel; difference less layers at most %d\n", m, n, cov,
           maxl, ot);
    assert_true(cov > W * H / 4);
    assert_true(maxl >= 4);
    assert_true(ot <= 0);
    /* order=auto with the host paths: the same discs, order and float blending as tile, on the
     * host */
    p.order = SP_ORDER_AUTO;
    tu_render(tu_ctx, id, &cam, &p, 0, &c);
    int nc, mc = max_diff(&a, &c, &nc), nt, mt = max_diff(&b, &c, &nt);
    int oc = over_layers(&a, &c, layers);
    printf("host compositor vs axis: max %d levels (%d pixels), less layers at most %d; vs tile: "
           "max %d (%d pixels)\n", mc, nc, oc, mt, nt);
    assert_true(oc <= 0);
    assert_true(mt <= 1); /* both float: one rounding, float sums in another order at most */
    /* order=auto without the host paths is axis, exactly */
    rnd_desc gd = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                   .host_paths = RND_CAP_OFF};
    sd_err err = {0};
    rnd_ctx *gl = rnd_create(&gd, &err);
    if (!gl) fail_msg("rnd_create: %s", err.msg);
    uint32_t idg = upload_layered_plane_to(gl);
    p.order = SP_ORDER_AUTO;
    tu_render(gl, idg, &cam, &p, 0, &u);
    assert_memory_equal(u.rgba8, a.rgba8, (size_t)W * H * 4);
    rnd_destroy(gl);
    free(layers);
    rnd_frame_free(&a);
    rnd_frame_free(&b);
    rnd_frame_free(&c);
    rnd_frame_free(&u);
    rnd_release(tu_ctx, id);
}

/* A frame whose float layer exceeds the host compositor's band (64 MiB: 2100 x 2100 x 16 bytes = 67 MiB,
 * so two bands): the bands meet without a seam. Against order=tile (the GL's compositor, the
 * same float blending) at most 1 level over every pixel, as in test_tile_matches_axis; a band
 * composited at the wrong rows or offset shows as differences of many levels. The layer and its
 * bands are what the host compositor makes when something follows it in the GL: a float frame here (an
 * 8-bit one composites over the read-back pixels instead, test_after_matches_layer). */
static void test_cpu_bands(void **state)
{
    (void)state;
    uint32_t id = upload_layered_plane();
    rnd_camera cam = cam_z(2.2);
    cam.width = 2100, cam.height = 2100;
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.4f, p.lambda = 0.5f, p.l_m = 0.6f;
    rnd_frame a = {0}, b = {0};
    p.order = SP_ORDER_TILE;
    tu_render(tu_ctx, id, &cam, &p, 1, &a);
    p.order = SP_ORDER_AUTO;
    tu_render(tu_ctx, id, &cam, &p, 1, &b);
    int n, m = max_diff(&a, &b, &n), cov = 0;
    for (size_t i = 0; i < (size_t)a.width * a.height; i++)
        cov += a.rgba8[4 * i] || a.rgba8[4 * i + 1] || a.rgba8[4 * i + 2];
    printf("2100x2100, the host compositor (two bands) vs tile: max %d levels (%d of %d covered pixels "
           "differ)\n", m, n, cov);
    assert_true(cov > 2100 * 2100 / 4);
    assert_true(m <= 1);
    rnd_frame_free(&a);
    rnd_frame_free(&b);
    rnd_release(tu_ctx, id);
}

/* The host compositor on an opaque 8-bit frame with nothing after it in the GL composites the discs over
 * the read-back pixels (soft_host.c soft__after: a float tile per thread, put over the frame
 * tile by tile); on a float frame it uploads the layer and the GL puts it over the target. The
 * two must agree: at most 1 level (the 8-bit path rounds the solid colour before the "over",
 * the float one after), in a frame where the soft discs change at least 20 % of the pixels
 * (against lambda = 0). A tile put over the wrong pixels, or a layer lost, differs by many
 * levels. */
static void test_after_matches_layer(void **state)
{
    (void)state;
    rnd_camera cam;
    sp_params p;
    uint32_t id = layered_scene(&cam, &p);
    p.order = SP_ORDER_AUTO;
    rnd_frame host = {0}, layer = {0}, none = {0};
    tu_render(tu_ctx, id, &cam, &p, 0, &host);
    tu_render(tu_ctx, id, &cam, &p, 1, &layer);
    int n, m = max_diff(&host, &layer, &n), nsoft;
    p.lambda = 0.0f;
    tu_render(tu_ctx, id, &cam, &p, 0, &none);
    max_diff(&host, &none, &nsoft);
    printf("host compositor over the read-back pixels vs the GL's layer: max %d levels (%d pixels); "
           "the discs changed %d of %d pixels\n", m, n, nsoft, W * H);
    assert_true(nsoft >= W * H / 5);
    assert_true(m <= 1);
    rnd_release(tu_ctx, id);
    rnd_frame_free(&host);
    rnd_frame_free(&layer);
    rnd_frame_free(&none);
}

/* The host "over" with the frame in 3 stripes against 1 (the keys of every stripe kept for
 * soft__after) on a comb: bands of solid points 6 grid rows high, the soft points between them
 * 0.03 behind, seen face on, so that each band's edge is a row where the keys change from solid
 * to empty: at most 1 level (float sums added in another order), where keys taken from the
 * wrong rows flip whole rows of soft discs. */
static void test_after_stripes(void **state)
{
    (void)state;
    rnd_desc dd = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                   .pipe = {.splat_stripe_rows = (H + 2) / 3}, .host_paths = RND_CAP_ON};
    sd_err err = {0};
    rnd_ctx *r3 = rnd_create(&dd, &err);
    if (!r3) fail_msg("rnd_create: %s", err.msg);
    pc_prepared pc;
    random_plane(&pc, 90, 90, 0.02f, 5);
    for (uint64_t k = 0; k < pc.n; k++) {
        pc.F[k] = (k / 90 / 6) % 2 ? 0.9f : 0.1f;
        if (pc.F[k] > 0.5f) pc.pos[3 * k + 2] = -0.03f;
    }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc), id3 = tu_upload(r3, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.order = SP_ORDER_AUTO;
    p.t = 0.5f, p.lambda = 0.5f, p.l_m = 0.0f;
    rnd_frame host = {0}, striped = {0};
    tu_render(tu_ctx, id, &cam, &p, 0, &host);
    tu_render(r3, id3, &cam, &p, 0, &striped);
    rnd_release(r3, id3);
    rnd_destroy(r3);
    int ns, ms = max_diff(&host, &striped, &ns);
    printf("comb, 3 stripes vs 1: max %d levels (%d pixels)\n", ms, ns);
    assert_true(ms <= 1);
    rnd_frame_free(&host);
    rnd_frame_free(&striped);
    rnd_release(tu_ctx, id);
}

/* shading=edl after the host compositor: a GL pass follows the pipeline, so the discs go over
 * the target as a layer (not over the read-back pixels) before the GL's EDL darkens the frame,
 * as after order=tile: the two frames must agree within 1 level (as in
 * test_tile_matches_axis: both blend in float), on a frame where EDL darkens at least 2 % of
 * the pixels (against lambert). EDL before the discs would leave them undarkened at the
 * plane's edges, which differs by many levels. */
static void test_host_then_edl(void **state)
{
    (void)state;
    rnd_camera cam;
    sp_params p;
    uint32_t id = layered_scene(&cam, &p);
    p.order = SP_ORDER_AUTO;
    rnd_frame lam = {0}, tile = {0}, host = {0};
    tu_render(tu_ctx, id, &cam, &p, 0, &lam);
    p.shading = SP_SHADING_EDL, p.edl_strength = 4.0f;
    tu_render(tu_ctx, id, &cam, &p, 0, &host);
    p.order = SP_ORDER_TILE;
    tu_render(tu_ctx, id, &cam, &p, 0, &tile);
    int nd, m = max_diff(&tile, &host, &nd), ne;
    max_diff(&lam, &host, &ne);
    printf("soft with EDL: host compositor vs tile max %d levels (%d pixels); EDL changed %d of "
           "%d pixels\n", m, nd, ne, W * H);
    assert_true(ne >= W * H / 50);
    assert_true(m <= 1);
    rnd_frame_free(&lam);
    rnd_frame_free(&tile);
    rnd_frame_free(&host);
    rnd_release(tu_ctx, id);
}

/* A cloud in several buffer sets (rnd_desc.max_set_points, as the renderer splits clouds over
 * GL_MAX_TEXTURE_BUFFER_SIZE / 3 points): the solid points then go through the splat passes as
 * runs of the view's chunks instead of the one-set filter, and the soft discs set by set (sets
 * back to front by their centres along the axis, each sorted within). With lambda = 0 the frame
 * must equal the one-set frame bit for bit (tolerance 0: the same splats); with lambda = 0.5,
 * where the soft discs of neighbouring sets overlap on screen in an order that may differ from
 * the one-set order, at most the tolerance of test_tile_matches_axis's layering (4 levels) in
 * at most 2 % of the pixels. */
static void test_buffer_sets(void **state)
{
    (void)state;
    rnd_desc dd = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                   .max_set_points = 2000, .host_paths = RND_CAP_ON};
    sd_err err = {0};
    rnd_ctx *r4 = rnd_create(&dd, &err);
    if (!r4) fail_msg("rnd_create: %s", err.msg);
    pc_prepared pc;
    random_plane(&pc, 90, 90, 0.02f, 4);
    for (uint64_t i = 0; i < pc.n; i++)
        if (pc.F[i] > 0.6f) pc.pos[3 * i + 2] = 0.1f;
    tu_finish_cloud(&pc, OFF);
    uint32_t id1 = tu_upload(tu_ctx, &pc), id4 = tu_upload(r4, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.6f;
    const float lambdas[2] = {0.0f, 0.5f};
    for (int l = 0; l < 2; l++) {
        p.lambda = lambdas[l];
        rnd_frame a = {0}, b = {0};
        tu_render(tu_ctx, id1, &cam, &p, 0, &a);
        tu_render(r4, id4, &cam, &p, 0, &b);
        int n, m = max_diff(&a, &b, &n);
        printf("buffer sets, lambda %.1f: max difference to one set %d levels (%d pixels)\n",
               lambdas[l], m, n);
        if (l == 0) assert_int_equal(m, 0);
        else assert_true(m <= 4 && n <= W * H / 50);
        rnd_frame_free(&a);
        rnd_frame_free(&b);
    }
    rnd_release(tu_ctx, id1);
    rnd_release(r4, id4);
    rnd_destroy(r4);
}

/* More soft discs than one dispatch of the projection covers (4096 groups of 32 = 131072): a
 * 460 x 460 plane of soft points (211600, F = 1) facing the camera, lambda = 0.5, both orders.
 * Every pixel inside the plane's screen square must be covered (not the background): the
 * projection walks all discs (before the fix, the discs past 131072 in the sorted order were
 * left unprojected and the plane had a hole at one end). Tolerance: none of the pixels inside
 * the square, 2 pixels in from its edges, is background, with every order. */
static void test_many_soft_points(void **state)
{
    (void)state;
    enum { NX = 460 };
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)NX * NX, 0);
    const float h = 0.0045f; /* the plane stays inside the frame (90 of 96 px half width) */
    for (int j = 0; j < NX; j++)
        for (int i = 0; i < NX; i++) {
            uint64_t k = (uint64_t)j * NX + i;
            pc.pos[3 * k] = (i - 0.5f * (NX - 1)) * h;
            pc.pos[3 * k + 1] = (j - 0.5f * (NX - 1)) * h;
            pc.radius[k] = 2.0f * h;
            pc.F[k] = 1.0f;
        }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_z(3.0);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.t = 0.5f, p.lambda = 0.5f;
    double half = 0.5 * (NX - 1) * h, px = disc_px(half, 3.0);
    int x0 = (int)ceil(0.5 * W - px) + 2, x1 = (int)floor(0.5 * W + px) - 2;
    assert_true(x0 >= 0 && x1 < W); /* the square is inside the frame */
    for (int oi = 0; oi < 3; oi++) {
        p.order = orders[oi];
        rnd_frame f = {0};
        tu_render(tu_ctx, id, &cam, &p, 0, &f);
        int empty = 0, n = 0;
        for (int y = x0; y <= x1; y++)
            for (int x = x0; x <= x1; x++, n++) empty += pix(&f, x, y)[0] == 0;
        printf("many soft points, order=%s: %d of %d pixels in the plane's square empty\n",
               onames[oi], empty, n);
        assert_true(n > 5000);
        assert_int_equal(empty, 0);
        rnd_frame_free(&f);
    }
    rnd_release(tu_ctx, id);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_t1_equals_splat),
        cmocka_unit_test(test_lambda0_is_solid_splat),
        cmocka_unit_test(test_disc_opacity_eq19),
        cmocka_unit_test(test_two_layers_order),
        cmocka_unit_test(test_modulation),
        cmocka_unit_test(test_field_height),
        cmocka_unit_test(test_tile_matches_axis),
        cmocka_unit_test(test_cpu_bands),
        cmocka_unit_test(test_after_matches_layer),
        cmocka_unit_test(test_after_stripes),
        cmocka_unit_test(test_host_then_edl),
        cmocka_unit_test(test_buffer_sets),
        cmocka_unit_test(test_many_soft_points),
    };
    return cmocka_run_group_tests(tests, setup_host, tu_egl_group_teardown);
}
