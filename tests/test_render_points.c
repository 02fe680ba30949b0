/* test_render_points.c — the renderer and the `points` pipeline on llvmpipe, against analytic
 * projections: pixel positions, eye depths, visibility, culling, the point budget, colours,
 * coverage, agreement of the two back ends and the two raster forms, and stale cloud ids.
 *
 * Every test runs on six renderers: {EGL, OSMesa} x {packed compute, exact compute, GL_POINTS}
 * (pipe_points.c). Clouds are built in memory (pc_prepared_alloc), offset far from the origin
 * like georeferenced data. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "commands.h"
#include "gl_names.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { NR = 6, W = 256, H = 256 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0}; /* a UTM-like offset */

typedef struct fixture {
    rnd_ctx *r[NR];
    const char *label[NR];
} fixture;

static int setup(void **state)
{
    static const char *labels[NR] = {"egl/packed", "osmesa/packed", "egl/exact",
                                     "osmesa/exact", "egl/gl",    "osmesa/gl"};
    static const int modes[NR / 2] = {RND_RASTER_PACKED, RND_RASTER_EXACT, RND_RASTER_GL};
    fixture *fx = calloc(1, sizeof *fx);
    if (!fx) return -1;
    for (int i = 0; i < NR; i++) {
        rnd_desc d = {.backend = (i % 2) ? RND_BACKEND_OSMESA : RND_BACKEND_EGL,
                      .shader_dir = getenv("SPLATD_SHADERS"),
                      .pipe = {.points_raster = modes[i / 2]}};
        sd_err err = {0};
        fx->r[i] = rnd_create(&d, &err);
        if (!fx->r[i]) {
            fprintf(stderr, "%s: %s\n", labels[i], err.msg);
            return -1;
        }
        fx->label[i] = labels[i];
    }
    *state = fx;
    return 0;
}

static int teardown(void **state)
{
    fixture *fx = *state;
    for (int i = 0; i < NR; i++) rnd_destroy(fx->r[i]);
    free(fx);
    return 0;
}

static void set_point(pc_prepared *pc, uint64_t i, float x, float y, float z, uint8_t r,
                      uint8_t g, uint8_t b)
{
    pc->pos[3 * i] = x, pc->pos[3 * i + 1] = y, pc->pos[3 * i + 2] = z;
    pc->rgba[4 * i] = r, pc->rgba[4 * i + 1] = g, pc->rgba[4 * i + 2] = b;
}

/* A camera at local eye looking down -z at local target (x, y, 0), up +y. */
static rnd_camera cam_down(double ex, double ey, double ez, float fov)
{
    rnd_camera c = {{ex + OFF[0], ey + OFF[1], ez + OFF[2]},
                    {ex + OFF[0], ey + OFF[1], OFF[2]},
                    {0, 1, 0}, fov, 0, 0, W, H};
    return c;
}

static const uint8_t *px(const rnd_frame *f, int x, int y)
{
    return f->rgba8 + 4 * ((size_t)y * f->width + x);
}

static int is_bg(const uint8_t *p, const uint8_t bg[3])
{
    return p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2];
}

static float half_to_float(uint16_t h)
{
    int e = (h >> 10) & 31, m = h & 1023;
    float v = e == 0    ? ldexpf((float)m, -24)
              : e == 31 ? INFINITY
                        : ldexpf((float)(m | 1024), e - 25);
    return (h & 0x8000) ? -v : v;
}

/* Points at known positions land on the analytically projected pixel and report the analytic
 * eye depth. Projection: eye at (0,0,5) looking down -z, fov 60: a point (x, y, z) is at eye
 * depth d = 5 - z and pixel x = (x / d * t / aspect + 1) / 2 * W, t = 1 / tan(30 deg). */
static void test_projection_and_depth(void **state)
{
    fixture *fx = *state;
    enum { N = 6 };
    const float P[N][3] = {{0, 0, 0},       {0.731f, 0.2f, 1.3f},  {-1.1f, 0.83f, -0.7f},
                           {1.9f, -1.4f, -2.2f}, {-0.37f, -0.91f, 2.6f}, {0.05f, 1.5f, -4.0f}};
    pc_prepared pc;
    tu_new_cloud(&pc, N, 1);
    for (int i = 0; i < N; i++)
        set_point(&pc, i, P[i][0], P[i][1], P[i][2], (uint8_t)(30 + 40 * i), 200, 10);
    tu_finish_cloud(&pc, OFF);
    rnd_camera cam = cam_down(0, 0, 5, 60);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        tu_render(fx->r[ri], id, &cam, &p, 1, &f);
        assert_int_equal(f.points_drawn, N);
        const double t = 1.0 / tan(30 * M_PI / 180);
        int covered = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) covered += !is_bg(px(&f, x, y), (uint8_t[3]){0, 0, 0});
        assert_int_equal(covered, N); /* point_size 1: one pixel each */
        for (int i = 0; i < N; i++) {
            double d = 5.0 - P[i][2];
            double sx = (P[i][0] / d * t + 1) / 2 * W, sy = (P[i][1] / d * t + 1) / 2 * H;
            int found = 0;
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++) {
                    if (px(&f, x, y)[0] != 30 + 40 * i || px(&f, x, y)[1] != 200) continue;
                    found++;
                    /* The pixel's centre is within half a pixel of the projection (the
                     * GL_POINTS rule; 1e-3 px for float rounding in the transform). */
                    assert_true(fabs(x + 0.5 - sx) <= 0.5 + 1e-3);
                    assert_true(fabs(y + 0.5 - sy) <= 0.5 + 1e-3);
                    float de = f.depth[(size_t)y * W + x];
                    /* Float transform of a depth of a few units: 1e-5 relative. */
                    assert_true(fabs(de - d) <= 1e-5 * d);
                    /* Linear colour in the half-float frame, alpha 1 = covered. */
                    assert_true(fabsf(half_to_float(f.rgba16f[4 * ((size_t)y * W + x)]) -
                                      (30 + 40 * i) / 255.0f) < 1e-3f);
                    assert_true(half_to_float(f.rgba16f[4 * ((size_t)y * W + x) + 3]) == 1.0f);
                    assert_int_equal(px(&f, x, y)[3], 255); /* 8-bit frames are opaque */
                }
            if (found != 1) fail_msg("%s: point %d found on %d pixels", fx->label[ri], i, found);
        }
        /* A second frame from another eye: exactly N pixels again, none left over from the
         * first (the compute forms clear only the cloud's screen rectangle). */
        rnd_camera cam2 = cam_down(0.3, -0.2, 5, 60);
        rnd_frame f2 = {0};
        tu_render(fx->r[ri], id, &cam2, &p, 0, &f2);
        int covered2 = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) covered2 += !is_bg(px(&f2, x, y), (uint8_t[3]){0, 0, 0});
        assert_int_equal(covered2, N);
        rnd_frame_free(&f2);
        /* Empty pixels: depth +inf, alpha 0 in the float frame, 255 in the 8-bit one. */
        assert_true(isinf(f.depth[0]) && f.depth[0] > 0);
        assert_true(half_to_float(f.rgba16f[3]) == 0.0f);
        assert_int_equal(f.rgba8[3], 255);
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* Two points on one line of sight: the nearer one wins whichever is drawn first. */
static void test_nearer_wins(void **state)
{
    fixture *fx = *state;
    for (int order = 0; order < 2; order++) {
        pc_prepared pc;
        tu_new_cloud(&pc, 2, 1);
        /* Both on the view axis at x = y = 0.3 / depth, so they hit one pixel. */
        set_point(&pc, order, 0.3f, 0.3f, 1.0f, 255, 0, 0);   /* near: depth 4 */
        set_point(&pc, 1 - order, 0.6f, 0.6f, -3.0f, 0, 0, 255); /* far: depth 8 */
        tu_finish_cloud(&pc, OFF);
        rnd_camera cam = cam_down(0, 0, 5, 50);
        sp_params p;
        sp_params_defaults(&p);
        p.pipeline = SP_PIPE_POINTS;
        p.point_size = 3; /* both squares cover the same 3x3 pixels */
        for (int ri = 0; ri < NR; ri++) {
            uint32_t id = tu_upload(fx->r[ri], &pc);
            rnd_frame f = {0};
            tu_render(fx->r[ri], id, &cam, &p, 1, &f);
            int red = 0, blue = 0;
            for (int i = 0; i < W * H; i++) {
                red += f.rgba8[4 * i] == 255 && f.rgba8[4 * i + 2] == 0;
                blue += f.rgba8[4 * i + 2] == 255;
                if (f.rgba8[4 * i] == 255) assert_true(fabsf(f.depth[i] - 4.0f) < 4e-5f);
            }
            if (red != 9 || blue != 0)
                fail_msg("%s order %d: %d red, %d blue pixels (want 9, 0)", fx->label[ri], order,
                         red, blue);
            rnd_release(fx->r[ri], id);
            rnd_frame_free(&f);
        }
        pc_prepared_free(&pc);
    }
}

/* A grid of side k x k with spacing s centred at the origin in the plane z = 0. */
static void grid_cloud(pc_prepared *pc, int k, float s, uint64_t nb, uint8_t r, uint8_t g,
                       uint8_t b)
{
    tu_new_cloud(pc, (uint64_t)k * k, nb);
    for (int j = 0; j < k; j++)
        for (int i = 0; i < k; i++)
            set_point(pc, (uint64_t)j * k + i, (i - (k - 1) / 2.0f) * s, (j - (k - 1) / 2.0f) * s,
                      0, r, g, b);
    tu_finish_cloud(pc, OFF);
}

/* Culling: a cloud behind the camera or beside the frustum draws nothing; of two batches one
 * visible, exactly its points are drawn. The background is exact where nothing is drawn. */
static void test_culling_and_background(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    grid_cloud(&pc, 64, 0.01f, 4, 255, 255, 255);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    p.background[0] = 0.2f, p.background[1] = 0.4f, p.background[2] = 0.6f;
    const uint8_t bg[3] = {51, 102, 153}; /* round(255 * background) */
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        /* The cloud behind the camera: the eye at z = -5 looking towards -z. */
        rnd_camera cam = {{OFF[0], OFF[1], OFF[2] - 5}, {OFF[0], OFF[1], OFF[2] - 10}, {0, 1, 0},
                          40, 0, 0, W, H};
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 0);
        for (int i = 0; i < W * H; i++) assert_true(is_bg(f.rgba8 + 4 * i, bg));
        /* Beside the frustum: at distance 5, fov 40 sees +-1.82; the grid (+-0.315) is 10
         * units to the side. */
        cam = cam_down(10, 0, 5, 40);
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 0);
        for (int i = 0; i < W * H; i++) assert_true(is_bg(f.rgba8 + 4 * i, bg));
        /* Batches are bands of 16 grid rows; the top one (rows 48-63) spans y in
         * [0.165, 0.315], the one below it [0.005, 0.155]. At distance 1, fov 40 sees
         * y in [cy - 0.364, cy + 0.364]: cy = 0.70 sees none of them, cy = 0.57 (bottom edge
         * 0.206) exactly the top band. */
        cam = cam_down(0, 0.70, 1, 40);
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 0);
        cam = cam_down(0, 0.57, 1, 40);
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 16 * 64);
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* point_budget: ranges in batch order, truncated. */
static void test_point_budget(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    grid_cloud(&pc, 64, 0.01f, 4, 255, 255, 255);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 3, 40);
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        p.point_budget = 0;
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 4096);
        p.point_budget = 1500;
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        assert_int_equal(f.points_drawn, 1500);
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* A sparse regular plane facing the camera: points leave background pixels inside its
 * projected rectangle (points make no surface; the splat pipeline's test asserts the
 * opposite). Spacing 0.02 at distance 2 with fov 40 is 0.02 / (2 * tan 20) * 256 = 3.5 px, so
 * every point has its own pixel: covered == points exactly, and with point_size 3 (squares
 * of 3 x 3 pixel centres, 3.5 px apart) covered == 9 x points. */
static void test_sparse_plane_has_holes(void **state)
{
    fixture *fx = *state;
    enum { K = 48 };
    pc_prepared pc;
    grid_cloud(&pc, K, 0.02f, 1, 255, 255, 255);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 2, 40);
    double pxu = 256 / (2 * 2 * tan(20 * M_PI / 180)); /* pixels per unit at depth 2 */
    int lo = (int)ceil(128 - 0.47 * pxu), hi = (int)floor(128 + 0.47 * pxu);
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        for (int size = 1; size <= 3; size += 2) {
            p.point_size = (float)size;
            tu_render(fx->r[ri], id, &cam, &p, 0, &f);
            int covered = 0, holes = 0;
            for (int i = 0; i < W * H; i++) covered += f.rgba8[4 * i] == 255;
            for (int y = lo; y < hi; y++)
                for (int x = lo; x < hi; x++) holes += f.rgba8[4 * ((size_t)y * W + x)] == 0;
            if (covered != K * K * size * size)
                fail_msg("%s size %d: %d pixels covered, want %d", fx->label[ri], size, covered,
                         K * K * size * size);
            /* Coverage inside: 1/3.5^2 = 8 % (size 1), 9/3.5^2 = 73 % (size 3). */
            double frac = (double)holes / ((hi - lo) * (hi - lo));
            if (size == 1) assert_true(frac > 0.85);
            else assert_true(frac > 0.2 && frac < 0.35);
        }
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* A dense constant-colour cloud renders exactly that colour wherever it covers; the colour
 * modes normal, intensity, depth and field give their analytic colours. */
static void test_colours(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    grid_cloud(&pc, 200, 0.004f, 2, 77, 153, 230);
    for (uint64_t i = 0; i < pc.n; i++) {
        float *n = &pc.normal[3 * i];
        n[0] = 1, n[1] = 0, n[2] = 0;          /* colour (1, 0.5, 0.5) */
        pc.intensity[i] = (i == 0) ? 0.0f : (i == 1) ? 10.0f : 5.0f; /* 5 -> 0.5 */
    }
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 2, 40);
    cam.znear = 1, cam.zfar = 5;
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        /* depth: 1 - (2 - near 1) / (far 5 - near 1) = 0.75; field: F = 0 is the colour
         * map's first entry, viridis (0.2777, 0.0054, 0.3341). */
        const uint8_t want[5][3] = {{77, 153, 230}, {255, 128, 128}, {128, 128, 128},
                                    {191, 191, 191}, {71, 1, 85}};
        const int mode[5] = {SP_COLOR_RGB, SP_COLOR_NORMAL, SP_COLOR_INTENSITY, SP_COLOR_DEPTH,
                             SP_COLOR_FIELD};
        for (int m = 0; m < 5; m++) {
            p.color = mode[m];
            tu_render(fx->r[ri], id, &cam, &p, 0, &f);
            int covered = 0, wrong = 0;
            for (int i = 0; i < W * H; i++) {
                const uint8_t *q = f.rgba8 + 4 * i;
                if (q[0] == 0 && q[1] == 0 && q[2] == 0) continue;
                covered++;
                /* Intensity: points 0 and 1 (0 and 10) are the two ends; skip their pixels. */
                wrong += q[0] != want[m][0] || q[1] != want[m][1] || q[2] != want[m][2];
            }
            /* 0.8 units at 2 units, fov 40: 0.8 / 1.456 * 256 = 141 px square, dense. */
            assert_true(covered > 135 * 135);
            assert_true(wrong <= (m == 2 ? 2 : 0));
        }
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* The same scene on EGL and OSMesa (same raster form) gives the same image, and the compute
 * raster matches GL_POINTS except where rounding at a pixel edge decides differently. */
static void test_backends_agree(void **state)
{
    fixture *fx = *state;
    enum { N = 20000 };
    pc_prepared pc;
    tu_new_cloud(&pc, N, 5);
    uint32_t s = 12345;
    for (uint64_t i = 0; i < N; i++) {
        float v[3];
        for (int k = 0; k < 3; k++) {
            s = s * 1664525u + 1013904223u;
            v[k] = (s >> 8) / 16777216.0f * 2 - 1;
        }
        set_point(&pc, i, v[0], v[1], v[2], (uint8_t)(i * 7), (uint8_t)(i * 13), (uint8_t)(i >> 4));
    }
    tu_finish_cloud(&pc, OFF);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    p.point_size = 2;
    rnd_camera cam;
    tu_camera_box(pc.bmin, pc.bmax, W, H, &cam);
    rnd_frame f[NR];
    memset(f, 0, sizeof f);
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        tu_render(fx->r[ri], id, &cam, &p, 1, &f[ri]);
        assert_int_equal(f[ri].points_drawn, N);
        rnd_release(fx->r[ri], id);
    }
    for (int pair = 0; pair < NR / 2; pair++) {
        const rnd_frame *a = &f[2 * pair], *b = &f[2 * pair + 1];
        assert_memory_equal(a->rgba8, b->rgba8, (size_t)W * H * 4);
        assert_memory_equal(a->depth, b->depth, (size_t)W * H * sizeof(float));
    }
    int packed_exact = 0, exact_gl = 0, covered = 0;
    for (int i = 0; i < W * H; i++) {
        covered += f[0].rgba8[4 * i] || f[0].rgba8[4 * i + 1] || f[0].rgba8[4 * i + 2];
        packed_exact += memcmp(f[0].rgba8 + 4 * i, f[2].rgba8 + 4 * i, 4) != 0;
        exact_gl += memcmp(f[2].rgba8 + 4 * i, f[4].rgba8 + 4 * i, 4) != 0;
    }
    print_message("of %d covered pixels, packed vs exact: %d differ, exact vs GL_POINTS: %d\n",
                  covered, packed_exact, exact_gl);
    assert_true(covered > 10000);
    /* Packed keys keep 17 depth bits for 20000 points: a depth quantum of 2^-17 of
     * log2(far/near) puts two points of one pixel in one quantum very rarely. */
    assert_true(packed_exact <= covered / 1000);
    /* GL_POINTS: pixel-centre ties at square edges may round the other way. */
    assert_true(exact_gl <= covered / 100);
    for (int ri = 0; ri < NR; ri++) rnd_frame_free(&f[ri]);
    pc_prepared_free(&pc);
}

/* Ids: 0 and stale ids are rejected, never dereferenced; a reused slot gets a new id. */
static void test_stale_id(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    grid_cloud(&pc, 8, 0.1f, 1, 255, 255, 255);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 2, 40);
    rnd_ctx *r = fx->r[0];
    rnd_frame f = {0};
    sd_err err = {0};
    uint32_t id = tu_upload(r, &pc);
    assert_int_equal(rnd_render(r, id, &cam, &p, 0, &f, &err), 0);
    rnd_release(r, id);
    assert_int_equal(rnd_render(r, id, &cam, &p, 0, &f, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "cloud id"));
    uint32_t id2 = tu_upload(r, &pc);
    assert_true(id2 != id);
    assert_int_equal(rnd_render(r, id, &cam, &p, 0, &f, &err), SD_EINVAL);
    assert_int_equal(rnd_render(r, 0, &cam, &p, 0, &f, &err), SD_EINVAL);
    assert_int_equal(rnd_render(r, id2 + 1, &cam, &p, 0, &f, &err), SD_EINVAL);
    assert_int_equal(rnd_render(r, id2, &cam, &p, 0, &f, &err), 0);
    rnd_release(r, id);  /* stale: no effect */
    assert_int_equal(rnd_render(r, id2, &cam, &p, 0, &f, &err), 0);
    /* Bad sizes and pipelines are refused with a message. */
    cam.width = 0;
    assert_int_equal(rnd_render(r, id2, &cam, &p, 0, &f, &err), SD_ELIMIT);
    cam.width = 9000;
    assert_int_equal(rnd_render(r, id2, &cam, &p, 0, &f, &err), SD_ELIMIT);
    cam.width = W;
    p.pipeline = 7;
    assert_int_equal(rnd_render(r, id2, &cam, &p, 0, &f, &err), SD_EINVAL);
    rnd_release(r, id2);
    rnd_frame_free(&f);
    pc_prepared_free(&pc);
}

/* The far plane culls and clips: eye at z = 5 looking down, near 1, far 5 (the camera's own
 * values, not the box's). Three batches of 16 points, each on its own pixel: batch 0 (red) at
 * depth 2; batch 1 half at depth 2 (green), half at depth 8 (blue); batch 2 (blue) all at
 * depth 8. Batch 2 lies wholly beyond the far plane and is culled (points_drawn counts
 * batches 0 and 1 only); batch 1 straddles it and stays, but its points beyond far are not
 * drawn by any form. */
static void test_far_plane_culls_and_clips(void **state)
{
    fixture *fx = *state;
    enum { M = 16 };
    pc_prepared pc;
    tu_new_cloud(&pc, 3 * M, 3);
    for (int b = 0; b < 3; b++)
        for (int j = 0; j < M; j++) {
            int far = b == 2 || (b == 1 && j >= M / 2);
            float x = (j % 4 - 1.5f) * 0.15f + b * 0.7f - 0.7f, y = (j / 4 - 1.5f) * 0.15f;
            set_point(&pc, (uint64_t)b * M + j, x, y, far ? -3.0f : 3.0f, b == 0 ? 255 : 0,
                      b == 1 && !far ? 255 : 0, far ? 255 : 0);
        }
    tu_finish_cloud(&pc, OFF);
    rnd_camera cam = cam_down(0, 0, 5, 60);
    cam.znear = 1, cam.zfar = 5;
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        tu_render(fx->r[ri], id, &cam, &p, 0, &f);
        int red = 0, green = 0, blue = 0;
        for (int i = 0; i < W * H; i++) {
            const uint8_t *q = f.rgba8 + 4 * i;
            red += q[0] == 255 && q[1] == 0 && q[2] == 0;
            green += q[0] == 0 && q[1] == 255 && q[2] == 0;
            blue += q[2] != 0;
        }
        if (f.points_drawn != 2 * M || red != M || green != M / 2 || blue != 0)
            fail_msg("%s: %llu points drawn (want %d), %d red (want %d), %d green (want %d), "
                     "%d blue (want 0)", fx->label[ri], (unsigned long long)f.points_drawn,
                     2 * M, red, M, green, M / 2, blue);
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* The packed form's limit (pipe_points.c): point indices take the smallest b bits with
 * n <= 2^b - 1 (the all-ones key means "empty"), and at least 12 bits must stay for the depth,
 * so the packed form takes clouds below 2^20 points. A cloud of 2^20 - 1 points renders; one
 * of exactly 2^20 needs 21 index bits, leaves 11 depth bits and is refused with a message
 * naming the limit (asked for explicitly; auto would take the exact form). */
static void test_packed_form_limit(void **state)
{
    fixture *fx = *state;
    rnd_ctx *r = fx->r[0]; /* egl/packed */
    const uint64_t big = (uint64_t)1 << 20;
    pc_prepared pc;
    tu_new_cloud(&pc, big, 1);
    for (uint64_t i = 0; i < big; i++)
        set_point(&pc, i, (float)(i % 1024) * 0.001f - 0.5f, (float)(i / 1024) * 0.001f - 0.5f,
                  0, 255, 255, 255);
    tu_finish_cloud(&pc, OFF);
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 2, 40);
    rnd_frame f = {0};
    sd_err err = {0};
    uint32_t id = tu_upload(r, &pc);
    assert_int_equal(rnd_render(r, id, &cam, &p, 0, &f, &err), SD_ELIMIT);
    assert_non_null(strstr(err.msg, "fewer than 12 depth bits"));
    rnd_release(r, id);
    pc.n = big - 1;
    tu_finish_cloud(&pc, OFF);
    id = tu_upload(r, &pc);
    tu_render(r, id, &cam, &p, 0, &f);
    assert_int_equal(f.points_drawn, big - 1);
    rnd_release(r, id);
    rnd_frame_free(&f);
    pc_prepared_free(&pc);
}

/* A cloud without colours is drawn white (render.h: missing colours are white), whatever its
 * unused colour array holds; intensities are normalised by the cloud's own range, not by
 * zero: intensities 100 (one point), 300 (one point) and 200 (the rest) make 200 the middle
 * grey, (200 - 100) / (300 - 100) = 0.5, i.e. 128. */
static void test_missing_colours_and_intensity_range(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    grid_cloud(&pc, 200, 0.004f, 2, 10, 20, 30);
    pc.attrs &= ~(uint32_t)PC_ATTR_RGB;
    for (uint64_t i = 0; i < pc.n; i++)
        pc.intensity[i] = (i == 0) ? 100.0f : (i == 1) ? 300.0f : 200.0f;
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_camera cam = cam_down(0, 0, 2, 40);
    const uint8_t want[2] = {255, 128};
    const int mode[2] = {SP_COLOR_RGB, SP_COLOR_INTENSITY};
    for (int ri = 0; ri < NR; ri++) {
        uint32_t id = tu_upload(fx->r[ri], &pc);
        rnd_frame f = {0};
        for (int m = 0; m < 2; m++) {
            p.color = mode[m];
            tu_render(fx->r[ri], id, &cam, &p, 0, &f);
            int covered = 0, wrong = 0;
            for (int i = 0; i < W * H; i++) {
                const uint8_t *q = f.rgba8 + 4 * i;
                if (q[0] == 0 && q[1] == 0 && q[2] == 0) continue;
                covered++;
                wrong += q[0] != want[m] || q[1] != want[m] || q[2] != want[m];
            }
            /* 0.8 units at 2 units, fov 40: a dense 141 px square (as in test_colours); the
             * two end points of the intensity range may show as two odd pixels. */
            if (covered <= 135 * 135 || wrong > (m ? 2 : 0))
                fail_msg("%s color=%s: %d pixels covered, %d not grey %d", fx->label[ri],
                         m ? "intensity" : "rgb", covered, wrong, want[m]);
        }
        rnd_release(fx->r[ri], id);
        rnd_frame_free(&f);
    }
    pc_prepared_free(&pc);
}

/* The default camera frames the box: every corner projects inside the frame. */
static void test_camera_frame(void **state)
{
    (void)state;
    const double bmin[3] = {100, 200, 10}, bmax[3] = {140, 260, 35};
    for (int pass = 0; pass < 2; pass++) {
        rnd_camera cam;
        double top[3] = {bmax[0], bmax[1], pass ? bmin[2] + 1 : bmax[2]}; /* pass 1: flat */
        tu_camera_box(bmin, top, 320, 200, &cam);
        assert_int_equal(cam.width, 320);
        double f[3], len = 0;
        for (int k = 0; k < 3; k++) f[k] = cam.target[k] - cam.eye[k], len += f[k] * f[k];
        len = sqrt(len);
        for (int k = 0; k < 3; k++) {
            f[k] /= len;
            assert_true(fabs(cam.target[k] - 0.5 * (bmin[k] + top[k])) < 1e-9);
        }
        /* s = f x up, u = s x f; every corner within the fov in both directions. */
        double s[3] = {f[1] * cam.up[2] - f[2] * cam.up[1], f[2] * cam.up[0] - f[0] * cam.up[2],
                       f[0] * cam.up[1] - f[1] * cam.up[0]};
        double sl = sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        for (int k = 0; k < 3; k++) s[k] /= sl;
        double u[3] = {s[1] * f[2] - s[2] * f[1], s[2] * f[0] - s[0] * f[2],
                       s[0] * f[1] - s[1] * f[0]};
        double ty = tan(cam.fov_deg * M_PI / 360), tx = ty * 320 / 200;
        for (int c = 0; c < 8; c++) {
            double q[3] = {c & 1 ? top[0] : bmin[0], c & 2 ? top[1] : bmin[1],
                           c & 4 ? top[2] : bmin[2]};
            double d[3] = {q[0] - cam.eye[0], q[1] - cam.eye[1], q[2] - cam.eye[2]};
            double z = d[0] * f[0] + d[1] * f[1] + d[2] * f[2];
            double x = d[0] * s[0] + d[1] * s[1] + d[2] * s[2];
            double y = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
            assert_true(z > 0);
            assert_true(fabs(x / z) < tx && fabs(y / z) < ty);
        }
    }
}

/* auto picks EGL here (Mesa's software device); a broken shader from --shader-dir stops
 * rnd_create with a message naming the file and the compiler's complaint. */
static void test_auto_backend_and_shader_errors(void **state)
{
    (void)state;
    sd_err err = {0};
    rnd_desc d = {.backend = RND_BACKEND_AUTO};
    rnd_ctx *r = rnd_create(&d, &err);
    assert_non_null(r);
    assert_string_equal(rnd_backend_name(r), "egl");
    assert_true(!strncmp(rnd_renderer_string(r), "egl: ", 5));
    assert_true(strlen(rnd_renderer_string(r)) > 6);
    rnd_destroy(r);

    char dir[512], path[600];
    tu_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/points.frag.glsl", dir);
    const char *bad = "#version 430\nout vec4 o;\nvoid main() { o = undefined_thing; }\n";
    assert_int_equal(tu_write_file(path, bad, strlen(bad)), 0);
    d.backend = RND_BACKEND_OSMESA;
    d.shader_dir = dir;
    r = rnd_create(&d, &err);
    assert_null(r);
    assert_int_equal(err.code, SD_EGL);
    assert_non_null(strstr(err.msg, path));
    assert_non_null(strstr(err.msg, "undefined_thing"));
    tu_rm_rf(dir);
}

/* The software capability is the back end's (gl_backend.h): EGL's from its device's
 * EGL_MESA_device_software, OSMesa always; by default the host paths follow it, and here, where
 * the device is Mesa's software one, its renderer's name must say so too (the two ways of
 * knowing agree). rnd_desc.software and .host_paths override it: host paths on or off whatever
 * the back end, off with software off unless forced on; values outside RND_CAP_* are refused. */
static void test_software_capability(void **state)
{
    (void)state;
    static const struct {
        int software, host, want;
    } cases[] = {
        {RND_CAP_AUTO, RND_CAP_ON, 1}, {RND_CAP_AUTO, RND_CAP_OFF, 0},
        {RND_CAP_OFF, RND_CAP_AUTO, 0}, {RND_CAP_ON, RND_CAP_AUTO, 1},
        {RND_CAP_OFF, RND_CAP_ON, 1},
    };
    sd_err err = {0};
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS")};
    rnd_ctx *r = rnd_create(&d, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    int named = gl_renderer_is_software(rnd_renderer_string(r));
    printf("egl: %s; host paths by default %d, the name says software %d\n",
           rnd_renderer_string(r), rnd_host_paths(r), named);
    assert_int_equal(rnd_host_paths(r), named);
    rnd_destroy(r);
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        d.software = cases[k].software, d.host_paths = cases[k].host;
        r = rnd_create(&d, &err);
        if (!r) fail_msg("rnd_create: %s", err.msg);
        assert_int_equal(rnd_host_paths(r), cases[k].want);
        rnd_destroy(r);
    }
    const int bad[4][2] = {{RND_CAP_OFF + 1, 0}, {-1, 0}, {0, RND_CAP_OFF + 1}, {0, -1}};
    for (int k = 0; k < 4; k++) {
        d.software = bad[k][0], d.host_paths = bad[k][1];
        assert_null(rnd_create(&d, &err));
        assert_int_equal(err.code, SD_EINVAL);
    }
    rnd_desc o = {.backend = RND_BACKEND_OSMESA, .shader_dir = getenv("SPLATD_SHADERS")};
    r = rnd_create(&o, &err);
    if (!r) TU_SKIP("OSMesa back end unavailable: %s", err.msg);
    assert_int_equal(rnd_host_paths(r), 1);
    rnd_destroy(r);
}

/* Runs `splatd render` with the given arguments (NULL-terminated). */
static int run_render(const char *first, ...)
{
    char *argv[40];
    int argc = 0;
    argv[argc++] = "render";
    va_list ap;
    va_start(ap, first);
    for (const char *a = first; a && argc < 39; a = va_arg(ap, const char *))
        argv[argc++] = (char *)a;
    va_end(ap);
    argv[argc] = NULL;
    return cmd_render(argc, argv);
}

/* Usage errors exit 2, failures 1, each before any GL work. */
static void test_cmd_render_errors(void **state)
{
    (void)state;
    char ply[512];
    tu_data("bun000.ply", ply, sizeof ply);
    assert_int_equal(run_render(ply, "-o", "x.png", "--bogus", NULL), 2);       /* unknown */
    assert_int_equal(run_render(ply, "-o", NULL), 2);                           /* no value */
    assert_int_equal(run_render(ply, "-o", "x.png", "--fov", "wide", NULL), 2); /* bad number */
    assert_int_equal(run_render(ply, "-o", "x.png", "--fov", "180", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--eye", "1,2", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--size", "0x100", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--size", "8193x100", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--size", "640", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--set", "lambda", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--set", "point_size=1000", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--pipeline", "teapot", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--backend", "vulkan", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.png", "--points-raster", "fast", NULL), 2);
    assert_int_equal(run_render(ply, "-o", "x.bmp", NULL), 2);                  /* format */
    assert_int_equal(run_render(ply, NULL), 2);                                 /* no -o */
    assert_int_equal(run_render("-o", "x.png", NULL), 2);                       /* no FILE */
    assert_int_equal(run_render(ply, "-o", "x.png", "--near", "5", "--far", "1", NULL), 2);
    assert_int_equal(run_render("/nonexistent/cloud.ply", "-o", "x.png", NULL), 1);
}

/* A real scan to PNG and EXR through the cache and the encoders; the output files exist and
 * carry their format's magic bytes. */
static void test_cmd_render_file(void **state)
{
    (void)state;
    char ply[512], dir[512], png[600], exr[600], cache[600];
    tu_data("bun000.ply", ply, sizeof ply);
    tu_tmpdir(dir, sizeof dir);
    snprintf(png, sizeof png, "%s/f.png", dir);
    snprintf(exr, sizeof exr, "%s/f.exr", dir);
    snprintf(cache, sizeof cache, "%s/cache", dir);
    assert_int_equal(run_render(ply, "-o", png, "--pipeline", "points", "--size", "160x120",
                                "--cache", cache, "--quiet", "--set", "color=normal", NULL), 0);
    assert_int_equal(run_render(ply, "-o", exr, "--pipeline", "points", "--size", "160x120",
                                "--cache", cache, "--quiet", "--backend", "osmesa",
                                "--up", "0,1,0", "--fov", "30", NULL), 0);
    size_t n = 0;
    uint8_t *b = tu_read_file(png, &n);
    assert_non_null(b);
    assert_true(n > 8 && !memcmp(b, "\x89PNG", 4));
    free(b);
    b = tu_read_file(exr, &n);
    assert_non_null(b);
    assert_true(n > 4 && b[0] == 0x76 && b[1] == 0x2f && b[2] == 0x31 && b[3] == 0x01);
    free(b);
    tu_rm_rf(dir);
}

/* make_sphere: n points on a unit sphere around the local origin (deterministic, golden-angle
 * spiral), colours varying with the index, splat radius fit for the density. */
static void make_sphere(pc_prepared *pc, uint64_t n, uint64_t nb)
{
    tu_new_cloud(pc, n, nb);
    for (uint64_t i = 0; i < n; i++) {
        double z = 1.0 - 2.0 * (i + 0.5) / n, r = sqrt(1.0 - z * z), a = 2.39996323 * i;
        set_point(pc, i, (float)(r * cos(a)), (float)(r * sin(a)), (float)z, (uint8_t)(i * 7),
                  (uint8_t)(i * 13), (uint8_t)(i * 29));
        for (int k = 0; k < 3; k++) pc->normal[3 * i + k] = pc->pos[3 * i + k];
        pc->radius[i] = (float)(2.5 / sqrt((double)n));
    }
    tu_finish_cloud(pc, OFF);
}

/* A cloud split over several buffer sets (rnd_desc.max_set_points, as a cloud past the
 * driver's buffer-texture limit is) renders what one set renders: every points form
 * pixel for pixel (the raster passes key points by their cloud-wide index, so depth order and
 * ties resolve across sets as within one), and splat within the float atomics' summation
 * order (they run in another order anyway: 2/255 in any channel). Batches of 1024 points
 * with sets of 1000 also cut every batch into two chunks. */
static void test_buffer_sets(void **state)
{
    (void)state;
    enum { N = 20000 };
    pc_prepared pc;
    make_sphere(&pc, N, N / 1024 + 1);
    rnd_camera cam = {{OFF[0] + 0.4, OFF[1] - 2.6, OFF[2] + 0.9}, {OFF[0], OFF[1], OFF[2]},
                      {0, 0, 1}, 50, 0, 0, W, H};
    static const int forms[3] = {RND_RASTER_PACKED, RND_RASTER_EXACT, RND_RASTER_GL};
    for (int fi = 0; fi < 3; fi++) {
        rnd_frame f[2] = {{0}, {0}};
        for (int split = 0; split < 2; split++) {
            rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                          .max_set_points = split ? 1000 : 0, .pipe = {.points_raster = forms[fi]}};
            sd_err err = {0};
            rnd_ctx *r = rnd_create(&d, &err);
            if (!r) fail_msg("rnd_create: %s", err.msg);
            uint32_t id = tu_upload(r, &pc);
            for (int pl = 0; pl < 2; pl++) {
                sp_params p;
                sp_params_defaults(&p);
                p.pipeline = pl ? SP_PIPE_SPLAT : SP_PIPE_POINTS;
                p.point_size = 2;
                if (pl && fi) continue; /* splat once */
                rnd_frame g = {0};
                tu_render(r, id, &cam, &p, 0, pl ? &g : &f[split]);
                assert_int_equal((pl ? g : f[split]).points_drawn, N / 2 + N / 2);
                if (pl) {
                    static uint8_t first[W * H * 4];
                    if (!split) memcpy(first, g.rgba8, sizeof first);
                    int worst = 0, covered = 0;
                    for (int i = 0; i < W * H * 4; i++) {
                        int dd = abs((int)g.rgba8[i] - first[i]);
                        if (dd > worst) worst = dd;
                        covered += (i % 4 == 0) && g.rgba8[i] + g.rgba8[i + 1] + g.rgba8[i + 2];
                    }
                    assert_true(covered > W * H / 4);
                    if (split && worst > 2) fail_msg("splat over buffer sets differs by %d/255", worst);
                }
                rnd_frame_free(&g);
            }
            rnd_destroy(r);
        }
        int same = memcmp(f[0].rgba8, f[1].rgba8, (size_t)W * H * 4) == 0;
        if (!same) fail_msg("points (form %d) over buffer sets is not the one-set image", forms[fi]);
        rnd_frame_free(&f[0]);
        rnd_frame_free(&f[1]);
    }
    pc_prepared_free(&pc);
}

/* Two clouds whose buffers together exceed the GPU budget (rnd_desc.gpu_memory, splatd
 * --gpu-memory): adopting the second evicts the first (least recently used), rendering the first
 * brings it back and evicts the second, and each image equals the image of that cloud rendered
 * alone, in a renderer with room for both. */
static void test_residency_budget(void **state)
{
    (void)state;
    enum { N = 30000 };
    const uint64_t bytes = (uint64_t)N * 40; /* 10 floats a point (pipe.h RND_ATTR_LIST) */
    rnd_camera cam = {{OFF[0] + 0.4, OFF[1] - 2.6, OFF[2] + 0.9}, {OFF[0], OFF[1], OFF[2]},
                      {0, 0, 1}, 50, 0, 0, W, H};
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SPLAT;
    rnd_frame ref[2] = {{0}, {0}};
    rnd_desc roomy = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS")};
    rnd_desc tight = roomy;
    tight.gpu_memory = bytes + bytes / 2; /* one fits, two do not */
    sd_err err = {0};
    rnd_ctx *r = rnd_create(&roomy, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    for (int k = 0; k < 2; k++) {
        pc_prepared pc;
        make_sphere(&pc, N - 7000 * k, 0); /* two different clouds */
        uint32_t id = tu_upload(r, &pc);
        tu_render(r, id, &cam, &p, 0, &ref[k]);
        pc_prepared_free(&pc);
    }
    rnd_destroy(r);

    r = rnd_create(&tight, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    uint32_t id[2];
    for (int k = 0; k < 2; k++) {
        pc_prepared *pc = calloc(1, sizeof *pc);
        make_sphere(pc, N - 7000 * k, 0);
        int64_t got = rnd_adopt(r, pc, &err);
        if (got <= 0) fail_msg("rnd_adopt: %s", err.msg);
        id[k] = (uint32_t)got;
    }
    rnd_stats st;
    rnd_get_stats(r, &st);
    assert_int_equal(st.clouds, 2);
    assert_int_equal(st.resident, 1);
    assert_int_equal(rnd_cloud_resident(r, id[0]), 0); /* the second pushed the first out */
    assert_int_equal(rnd_cloud_resident(r, id[1]), 1);
    assert_true(st.resident_bytes <= tight.gpu_memory);
    const int order[3] = {1, 0, 1};
    for (int i = 0; i < 3; i++) {
        int k = order[i];
        rnd_frame f = {0};
        tu_render(r, id[k], &cam, &p, 0, &f);
        assert_int_equal(rnd_cloud_resident(r, id[k]), 1);
        assert_int_equal(rnd_cloud_resident(r, id[1 - k]), 0);
        int worst = 0;
        for (size_t j = 0; j < (size_t)W * H * 4; j++) {
            int dd = abs((int)f.rgba8[j] - ref[k].rgba8[j]);
            if (dd > worst) worst = dd;
        }
        if (worst > 2) fail_msg("cloud %d after %d evictions differs by %d/255", k, i, worst);
        rnd_frame_free(&f);
    }
    rnd_get_stats(r, &st);
    assert_int_equal(st.evictions, 3);   /* at the second adopt, then at each switch */
    assert_int_equal(st.uploads, 4);
    /* A cloud bigger than the whole budget is refused by name, and the others stay usable. */
    pc_prepared *big = calloc(1, sizeof *big);
    make_sphere(big, 2 * N, 0);
    assert_true(rnd_adopt(r, big, &err) < 0);
    assert_non_null(strstr(err.msg, "GPU budget"));
    rnd_frame f = {0};
    tu_render(r, id[0], &cam, &p, 0, &f);
    rnd_frame_free(&f);
    rnd_release(r, id[0]);
    rnd_release(r, id[1]);
    rnd_get_stats(r, &st);
    assert_int_equal(st.clouds, 0);
    assert_int_equal(st.resident_bytes, 0);
    rnd_destroy(r);
    rnd_frame_free(&ref[0]);
    rnd_frame_free(&ref[1]);
}

/* Eviction takes the least recently rendered cloud, not the oldest upload: with room for two
 * clouds, A and B are adopted, A is rendered, and adopting C must evict B (last used before
 * A's frame), keeping A. The budget is two and a half clouds, measured by adopting one cloud
 * in a renderer with room to spare (so the test does not depend on the bytes per point). */
static void test_residency_evicts_least_recently_rendered(void **state)
{
    (void)state;
    enum { N = 2000 };
    rnd_camera cam = {{OFF[0] + 0.4, OFF[1] - 2.6, OFF[2] + 0.9}, {OFF[0], OFF[1], OFF[2]},
                      {0, 0, 1}, 50, 0, 0, 64, 64};
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS")};
    sd_err err = {0};
    rnd_ctx *r = rnd_create(&d, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    pc_prepared *pc = calloc(1, sizeof *pc);
    make_sphere(pc, N, 0);
    if (rnd_adopt(r, pc, &err) <= 0) fail_msg("rnd_adopt: %s", err.msg);
    rnd_stats st;
    rnd_get_stats(r, &st);
    uint64_t one = st.resident_bytes;
    assert_true(one > 0);
    rnd_destroy(r);

    d.gpu_memory = 2 * one + one / 2;
    r = rnd_create(&d, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    uint32_t id[3];
    for (int k = 0; k < 3; k++) {
        if (k == 2) { /* A is rendered after B's upload: B is now the least recently used */
            rnd_frame f = {0};
            tu_render(r, id[0], &cam, &p, 0, &f);
            rnd_frame_free(&f);
        }
        pc = calloc(1, sizeof *pc);
        make_sphere(pc, N, 0);
        int64_t got = rnd_adopt(r, pc, &err);
        if (got <= 0) fail_msg("rnd_adopt: %s", err.msg);
        id[k] = (uint32_t)got;
    }
    rnd_get_stats(r, &st);
    assert_int_equal(st.evictions, 1);
    if (rnd_cloud_resident(r, id[0]) != 1 || rnd_cloud_resident(r, id[1]) != 0 ||
        rnd_cloud_resident(r, id[2]) != 1)
        fail_msg("resident after C's upload: A %d, B %d, C %d (want 1, 0, 1)",
                 rnd_cloud_resident(r, id[0]), rnd_cloud_resident(r, id[1]),
                 rnd_cloud_resident(r, id[2]));
    for (int k = 0; k < 3; k++) rnd_release(r, id[k]);
    rnd_destroy(r);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_camera_frame),
        cmocka_unit_test(test_projection_and_depth),
        cmocka_unit_test(test_nearer_wins),
        cmocka_unit_test(test_culling_and_background),
        cmocka_unit_test(test_point_budget),
        cmocka_unit_test(test_sparse_plane_has_holes),
        cmocka_unit_test(test_colours),
        cmocka_unit_test(test_backends_agree),
        cmocka_unit_test(test_stale_id),
        cmocka_unit_test(test_auto_backend_and_shader_errors),
        cmocka_unit_test(test_software_capability),
        cmocka_unit_test(test_cmd_render_errors),
        cmocka_unit_test(test_cmd_render_file),
        cmocka_unit_test(test_buffer_sets),
        cmocka_unit_test(test_residency_budget),
        cmocka_unit_test(test_residency_evicts_least_recently_rendered),
        cmocka_unit_test(test_far_plane_culls_and_clips),
        cmocka_unit_test(test_missing_colours_and_intensity_range),
        cmocka_unit_test(test_packed_form_limit),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
