/* test_render_splat.c — the `splat` pipeline (EWA surface splatting) on llvmpipe through the
 * public renderer (render.h), against analytic expectations: hole filling, exact normalisation
 * of a constant colour, visibility and depth of two planes, EWA anti-aliasing of a minified
 * checkerboard, the elliptical footprint of an inclined disc, a real scan (stable across runs and
 * against golden images over covered pixels, one a magnified close-up in ewa=exact), and the
 * fixed-point fallback and OSMesa back end. The footprint tests run in both filter modes
 * (ewa=exact: the textbook resampling filter per splat; ewa=split: part of the low-pass in the
 * resolve); the second moments of minified exact footprints are checked against J V_r J^T + I
 * from splat_math.c, and those of tilted, off-axis splats under a wide fov (where the
 * perspective term of the shader's Jacobian matters) against a finite-difference Jacobian of the
 * projection computed in the test itself (test_tilted_footprints).
 * Timings are in `make bench` (tests/bench/render_bench.c, with --set ewa=exact for the textbook
 * filter), not here. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "camera.h"
#include "cloud.h"
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "splat_math.h"
#include "imgtest.h"
#include "testutil.h"

enum { W = 256, H = 256 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0}; /* a UTM-like offset */

typedef struct fixture {
    rnd_ctx *egl;
} fixture;

/* make_ctx: a renderer on back end kind with the pipeline options o (NULL: defaults). */
static rnd_ctx *make_ctx(rnd_backend_kind kind, const rnd_pipe_opts *o)
{
    rnd_desc d = {.backend = kind, .shader_dir = getenv("SPLATD_SHADERS")};
    if (o) d.pipe = *o;
    sd_err err = {0};
    rnd_ctx *r = rnd_create(&d, &err);
    if (!r) fprintf(stderr, "rnd_create: %s\n", err.msg);
    return r;
}

static int setup(void **state)
{
    fixture *fx = calloc(1, sizeof *fx);
    if (!fx) return -1;
    fx->egl = make_ctx(RND_BACKEND_EGL, NULL);
    if (!fx->egl) {
        free(fx);
        return -1;
    }
    *state = fx;
    return 0;
}

static int teardown(void **state)
{
    fixture *fx = *state;
    if (!fx) return 0;
    rnd_destroy(fx->egl);
    free(fx);
    return 0;
}

/* Fills points [first, first + nx * ny) with a regular grid in the plane z = z0 centred on the
 * origin, spacing h, radius r, colour rgb (or a checkerboard of `cell` points with rgb and rgb2
 * when cell > 0). */
static void grid(pc_prepared *pc, uint64_t first, int nx, int ny, float h, float z0, float r,
                 const uint8_t rgb[3], const uint8_t rgb2[3], int cell)
{
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            uint64_t k = first + (uint64_t)j * nx + i;
            pc->pos[3 * k] = (i - 0.5f * (nx - 1)) * h;
            pc->pos[3 * k + 1] = (j - 0.5f * (ny - 1)) * h;
            pc->pos[3 * k + 2] = z0;
            pc->radius[k] = r;
            const uint8_t *c = (cell > 0 && ((i / cell + j / cell) & 1)) ? rgb2 : rgb;
            for (int q = 0; q < 3; q++) pc->rgba[4 * k + q] = c[q];
        }
}

/* A camera at local (ex, ey, ez) looking at local (tx, ty, tz), up +y. */
static rnd_camera cam_at(double ex, double ey, double ez, double tx, double ty, double tz,
                         float fov, int w, int h)
{
    rnd_camera c = {{ex + OFF[0], ey + OFF[1], ez + OFF[2]},
                    {tx + OFF[0], ty + OFF[1], tz + OFF[2]},
                    {0, 1, 0}, fov, 0, 0, w, h};
    return c;
}

/* ---- projection, as camera.c builds it (gluLookAt + gluPerspective), for analytic pixels ---- */

typedef struct proj {
    double e[3], s[3], u[3], f[3];
    double t, aspect;
    int w, h;
} proj;

static void vnorm(double v[3])
{
    double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    v[0] /= l, v[1] /= l, v[2] /= l;
}

static proj proj_of(const rnd_camera *c)
{
    proj p;
    for (int i = 0; i < 3; i++) p.e[i] = c->eye[i] - OFF[i], p.f[i] = c->target[i] - c->eye[i];
    vnorm(p.f);
    p.s[0] = p.f[1] * c->up[2] - p.f[2] * c->up[1];
    p.s[1] = p.f[2] * c->up[0] - p.f[0] * c->up[2];
    p.s[2] = p.f[0] * c->up[1] - p.f[1] * c->up[0];
    vnorm(p.s);
    p.u[0] = p.s[1] * p.f[2] - p.s[2] * p.f[1];
    p.u[1] = p.s[2] * p.f[0] - p.s[0] * p.f[2];
    p.u[2] = p.s[0] * p.f[1] - p.s[1] * p.f[0];
    p.t = 1.0 / tan(c->fov_deg * M_PI / 360.0);
    p.aspect = (double)c->width / c->height;
    p.w = c->width, p.h = c->height;
    return p;
}

/* Pixel position (sx, sy) and eye depth of local point (x, y, z). */
static void project(const proj *p, double x, double y, double z, double *sx, double *sy, double *d)
{
    double q[3] = {x - p->e[0], y - p->e[1], z - p->e[2]};
    double xe = q[0] * p->s[0] + q[1] * p->s[1] + q[2] * p->s[2];
    double ye = q[0] * p->u[0] + q[1] * p->u[1] + q[2] * p->u[2];
    double de = q[0] * p->f[0] + q[1] * p->f[1] + q[2] * p->f[2];
    *sx = (xe * p->t / p->aspect / de + 1) * 0.5 * p->w;
    *sy = (ye * p->t / de + 1) * 0.5 * p->h;
    if (d) *d = de;
}

/* The pixel rectangle [x0, x1] x [y0, y1] inside the projection of the local axis-aligned
 * rectangle [ax, bx] x [ay, by] at height z (seen straight down: an exact screen rectangle),
 * shrunk by m pixels. */
static void rect_px(const proj *p, double ax, double bx, double ay, double by, double z, int m,
                    int r[4])
{
    double sx0, sy0, sx1, sy1;
    project(p, ax, ay, z, &sx0, &sy0, NULL);
    project(p, bx, by, z, &sx1, &sy1, NULL);
    r[0] = (int)ceil(fmin(sx0, sx1)) + m, r[1] = (int)ceil(fmin(sy0, sy1)) + m;
    r[2] = (int)floor(fmax(sx0, sx1)) - 1 - m, r[3] = (int)floor(fmax(sy0, sy1)) - 1 - m;
}

static const uint8_t *pix(const rnd_frame *f, int x, int y)
{
    return f->rgba8 + 4 * ((size_t)y * f->width + x);
}

static int is_bg(const uint8_t *q)
{
    return q[0] == 0 && q[1] == 0 && q[2] == 0;
}

static uint64_t rng_next(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s >> 33;
}

static float rng_unit(uint64_t *s) /* in [-1, 1) */
{
    return (float)rng_next(s) / (float)(1u << 30) - 1.0f;
}

static const char *ewa_name(int ewa)
{
    return ewa == SP_EWA_EXACT ? "exact" : ewa == SP_EWA_SPLIT ? "split" : "auto";
}

/* ---- tests ---- */

/* A dense regular plane facing the camera: `splat` leaves no background pixel inside the
 * projected rectangle of the outermost point centres (shrunk by 2 px: the Gaussian rim is
 * sampled at pixel centres, so the last pixel row may be partly covered), in both regimes:
 * spacing 1.6 px (minified: deposited splats, holes filled by the low-pass) and 5 px
 * (magnified: rasterised ellipses, radius 1.2 spacings). `points` of the first, with spacing
 * 1.6 px > 1 px, must leave holes: that is what the splats fill. */
static void check_hole_filling(rnd_ctx *rc, int ewa)
{
    enum { N = 100 };
    const float h = 0.01f;
    const uint8_t white[3] = {255, 255, 255};
    const double px_per_unit_at_1 = W / (2 * tan(30 * M_PI / 180)); /* fov 60 */
    const double spacing_px[2] = {1.6, 5.0}, rfac[2] = {1.0, 1.2};
    for (int k = 0; k < 2; k++) {
        pc_prepared pc;
        tu_new_cloud(&pc, (uint64_t)N * N, 0);
        grid(&pc, 0, N, N, h, 0, h * (float)rfac[k], white, white, 0);
        tu_finish_cloud(&pc, OFF);
        uint32_t id = tu_upload(rc, &pc);
        pc_prepared_free(&pc);
        double dist = h * px_per_unit_at_1 / spacing_px[k];
        rnd_camera cam = cam_at(0, 0, dist, 0, 0, 0, 60, W, H);
        proj pj = proj_of(&cam);
        int r[4];
        double half = 0.5 * (N - 1) * h;
        rect_px(&pj, -half, half, -half, half, 0, 2, r);
        int rx0 = r[0] < 0 ? 0 : r[0], ry0 = r[1] < 0 ? 0 : r[1];
        int rx1 = r[2] >= W ? W - 1 : r[2], ry1 = r[3] >= H ? H - 1 : r[3];
        assert_true(rx1 - rx0 > 50 && ry1 - ry0 > 50);
        sp_params p;
        sp_params_defaults(&p);
        p.ewa = ewa;
        rnd_frame f = {0};
        tu_render(rc, id, &cam, &p, 0, &f);
        int holes = 0;
        for (int y = ry0; y <= ry1; y++)
            for (int x = rx0; x <= rx1; x++) holes += is_bg(pix(&f, x, y));
        if (holes) fail_msg("splat ewa=%s, spacing %.1f px: %d background pixels inside the plane", ewa_name(ewa), spacing_px[k], holes);
        if (k == 0 && ewa == SP_EWA_SPLIT) {
            p.pipeline = SP_PIPE_POINTS;
            tu_render(rc, id, &cam, &p, 0, &f);
            holes = 0;
            for (int y = ry0; y <= ry1; y++)
                for (int x = rx0; x <= rx1; x++) holes += is_bg(pix(&f, x, y));
            /* 1-px points 1.6 px apart cover about 1 / 1.6^2 = 39 % of the pixels. */
            assert_true(holes > (rx1 - rx0) * (ry1 - ry0) / 4);
        }
        rnd_frame_free(&f);
        rnd_release(rc, id);
    }
}

static void test_hole_filling(void **state)
{
    fixture *fx = *state;
    check_hole_filling(fx->egl, SP_EWA_SPLIT);
    check_hole_filling(fx->egl, SP_EWA_EXACT);
}

/* A constant-colour plane with jittered sampling (so overlapping weights differ from pixel to
 * pixel) facing the camera, lit along the view axis: every covered pixel normalises to exactly
 * the colour. Tolerance 1/255: the RGBA16F target's rounding (11-bit mantissa) then GL's float
 * to unorm8 conversion; the sums themselves are exact to float rounding (1e-6). Three regimes. */
static void check_constant_colour(rnd_ctx *r, const char *label, int ewa)
{
    enum { N = 100 };
    const float h = 0.01f;
    const uint8_t col[3] = {200, 100, 50};
    const double px_per_unit_at_1 = W / (2 * tan(30 * M_PI / 180));
    /* Spacings: minified (deposited), magnified (sampled), close-up (splats of ~26 px radius,
     * boxes over SPLAT_BIG_PIXELS: the 8x8 work-group path). */
    const double spacing_px[3] = {1.3, 6.0, 20.0};
    for (int k = 0; k < 3; k++) {
        pc_prepared pc;
        tu_new_cloud(&pc, (uint64_t)N * N, 0);
        grid(&pc, 0, N, N, h, 0, h * 1.3f, col, col, 0);
        uint64_t seed = 12345;
        for (uint64_t i = 0; i < pc.n; i++) {
            pc.pos[3 * i] += 0.3f * h * rng_unit(&seed);
            pc.pos[3 * i + 1] += 0.3f * h * rng_unit(&seed);
        }
        tu_finish_cloud(&pc, OFF);
        uint32_t id = tu_upload(r, &pc);
        pc_prepared_free(&pc);
        rnd_camera cam = cam_at(0, 0, h * px_per_unit_at_1 / spacing_px[k], 0, 0, 0, 60, W, H);
        sp_params p;
        sp_params_defaults(&p);
        p.light[0] = 0, p.light[1] = 0, p.light[2] = 1;
        p.ewa = ewa;
        rnd_frame f = {0};
        tu_render(r, id, &cam, &p, 0, &f);
        int covered = 0, bad = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                const uint8_t *q = pix(&f, x, y);
                if (is_bg(q)) continue;
                covered++;
                for (int c = 0; c < 3; c++) bad += abs(q[c] - col[c]) > 1;
            }
        if (bad) fail_msg("%s, ewa=%s, spacing %.1f px: %d channel values differ from the colour by more than 1", label, ewa_name(ewa), spacing_px[k], bad);
        assert_true(covered > 5000);
        if (k == 2) assert_int_equal(covered, W * H); /* the close-up fills the frame */
        rnd_frame_free(&f);
        rnd_release(r, id);
    }
}

static void test_constant_colour(void **state)
{
    fixture *fx = *state;
    check_constant_colour(fx->egl, "egl, float atomics", SP_EWA_SPLIT);
    check_constant_colour(fx->egl, "egl, float atomics", SP_EWA_EXACT);
}

/* Two parallel planes facing the camera, the nearer (z = 0, colour A, 1 x 1) in front of a
 * larger farther one (z = -0.3, colour B, 1.6 x 1.6), far plane's points first in the buffer:
 * only A shows where A covers, B around it, and depth_eye equals the analytic eye depth (eye
 * at z = dist: A at dist, B at dist + 0.3) within 1e-3 relative (the ray-plane depth of a
 * facing plane is exact to float rounding, 1e-6). Margins: 2 px inside A (rim sampling and the
 * one-pixel low-pass gather), A's projected radius + 2.5 px outside A for B. */
static void check_two_planes(rnd_ctx *r, const char *label, int ewa)
{
    enum { NA = 100, NB = 160 };
    const float h = 0.01f;
    const uint8_t ca[3] = {220, 40, 40}, cb[3] = {40, 40, 220};
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)NA * NA + (uint64_t)NB * NB, 0);
    grid(&pc, 0, NB, NB, h, -0.3f, h * 1.3f, cb, cb, 0);
    grid(&pc, (uint64_t)NB * NB, NA, NA, h, 0, h * 1.3f, ca, ca, 0);
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    pc_prepared_free(&pc);
    const double dist = 1.6;
    rnd_camera cam = cam_at(0, 0, dist, 0, 0, 0, 60, W, H);
    proj pj = proj_of(&cam);
    int ra[4], ra_out[4], rb[4];
    double ha = 0.5 * (NA - 1) * h, hb = 0.5 * (NB - 1) * h;
    rect_px(&pj, -ha, ha, -ha, ha, 0, 2, ra);
    /* A's splats reach r (1.3 spacings = 1.8 px here) plus the low-pass (about 1.5 px) beyond
     * its outermost centres. */
    double r_px = 1.3 * h * W / (2 * dist * tan(30 * M_PI / 180));
    rect_px(&pj, -ha, ha, -ha, ha, 0, -(int)ceil(r_px + 2.5), ra_out);
    rect_px(&pj, -hb, hb, -hb, hb, -0.3, 2, rb);
    sp_params p;
    sp_params_defaults(&p);
    p.light[0] = 0, p.light[1] = 0, p.light[2] = 1;
    p.ewa = ewa;
    rnd_frame f = {0};
    tu_render(r, id, &cam, &p, 1, &f);
    int na = 0, nb = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int in_a = x >= ra[0] && x <= ra[2] && y >= ra[1] && y <= ra[3];
            int near_a = x >= ra_out[0] && x <= ra_out[2] && y >= ra_out[1] && y <= ra_out[3];
            int in_b = x >= rb[0] && x <= rb[2] && y >= rb[1] && y <= rb[3];
            const uint8_t *want = in_a ? ca : (in_b && !near_a) ? cb : NULL;
            if (!want) continue;
            const uint8_t *q = pix(&f, x, y);
            for (int c = 0; c < 3; c++)
                if (abs(q[c] - want[c]) > 1)
                    fail_msg("%s, ewa=%s: pixel (%d, %d) is %d,%d,%d, not plane %c's %d,%d,%d",
                             label, ewa_name(ewa), x, y, q[0], q[1], q[2], in_a ? 'A' : 'B',
                             want[0], want[1], want[2]);
            double dz = in_a ? dist : dist + 0.3;
            float d = f.depth[(size_t)y * W + x];
            if (!(fabs(d - dz) <= 1e-3 * dz))
                fail_msg("%s, ewa=%s: pixel (%d, %d) depth %.6f, expected %.6f", label,
                         ewa_name(ewa), x, y, d, dz);
            in_a ? na++ : nb++;
        }
    assert_true(na > 5000 && nb > 5000);
    rnd_frame_free(&f);
    rnd_release(r, id);
}

static void test_two_planes(void **state)
{
    fixture *fx = *state;
    check_two_planes(fx->egl, "egl, float atomics", SP_EWA_SPLIT);
    check_two_planes(fx->egl, "egl, float atomics", SP_EWA_EXACT);
}

/* The same two tests through the fixed-point accumulation (GPUs without
 * GL_NV_shader_atomic_float) and through OSMesa. */
static void test_fixed_point_and_osmesa(void **state)
{
    (void)state;
    const rnd_pipe_opts fixed = {.splat_fixed = 1};
    rnd_ctx *r = make_ctx(RND_BACKEND_EGL, &fixed);
    assert_non_null(r);
    check_constant_colour(r, "egl, fixed point", SP_EWA_AUTO);
    check_two_planes(r, "egl, fixed point", SP_EWA_AUTO);
    /* The option takes effect: weights quantised to 1/255 give another image than the float
     * sums of the same jittered scene (with them ignored, the two would be equal). */
    rnd_ctx *rf = make_ctx(RND_BACKEND_EGL, NULL);
    assert_non_null(rf);
    enum { N = 60 };
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)N * N, 0);
    const uint8_t ca[3] = {200, 150, 50}, cb[3] = {50, 100, 200};
    grid(&pc, 0, N, N, 0.01f, 0, 0.013f, ca, cb, 7);
    tu_finish_cloud(&pc, OFF);
    uint32_t i1 = tu_upload(r, &pc), i2 = tu_upload(rf, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_at(0.02, -0.01, 0.6, 0, 0, 0, 60, W, H);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame f1 = {0}, f2 = {0};
    tu_render(r, i1, &cam, &p, 0, &f1);
    tu_render(rf, i2, &cam, &p, 0, &f2);
    assert_true(memcmp(f1.rgba8, f2.rgba8, (size_t)W * H * 4) != 0);
    rnd_frame_free(&f1);
    rnd_frame_free(&f2);
    rnd_destroy(rf);
    rnd_destroy(r);
    r = make_ctx(RND_BACKEND_OSMESA, NULL);
    assert_non_null(r);
    check_two_planes(r, "osmesa", SP_EWA_AUTO);
    rnd_destroy(r);
}

/* Stripes: with rnd_pipe_opts.splat_stripe_rows = 37 the frame is rendered 37 rows at a time (as frames
 * over the storage-block limit are, e.g. 4K on llvmpipe), each with a halo row for the 3x3
 * low-pass (split) or none (exact); the image must equal the one-stripe render: every channel within 1 (float atomics
 * add in a different order) and depth within 1e-6 relative. Jittered plane in both regimes and
 * a magnified inclined splat crossing stripe borders. */
static void test_stripes(void **state)
{
    fixture *fx = *state;
    const rnd_pipe_opts stripes = {.splat_stripe_rows = 37};
    rnd_ctx *rs = make_ctx(RND_BACKEND_EGL, &stripes);
    assert_non_null(rs);
    enum { N = 100 };
    const float h = 0.01f;
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)N * N + 1, 0);
    const uint8_t a[3] = {200, 150, 50}, b[3] = {50, 100, 200};
    grid(&pc, 0, N, N, h, 0, h * 1.3f, a, b, 7);
    uint64_t seed = 777;
    for (uint64_t i = 0; i < (uint64_t)N * N; i++) {
        pc.pos[3 * i] += 0.3f * h * rng_unit(&seed);
        pc.pos[3 * i + 1] += 0.3f * h * rng_unit(&seed);
        pc.pos[3 * i + 2] = 0.05f * sinf(20 * pc.pos[3 * i]);
    }
    uint64_t big = (uint64_t)N * N; /* one big tilted splat in front */
    pc.pos[3 * big] = 0.1f, pc.pos[3 * big + 1] = 0.05f, pc.pos[3 * big + 2] = 0.2f;
    pc.normal[3 * big + 1] = 0.6f, pc.normal[3 * big + 2] = 0.8f;
    pc.radius[big] = 0.15f;
    tu_finish_cloud(&pc, OFF);
    uint32_t id1 = tu_upload(fx->egl, &pc), id2 = tu_upload(rs, &pc);
    pc_prepared_free(&pc);
    const double dists[2] = {1.0, 0.35};
    for (int km = 0; km < 4; km++) { /* both distances, ewa split then exact */
        int k = km & 1;
        rnd_camera cam = cam_at(0.02, -0.01, dists[k], 0, 0, 0, 60, W, H);
        sp_params p;
        sp_params_defaults(&p);
        p.ewa = km < 2 ? SP_EWA_SPLIT : SP_EWA_EXACT;
        rnd_frame f1 = {0}, f2 = {0};
        tu_render(fx->egl, id1, &cam, &p, 1, &f1);
        tu_render(rs, id2, &cam, &p, 1, &f2);
        int maxd = 0, covered = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) {
            covered += !is_bg(f1.rgba8 + 4 * i);
            for (int c = 0; c < 3; c++) {
                int d = abs(f1.rgba8[4 * i + c] - f2.rgba8[4 * i + c]);
                if (d > maxd) maxd = d;
            }
            if (isinf(f1.depth[i]) != isinf(f2.depth[i]) ||
                (!isinf(f1.depth[i]) && fabsf(f1.depth[i] - f2.depth[i]) > 1e-6f * f1.depth[i]))
                fail_msg("ewa=%s, distance %.2f: depth of pixel %zu differs: %g vs %g",
                         ewa_name(p.ewa), dists[k], i, f1.depth[i], f2.depth[i]);
        }
        if (maxd > 1)
            fail_msg("ewa=%s, distance %.2f: striped render differs by %d", ewa_name(p.ewa),
                     dists[k], maxd);
        assert_true(covered > W * H / 4);
        rnd_frame_free(&f1);
        rnd_frame_free(&f2);
    }
    rnd_release(fx->egl, id1);
    rnd_release(rs, id2);
    rnd_destroy(rs);
}

/* Luminance mean and variance over a pixel rectangle; counts background pixels. */
static void region_stats(const rnd_frame *f, const int r[4], double *mean, double *var, int *bg)
{
    double s = 0, s2 = 0;
    int n = 0;
    *bg = 0;
    for (int y = r[1]; y <= r[3]; y++)
        for (int x = r[0]; x <= r[2]; x++) {
            const uint8_t *q = pix(f, x, y);
            double l = (q[0] + q[1] + q[2]) / 3.0;
            s += l, s2 += l * l, n++;
            *bg += is_bg(q);
        }
    *mean = s / n;
    *var = s2 / n - *mean * *mean;
}

/* EWA anti-aliasing: a black-and-white checkerboard (cells of 2 x 2 points, 0.02 units) seen at
 * a grazing angle. In the far region (4.5 to 8 units away, about 0.04 px per cell vertically)
 * the pattern is far above the Nyquist rate: without the low-pass (lowpass = 0) the discs are
 * point-sampled and the pixels alias to a noisy mix of black, white and misses; with lowpass 1
 * every pixel averages many splats. Asserts variance(lowpass 1) < 0.5 variance(lowpass 0) (0.5
 * is the brief's bound) and no background pixel in the region with the low-pass on (minified
 * splats never vanish), in both ewa modes. Measured ratios: split 0.008; exact 0.35, because
 * the depth-clamped fringes of nearer splats win visibility at this angle and a pixel blends
 * about one row of splats (see pipe_splat.c). */
static void test_ewa_antialiasing(void **state)
{
    fixture *fx = *state;
    enum { NX = 200, NY = 1000 };
    const float h = 0.01f;
    const uint8_t wh[3] = {240, 240, 240}, bk[3] = {20, 20, 20};
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)NX * NY, 0);
    grid(&pc, 0, NX, NY, h, 0, h, wh, bk, 2);
    for (uint64_t i = 0; i < pc.n; i++) pc.pos[3 * i + 1] += 0.5f * NY * h; /* y in [0, 10] */
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(fx->egl, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = cam_at(0, -0.5, 0.3, 0, 10, 0, 40, W, H);
    proj pj = proj_of(&cam);
    double sx0, sy0, sx1, sy1;
    project(&pj, -0.3, 4.5, 0, &sx0, &sy0, NULL);
    project(&pj, 0.3, 8.0, 0, &sx1, &sy1, NULL);
    int reg[4] = {(int)ceil(sx0) + 1, (int)ceil(sy0) + 1, (int)floor(sx1) - 2, (int)floor(sy1) - 2};
    assert_true(reg[2] - reg[0] >= 10 && reg[3] - reg[1] >= 4);
    sp_params p;
    sp_params_defaults(&p);
    rnd_frame f = {0};
    const int modes[2] = {SP_EWA_EXACT, SP_EWA_SPLIT};
    for (int m = 0; m < 2; m++) {
        double mean[2], var[2];
        int bg[2];
        p.ewa = modes[m];
        for (int k = 0; k < 2; k++) {
            p.lowpass = k ? 1.0f : 0.0f;
            tu_render(fx->egl, id, &cam, &p, 0, &f);
            region_stats(&f, reg, &mean[k], &var[k], &bg[k]);
        }
        printf("anti-aliasing, ewa=%s: region %dx%d px, mean %.1f / %.1f, variance %.1f "
               "(lowpass 0) vs %.1f (lowpass 1), background pixels %d vs %d\n",
               ewa_name(modes[m]), reg[2] - reg[0] + 1, reg[3] - reg[1] + 1, mean[0], mean[1],
               var[0], var[1], bg[0], bg[1]);
        assert_true(var[1] < 0.5 * var[0]);
        assert_int_equal(bg[1], 0);
    }
    rnd_frame_free(&f);
    rnd_release(fx->egl, id);
}

/* A single disc tilted by theta = 60 degrees about the x axis, seen head-on from a distance
 * (fov 20, so the projection is nearly affine): its covered pixels form an ellipse whose minor
 * (y) to major (x) axis ratio is cos(theta) = 0.5. Measured by the second moments of the
 * coverage mask (a uniform ellipse with semi-axes a, b has m_xx = a^2 / 4, m_yy = b^2 / 4), so
 * aspect = sqrt(m_yy / m_xx); tolerance 10 % (the brief's; pixel quantisation of a 6 px disc
 * and, for the big one, the one-pixel low-pass rim stay well inside it). Two sizes: a 6 px
 * radius (one invocation loops over its box; lowpass 0, the pure disc) and a 25 px radius
 * (the big-splat path of 8x8 work groups; default lowpass 1). The major semi-axis must also
 * equal the projected radius within 10 %. Both ewa modes. */
static void test_inclined_footprint(void **state)
{
    fixture *fx = *state;
    const double theta = 60 * M_PI / 180, dist = 10;
    const double px_per_unit = H / (2 * dist * tan(10 * M_PI / 180));
    const double radius_px[2] = {6, 25};
    for (int km = 0; km < 4; km++) {
        int k = km & 1, ewa = km < 2 ? SP_EWA_EXACT : SP_EWA_SPLIT;
        pc_prepared pc;
        tu_new_cloud(&pc, 1, 0);
        pc.normal[0] = 0, pc.normal[1] = (float)sin(theta), pc.normal[2] = (float)cos(theta);
        pc.radius[0] = (float)(radius_px[k] / px_per_unit);
        tu_finish_cloud(&pc, OFF);
        uint32_t id = tu_upload(fx->egl, &pc);
        pc_prepared_free(&pc);
        rnd_camera cam = cam_at(0, 0, dist, 0, 0, 0, 20, W, H);
        sp_params p;
        sp_params_defaults(&p);
        p.lowpass = k ? 1.0f : 0.0f;
        p.ewa = ewa;
        rnd_frame f = {0};
        tu_render(fx->egl, id, &cam, &p, 0, &f);
        double n = 0, mx = 0, my = 0, mxx = 0, myy = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                if (!is_bg(pix(&f, x, y))) n++, mx += x, my += y;
        assert_true(n > 10);
        mx /= n, my /= n;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                if (!is_bg(pix(&f, x, y))) mxx += (x - mx) * (x - mx), myy += (y - my) * (y - my);
        mxx /= n, myy /= n;
        double aspect = sqrt(myy / mxx), major = 2 * sqrt(mxx);
        printf("footprint ewa=%s, r = %.0f px: %0.f pixels, major semi-axis %.2f px, aspect "
               "%.4f (cos theta = %.4f)\n", ewa_name(ewa), radius_px[k], n, major, aspect,
               cos(theta));
        assert_true(fabs(aspect - cos(theta)) <= 0.1 * cos(theta));
        assert_true(fabs(major - radius_px[k]) <= 0.1 * radius_px[k]);
        rnd_frame_free(&f);
        rnd_release(fx->egl, id);
    }
}

/* IEEE half to float (the rgba16f read-back). */
static float half_to_float(uint16_t h)
{
    int e = (h >> 10) & 31, m = h & 1023;
    float v = e == 0 ? ldexpf((float)m, -24) : e == 31 ? INFINITY : ldexpf((float)(m | 1024), e - 25);
    return (h & 0x8000) ? -v : v;
}

/* The weight scene: one huge green splat (radius 2000 px, so its weight is 1 - 1e-3 over the
 * area used) and G x G small red splats of radius 1.6 px (sigma 0.8 px: minified, split mode
 * would deposit them), all in the plane z = 0 facing a camera 10 units away (fov 20), 16.25 px
 * apart so that their centres take G x G different sub-pixel positions. Every covered pixel
 * normalises to (w_s, w_b, 0) / (w_s + w_b), so red / green = w_s / w_b is the small splat's
 * EWA weight at that pixel. Returns the cloud id; fills cam and the view (for splat_math). */
enum { MOM_G = 4 };
static uint32_t weight_scene(rnd_ctx *r, rnd_camera *cam, rnd_view *v, float *r_small)
{
    const double dist = 10, px_per_unit = H / (2 * dist * tan(10 * M_PI / 180));
    pc_prepared pc;
    tu_new_cloud(&pc, MOM_G * MOM_G + 1, 0);
    pc.radius[0] = (float)(2000 / px_per_unit);
    pc.rgba[0] = 0, pc.rgba[2] = 0;
    *r_small = (float)(1.6 / px_per_unit);
    for (int j = 0; j < MOM_G; j++)
        for (int i = 0; i < MOM_G; i++) {
            int k = 1 + j * MOM_G + i;
            pc.pos[3 * k] = (float)((i - 1.5) * 16.25 / px_per_unit);
            pc.pos[3 * k + 1] = (float)((j - 1.5) * 16.25 / px_per_unit);
            pc.radius[k] = *r_small;
            pc.rgba[4 * k + 1] = 0, pc.rgba[4 * k + 2] = 0;
        }
    tu_finish_cloud(&pc, OFF);
    *cam = cam_at(0, 0, dist, 0, 0, 0, 20, W, H);
    float lmin[3], lmax[3];
    for (int k = 0; k < 3; k++) lmin[k] = (float)(pc.bmin[k] - OFF[k]), lmax[k] = (float)(pc.bmax[k] - OFF[k]);
    sd_err err = {0};
    if (rnd__view_setup(cam, OFF, lmin, lmax, v, &err) < 0) fail_msg("view: %s", err.msg);
    uint32_t id = tu_upload(r, &pc);
    pc_prepared_free(&pc);
    return id;
}

/* ewa=exact, second moments of minified splats: each small splat's weights w = red / green
 * (weight_scene) around its analytic centre must have the second moments of the resampling
 * filter V = J V_r J^T + I computed by splat_footprint_compute (splat_math.c, lowpass 1): here
 * V_xx = V_yy = 0.64 + 1 px^2. A Gaussian cut off at x^T V^-1 x <= 4 has covariance c V with
 * c = 1 - 2 e^-2 / (1 - e^-2) = 0.687 (|x|^2 of a whitened 2-D Gaussian is exponential with
 * mean 2, truncated at 4). Pooling the 16 splats at 16 sub-pixel offsets averages out the
 * pixel grid (one splat alone is off by up to 12 %, computed). Tolerance 15 % (the brief's;
 * measured within 2 %): the low-pass missing (0.64) or J V_r J^T missing (1.0) is 39-61 % off,
 * and split mode's deposit + 3x3 blur is further still. Also: each splat's weighted mean lies
 * within 0.1 px of the analytic centre. */
static void test_exact_footprint_moments(void **state)
{
    fixture *fx = *state;
    rnd_camera cam;
    rnd_view v;
    float rs;
    uint32_t id = weight_scene(fx->egl, &cam, &v, &rs);
    sp_params p;
    sp_params_defaults(&p);
    p.ewa = SP_EWA_EXACT;
    p.light[0] = 0, p.light[1] = 0, p.light[2] = 1;
    rnd_frame f = {0};
    tu_render(fx->egl, id, &cam, &p, 1, &f);
    assert_non_null(f.rgba16f);
    double sw = 0, sxx = 0, syy = 0, vxx = 0, vyy = 0;
    for (int k = 1; k <= MOM_G * MOM_G; k++) {
        int i = (k - 1) % MOM_G, j = (k - 1) / MOM_G;
        const double ppu = H / (2 * 10 * tan(10 * M_PI / 180));
        const float pos[3] = {(float)((i - 1.5) * 16.25 / ppu), (float)((j - 1.5) * 16.25 / ppu), 0};
        const float nrm[3] = {0, 0, 1};
        splat_footprint fp;
        assert_int_equal(splat_footprint_compute(v.view, v.proj, W, H, pos, nrm, rs, 1.0f, v.znear, &fp), 1);
        vxx = fp.cov[0], vyy = fp.cov[2];
        double w0 = 0, mx = 0, my = 0;
        for (int y = (int)fp.ctr[1] - 6; y <= (int)fp.ctr[1] + 6; y++)
            for (int x = (int)fp.ctr[0] - 6; x <= (int)fp.ctr[0] + 6; x++) {
                const uint16_t *q = f.rgba16f + 4 * ((size_t)y * W + x);
                float red = half_to_float(q[0]), green = half_to_float(q[1]);
                if (!(green > 0) || !(red > 0)) continue;
                double w = red / green, dx = x + 0.5 - fp.ctr[0], dy = y + 0.5 - fp.ctr[1];
                w0 += w, mx += w * dx, my += w * dy;
                sw += w, sxx += w * dx * dx, syy += w * dy * dy;
            }
        assert_true(w0 > 0);
        if (!(fabs(mx / w0) < 0.1 && fabs(my / w0) < 0.1))
            fail_msg("splat %d: weighted mean (%+.3f, %+.3f) px from the analytic centre", k, mx / w0, my / w0);
    }
    const double c = 1 - 2 * exp(-2) / (1 - exp(-2));
    double mxx = sxx / sw / c, myy = syy / sw / c;
    printf("exact footprint: V from splat_math xx %.4f yy %.4f px^2, measured (truncation "
           "corrected) xx %.4f yy %.4f\n", vxx, vyy, mxx, myy);
    assert_true(fabs(mxx - vxx) <= 0.15 * vxx);
    assert_true(fabs(myy - vyy) <= 0.15 * vyy);
    rnd_frame_free(&f);
    rnd_release(fx->egl, id);
}

/* ---- tilted, off-axis footprints against the finite-difference Jacobian of the projection ---- */

/* Pixel position of local point q through projection p (as `project`), or, with dfix > 0, with
 * the divide by the eye depth frozen at dfix: the affine projection whose Jacobian lacks the
 * perspective term (what splat_raster.comp computes when that term is dropped). */
static void project_px(const proj *p, const double q[3], double dfix, double out[2])
{
    double a[3] = {q[0] - p->e[0], q[1] - p->e[1], q[2] - p->e[2]};
    double xe = a[0] * p->s[0] + a[1] * p->s[1] + a[2] * p->s[2];
    double ye = a[0] * p->u[0] + a[1] * p->u[1] + a[2] * p->u[2];
    double de = dfix > 0 ? dfix : a[0] * p->f[0] + a[1] * p->f[1] + a[2] * p->f[2];
    out[0] = (xe * p->t / p->aspect / de + 1) * 0.5 * p->w;
    out[1] = (ye * p->t / de + 1) * 0.5 * p->h;
}

/* A splat's predicted EWA footprint: centre (pixels), resampling filter V = J V_r J^T + V_h
 * (xx, xy, yy, px^2) and Q = V^-1. */
typedef struct ewa_pred {
    double ctr[2], v[3], q[3];
} ewa_pred;

/* The footprint of the disc at local c with unit normal n and radius r, with V_h = lowpass I:
 * J = d(pixel)/d(u, v) along an orthonormal tangent basis (u, v) of the disc, by central
 * differences of the projection over offsets of 1e-4 r (truncation and rounding errors under
 * 1e-7 relative), computed here and not with splat_math.c; V_r = (r / 2)^2 I, the disc's
 * rim being the 2-sigma contour (the project's convention: splat_raster.comp, DESIGN.md).
 * affine != 0: the Jacobian of the affine projection instead (perspective term dropped). */
static ewa_pred ewa_predict(const proj *pj, const double c[3], const double n[3], double r,
                            double lowpass, int affine)
{
    ewa_pred e;
    double dc;
    project(pj, c[0], c[1], c[2], &e.ctr[0], &e.ctr[1], &dc);
    double a[3] = {fabs(n[0]) < 0.9 ? 1 : 0, fabs(n[0]) < 0.9 ? 0 : 1, 0}, t[2][3];
    double an = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
    for (int i = 0; i < 3; i++) t[0][i] = a[i] - an * n[i];
    vnorm(t[0]);
    t[1][0] = n[1] * t[0][2] - n[2] * t[0][1];
    t[1][1] = n[2] * t[0][0] - n[0] * t[0][2];
    t[1][2] = n[0] * t[0][1] - n[1] * t[0][0];
    const double h = 1e-4 * r;
    double j[2][2]; /* j[k] = d(pixel) / d(tangent k) */
    for (int k = 0; k < 2; k++) {
        double qp[3], qm[3], pp[2], pm[2];
        for (int i = 0; i < 3; i++) qp[i] = c[i] + h * t[k][i], qm[i] = c[i] - h * t[k][i];
        project_px(pj, qp, affine ? dc : 0, pp);
        project_px(pj, qm, affine ? dc : 0, pm);
        for (int i = 0; i < 2; i++) j[k][i] = (pp[i] - pm[i]) / (2 * h);
    }
    double s2 = 0.25 * r * r;
    e.v[0] = s2 * (j[0][0] * j[0][0] + j[1][0] * j[1][0]) + lowpass;
    e.v[1] = s2 * (j[0][0] * j[0][1] + j[1][0] * j[1][1]);
    e.v[2] = s2 * (j[0][1] * j[0][1] + j[1][1] * j[1][1]) + lowpass;
    double det = e.v[0] * e.v[2] - e.v[1] * e.v[1];
    e.q[0] = e.v[2] / det, e.q[1] = -e.v[1] / det, e.q[2] = e.v[0] / det;
    return e;
}

/* The direction of the eye ray through ndc point (nx, ny), scaled to a unit component along the
 * view direction (so the ray parameter is the eye depth). */
static void ray_dir(const proj *p, double nx, double ny, double d[3])
{
    for (int i = 0; i < 3; i++)
        d[i] = p->f[i] + p->s[i] * nx * p->aspect / p->t + p->u[i] * ny / p->t;
}

/* How far covariance m is from the reference v: the largest of |m_xx - v_xx| / v_xx,
 * |m_yy - v_yy| / v_yy and |m_xy - v_xy| / sqrt(v_xx v_yy). */
static double cov_err(const double m[3], const double v[3])
{
    double exx = fabs(m[0] - v[0]) / v[0], eyy = fabs(m[2] - v[2]) / v[2];
    return fmax(fmax(exx, eyy), fabs(m[1] - v[1]) / sqrt(v[0] * v[2]));
}

/* x^T Q x of pixel centre (x, y) for footprint e. */
static double ewa_q(const ewa_pred *e, int x, int y)
{
    double dx = x + 0.5 - e->ctr[0], dy = y + 0.5 - e->ctr[1];
    return e->q[0] * dx * dx + 2 * e->q[1] * dx * dy + e->q[2] * dy * dy;
}

/* Weighted moments of a footprint about a fixed origin (the predicted centre). */
typedef struct moments {
    double w, x, y, xx, xy, yy;
} moments;

static void mom_add(moments *m, double w, double dx, double dy)
{
    m->w += w, m->x += w * dx, m->y += w * dy;
    m->xx += w * dx * dx, m->xy += w * dx * dy, m->yy += w * dy * dy;
}

/* Centroid (relative to the origin) and covariance (xx, xy, yy) of m. */
static void mom_final(const moments *m, double ctr[2], double cov[3])
{
    ctr[0] = m->x / m->w, ctr[1] = m->y / m->w;
    cov[0] = m->xx / m->w - ctr[0] * ctr[0];
    cov[1] = m->xy / m->w - ctr[0] * ctr[1];
    cov[2] = m->yy / m->w - ctr[1] * ctr[1];
}

/* Tilted, off-axis splats in ewa=exact: what splat_raster.comp computes (its Jacobian, with
 * the perspective term, the low-pass, the cut-off, the sampling at pixel centres) against the
 * footprint the test predicts from its own finite-difference Jacobian (ewa_predict).
 *
 * Scene: a camera with a wide fov (90) at local (0, 0, 1) looking at the origin, and a plane
 * through the origin tilted by theta from the view axis towards azimuth phi. In it, nine red
 * splats near the frame's edges and corners (ndc +-0.7 to +-0.86): four magnified (radius 12 px
 * for a facing disc at that depth: boxes over SPLAT_BIG_PIXELS, the 8x8 work-group path) and
 * five of 2-3 px, for which the one-pixel low-pass is 20-90 % of V's diagonal (the per-splat
 * loop). Behind
 * them, in the same plane and centred on the axis, a green reference disc so large (20000 px)
 * that its weight is 1 to within 0.5 % over the frame (the test divides it out with its own
 * prediction). Every pixel of a red footprint then normalises to (w_s, w_b, 0) / (w_s + w_b)
 * times the shading (the same normal for both, so the same factor), and red / green is the red
 * splat's EWA weight w_s at that pixel. Coplanar depths are equal (to float rounding), so both
 * splats pass the depth test everywhere; the geometry keeps every footprint pixel's plane
 * depth from being nearer than dc - 2r (checked below), away from the shader's clamp of a
 * fragment's depth to dc +- r, which at grazing angles drops a fringe pixel whose plane depth
 * is more than eps * r = r nearer than the clamped one (pipe_splat.c; seen with a 3 px splat
 * at 82 degrees from its normal: one pixel missing, moments 3 % off).
 *
 * Checks, per splat, against the prediction sampled at the same pixel centres within the same
 * cut-off x^T V^-1 x <= 4 (so pixel quantisation, the truncation of the Gaussian and, through
 * V, the low-pass are modelled, not tolerated):
 *  - coverage: every pixel with q < 4 (1 - 1e-3) is covered, none with q > 4 (1 + 1e-3), and
 *    no red pixel lies outside the splats' windows (1e-3: the shader's float conic and the
 *    test's matrices differ by ~1e-6 relative, the band holds a few pixels at most);
 *  - the weight-normalised centroid within 0.02 px of the sampled prediction's;
 *  - the weighted covariance within 1 % (xx, yy relative; xy relative to sqrt(xx yy));
 *  - red + green equals the shading factor measured on the axis (where only green is) within
 *    0.5 %: the resolve divides by the weight sum (unnormalised, it is w_s + w_b, up to 2).
 * Tolerances: what remains is rounding. The RGBA16F read-back holds red and green to 2^-11
 * relative each (a ratio to ~1e-3 per pixel, averaging out over a footprint), the reference
 * weight is predicted to far better than its 0.5 % deviation from 1, the central differences
 * are exact to 1e-7. Measured: covariance within 0.013 %, centroid within 0.0002 px, sum within
 * 0.06 %, no coverage mismatch (through the fixed-point sums, rnd_pipe_opts.splat_fixed, whose
 * weights are quantised to 1/255: 0.12 %, 0.003 px). The affine Jacobian (the perspective term
 * dropped) predicts footprints 23-205 % off the perspective ones here (printed as "affine gap";
 * asserted >= 10 % for every splat, ten times the tolerance). Mutations of the shaders, each
 * failing this test (worst covariance error; coverage mismatches): the perspective term of J
 * dropped 203 % (1683 pixels), dropped in x only 107 %, two entries of J swapped (J^T) 93 %,
 * no low-pass V_h 71 % (287 pixels), samples at pixel corners instead of centres 22 % and
 * 0.55 px, cut-off at 3 sigma instead of 2 35 %, no division by the weight sum (the sum check:
 * 100 % off; the ratios are blind to it), pass 2's depth test with -eps (nothing accumulated). */
enum { TILT_NS = 9 };
typedef struct tilt_result {
    double worst_cov, worst_ctr, worst_sum, min_gap;
    int holes, excess, stray;
} tilt_result;

static void check_tilted_plane(rnd_ctx *rc, double th_deg, double ph_deg, tilt_result *res)
{
    rnd_camera cam = cam_at(0, 0, 1, 0, 0, 0, 90, W, H);
    proj pj = proj_of(&cam);
    const double th = th_deg * M_PI / 180, ph = ph_deg * M_PI / 180;
    const double np[3] = {sin(th) * cos(ph), sin(th) * sin(ph), cos(th)};
    /* The centre's ndc x and y, and the radius in pixels a disc facing the camera at the
     * centre's depth would have. */
    static const double spl[TILT_NS][3] = {
        {0.70, 0.70, 12}, {0.70, -0.70, 12}, {-0.70, 0.70, 12}, {-0.70, -0.70, 12},
        {-0.86, -0.25, 3}, {-0.86, 0.05, 2.5}, {-0.86, 0.35, 2}, {0.86, -0.15, 3}, {0.86, 0.2, 2}};
    double c[TILT_NS + 1][3], r[TILT_NS + 1];
    c[0][0] = c[0][1] = c[0][2] = 0; /* the reference disc: depth 1 */
    r[0] = 20000 * 2.0 / (H * pj.t);
    double ne = np[0] * pj.e[0] + np[1] * pj.e[1] + np[2] * pj.e[2];
    for (int k = 1; k <= TILT_NS; k++) {
        /* The ray through the ndc point met with the plane np . x = 0. */
        double d[3];
        ray_dir(&pj, spl[k - 1][0], spl[k - 1][1], d);
        double nd = np[0] * d[0] + np[1] * d[1] + np[2] * d[2];
        assert_true(nd < 0);
        double lam = -ne / nd;
        for (int i = 0; i < 3; i++) c[k][i] = pj.e[i] + lam * d[i];
        r[k] = spl[k - 1][2] * 2 * lam / (H * pj.t);
    }
    pc_prepared pc;
    tu_new_cloud(&pc, TILT_NS + 1, 0);
    for (int k = 0; k <= TILT_NS; k++) {
        for (int i = 0; i < 3; i++)
            pc.pos[3 * k + i] = (float)c[k][i], pc.normal[3 * k + i] = (float)np[i];
        pc.radius[k] = (float)r[k];
        pc.rgba[4 * k + 0] = k ? 255 : 0, pc.rgba[4 * k + 1] = k ? 0 : 255, pc.rgba[4 * k + 2] = 0;
    }
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(rc, &pc);
    pc_prepared_free(&pc);
    sp_params p;
    sp_params_defaults(&p);
    p.ewa = SP_EWA_EXACT;
    p.light[0] = 0, p.light[1] = 0, p.light[2] = 1;
    rnd_frame f = {0};
    tu_render(rc, id, &cam, &p, 1, &f);
    assert_non_null(f.rgba16f);
    const double lp = p.lowpass, sc = p.splat_scale;
    ewa_pred ref = ewa_predict(&pj, c[0], np, r[0] * sc, lp, 0);
    const uint16_t *q0 = f.rgba16f + 4 * ((size_t)(H / 2) * W + W / 2);
    double shade = half_to_float(q0[0]) + half_to_float(q0[1]);
    if (!(half_to_float(q0[0]) == 0 && shade > 0.2))
        fail_msg("tilt (%.0f, %.0f): the pixel on the axis is not the reference disc's shaded "
                 "green: red %g, green %g", th_deg, ph_deg, half_to_float(q0[0]),
                 half_to_float(q0[1]));
    static unsigned char owned[W * H];
    memset(owned, 0, sizeof owned);
    for (int k = 1; k <= TILT_NS; k++) {
        ewa_pred e = ewa_predict(&pj, c[k], np, r[k] * sc, lp, 0);
        ewa_pred ea = ewa_predict(&pj, c[k], np, r[k] * sc, lp, 1);
        double sx, sy, dc;
        project(&pj, c[k][0], c[k][1], c[k][2], &sx, &sy, &dc);
        /* Window: twice the cut-off ellipse's box (of either Jacobian) plus 3 px. */
        int win[4];
        for (int a = 0; a < 2; a++) {
            double ext = 4 * fmax(sqrt(e.v[2 * a]), sqrt(ea.v[2 * a])) + 3;
            win[a] = (int)floor(e.ctr[a] - ext), win[2 + a] = (int)ceil(e.ctr[a] + ext);
        }
        win[0] = win[0] < 0 ? 0 : win[0], win[1] = win[1] < 0 ? 0 : win[1];
        win[2] = win[2] >= W ? W - 1 : win[2], win[3] = win[3] >= H ? H - 1 : win[3];
        moments mm = {0}, mp = {0};
        for (int y = win[1]; y <= win[3]; y++)
            for (int x = win[0]; x <= win[2]; x++) {
                if (owned[y * W + x])
                    fail_msg("tilt (%.0f, %.0f): splat %d's window overlaps another at (%d, %d)",
                             th_deg, ph_deg, k, x, y);
                owned[y * W + x] = 1;
                const uint16_t *q = f.rgba16f + 4 * ((size_t)y * W + x);
                double red = half_to_float(q[0]), green = half_to_float(q[1]);
                double qb = ewa_q(&ref, x, y), qs = ewa_q(&e, x, y);
                assert_true(qb < 0.01); /* reference weight >= 0.995 */
                double dx = x + 0.5 - e.ctr[0], dy = y + 0.5 - e.ctr[1];
                if (qs <= 4) {
                    mom_add(&mp, exp(-0.5 * qs), dx, dy);
                    /* The geometry stays clear of the depth clamp (see above): the plane's
                     * depth along this pixel's ray is not under dc - 2r. */
                    double rd[3];
                    ray_dir(&pj, (x + 0.5) / W * 2 - 1, (y + 0.5) / H * 2 - 1, rd);
                    double nd = np[0] * rd[0] + np[1] * rd[1] + np[2] * rd[2];
                    if (!(-ne / nd > dc - 2 * r[k] * sc))
                        fail_msg("tilt (%.0f, %.0f): splat %d too oblique for this test at "
                                 "(%d, %d)", th_deg, ph_deg, k, x, y);
                }
                if (red > 0) {
                    assert_true(green > 0);
                    mom_add(&mm, red / green * exp(-0.5 * qb), dx, dy);
                }
                if (qs < 4 * (1 - 1e-3) && !(red > 0)) res->holes++;
                if (qs > 4 * (1 + 1e-3) && red > 0) res->excess++;
                double ds = fabs((red + green) / shade - 1);
                if (ds > res->worst_sum) res->worst_sum = ds;
            }
        if (!(mm.w > 0)) fail_msg("tilt (%.0f, %.0f): splat %d left no weight", th_deg, ph_deg, k);
        double pctr[2], pv[3], mctr[2], mv[3];
        mom_final(&mp, pctr, pv);
        mom_final(&mm, mctr, mv);
        double dcov = cov_err(mv, pv), gap = cov_err(ea.v, e.v);
        double dctr = fmax(fabs(mctr[0] - pctr[0]), fabs(mctr[1] - pctr[1]));
        printf("tilt (%.0f, %.0f) splat %d at (%.1f, %.1f) px: V = J V_r J^T + I %.2f %+.2f %.2f "
               "(affine J: %.2f %+.2f %.2f, gap %.0f %%); sampled, cut off: predicted %.3f %+.3f "
               "%.3f, rendered %.3f %+.3f %.3f (%.3f %%), centroid %.4f px off\n",
               th_deg, ph_deg, k, sx, sy, e.v[0], e.v[1], e.v[2], ea.v[0], ea.v[1], ea.v[2],
               100 * gap, pv[0], pv[1], pv[2], mv[0], mv[1], mv[2], 100 * dcov, dctr);
        res->worst_cov = fmax(res->worst_cov, dcov);
        res->worst_ctr = fmax(res->worst_ctr, dctr);
        res->min_gap = fmin(res->min_gap, gap);
    }
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            res->stray += !owned[y * W + x] && f.rgba16f[4 * ((size_t)y * W + x)] != 0;
    rnd_frame_free(&f);
    rnd_release(rc, id);
}

static void test_tilted_footprints(void **state)
{
    fixture *fx = *state;
    tilt_result res = {.min_gap = INFINITY};
    check_tilted_plane(fx->egl, 35, 30, &res);
    check_tilted_plane(fx->egl, 40, 250, &res);
    printf("tilted footprints: worst covariance %.3f %%, centroid %.4f px, red + green %.4f off "
           "the shading, coverage: %d holes, %d excess, %d stray; smallest affine gap %.0f %%\n",
           100 * res.worst_cov, res.worst_ctr, res.worst_sum, res.holes, res.excess, res.stray,
           100 * res.min_gap);
    if (!(res.min_gap >= 0.1))
        fail_msg("the geometry no longer tells the perspective and affine Jacobians apart");
    if (res.holes || res.excess || res.stray)
        fail_msg("coverage differs from the predicted cut-off ellipses");
    if (!(res.worst_ctr <= 0.02)) fail_msg("a centroid is off by more than 0.02 px");
    if (!(res.worst_cov <= 0.01)) fail_msg("a covariance is off by more than 1 %%");
    if (!(res.worst_sum <= 0.005))
        fail_msg("a footprint pixel is not normalised by its weight sum");
}

/* ewa=auto: on a software renderer (llvmpipe, softpipe, swrast in the renderer string) the
 * frame equals ewa=split's (every channel within 1: float atomics add in varying order) and
 * differs from ewa=exact's (the small splats' weights differ by far more than 1/255); on a
 * hardware GPU the other way round. */
static void test_ewa_auto(void **state)
{
    fixture *fx = *state;
    rnd_camera cam;
    rnd_view v;
    float rs;
    uint32_t id = weight_scene(fx->egl, &cam, &v, &rs);
    const char *ren = rnd_renderer_string(fx->egl);
    int software = strstr(ren, "llvmpipe") || strstr(ren, "softpipe") || strstr(ren, "swrast");
    sp_params p;
    sp_params_defaults(&p);
    assert_int_equal(p.ewa, SP_EWA_AUTO);
    rnd_frame f[3] = {{0}, {0}, {0}};
    const int modes[3] = {SP_EWA_AUTO, SP_EWA_SPLIT, SP_EWA_EXACT};
    for (int m = 0; m < 3; m++) {
        p.ewa = modes[m];
        tu_render(fx->egl, id, &cam, &p, 0, &f[m]);
    }
    int d[3] = {0, 0, 0}; /* max difference of auto against split and exact */
    for (size_t i = 0; i < (size_t)4 * W * H; i++)
        for (int m = 1; m < 3; m++) {
            int dd = abs(f[0].rgba8[i] - f[m].rgba8[i]);
            if (dd > d[m]) d[m] = dd;
        }
    printf("ewa=auto on %s (%s): max difference %d from split, %d from exact\n", ren,
           software ? "software" : "hardware", d[1], d[2]);
    int same = software ? 1 : 2, other = software ? 2 : 1;
    assert_true(d[same] <= 1);
    assert_true(d[other] > 10);
    for (int m = 0; m < 3; m++) rnd_frame_free(&f[m]);
    rnd_release(fx->egl, id);
}

/* ---- a real scan ---- */

/* Culling that leaves several ranges: five batches of 64 x 64 points, three plane patches in
 * view (batches 0, 2, 4) and two far outside it (1, 3), so the visible points are three
 * separate ranges and the shaders map visible indices to points through the range table
 * (lib_ranges.glsl). Each pipeline must draw exactly what it draws for a cloud of the three
 * visible patches alone (one range): the same covered pixels, colours within 1/255 (float
 * atomics add in a different order). */
static void test_culled_ranges(void **state)
{
    fixture *fx = *state;
    enum { SIDE = 64 };
    const float h = 0.004f;
    const uint8_t cols[5][3] = {{220, 40, 40}, {0, 0, 0}, {40, 220, 40}, {0, 0, 0}, {40, 40, 220}};
    const float xs[5] = {-0.27f, 50.0f, 0.0f, -50.0f, 0.27f};
    pc_prepared both[2];
    for (int v = 0; v < 2; v++) {
        uint64_t nb = v == 0 ? 5 : 3, b = 0;
        tu_new_cloud(&both[v], nb * SIDE * SIDE, 0);
        for (int k = 0; k < 5; k++) {
            if (v == 1 && (k == 1 || k == 3)) continue;
            uint64_t first = b * SIDE * SIDE;
            grid(&both[v], first, SIDE, SIDE, h, 0, h * 1.2f, cols[k], cols[k], 0);
            for (uint64_t q = first; q < first + SIDE * SIDE; q++) both[v].pos[3 * q] += xs[k];
            b++;
        }
        tu_finish_cloud(&both[v], OFF);
        assert_int_equal(both[v].nbatches, nb);
    }
    rnd_camera cam = cam_at(0, 0, 1.2, 0, 0, 0, 40, W, H);
    for (int pipe = 0; pipe < 2; pipe++) {
        sp_params p;
        sp_params_defaults(&p);
        p.pipeline = pipe == 0 ? SP_PIPE_POINTS : SP_PIPE_SPLAT;
        rnd_frame f[2] = {{0}, {0}};
        for (int v = 0; v < 2; v++) {
            uint32_t id = tu_upload(fx->egl, &both[v]);
            tu_render(fx->egl, id, &cam, &p, 0, &f[v]);
            rnd_release(fx->egl, id);
        }
        assert_int_equal(f[0].points_drawn, 3 * SIDE * SIDE);
        assert_int_equal(f[1].points_drawn, 3 * SIDE * SIDE);
        int covered = 0, coverage_differs = 0, maxdiff = 0, hues = 0;
        for (int i = 0; i < W * H; i++) {
            const uint8_t *a = f[0].rgba8 + 4 * i, *c = f[1].rgba8 + 4 * i;
            covered += !is_bg(a);
            coverage_differs += is_bg(a) != is_bg(c);
            for (int k = 0; k < 3; k++)
                if (abs(a[k] - c[k]) > maxdiff) maxdiff = abs(a[k] - c[k]);
        }
        for (int k = 0; k < 5; k += 2) /* each patch shows, in its own colour, at its centre */
            for (int i = 0; i < W * H; i++) {
                const uint8_t *a = f[0].rgba8 + 4 * i;
                int dom = cols[k][0] > 100 ? 0 : cols[k][1] > 100 ? 1 : 2;
                if (!is_bg(a) && a[dom] > 2 * a[(dom + 1) % 3] && a[dom] > 2 * a[(dom + 2) % 3]) {
                    hues++;
                    break;
                }
            }
        printf("culled ranges, %s: %d pixels covered, coverage differs at %d, max difference %d\n",
               pipe == 0 ? "points" : "splat", covered, coverage_differs, maxdiff);
        assert_true(covered > W * H / 20);
        assert_int_equal(coverage_differs, 0);
        assert_true(maxdiff <= 1);
        assert_int_equal(hues, 3);
        rnd_frame_free(&f[0]);
        rnd_frame_free(&f[1]);
    }
    pc_prepared_free(&both[0]);
    pc_prepared_free(&both[1]);
}

/* Golden images: the lowest PSNR over covered pixels accepted. Measured on llvmpipe (LLVM 15,
 * Mesa's EGL device), PSNR over covered pixels of each frame against its golden:
 *   view (a), default camera: 8-bit frames 68.57 dB, float-target frames 78.67 dB (the golden
 *     was made through the float target, before 8-bit frames rendered straight into RGBA8);
 *   view (b), close-up, ewa=exact: 8-bit inf (identical), float target 67.17 dB;
 *   identical to 0.01 dB in 5 separate processes, with LP_NUM_THREADS 1 to 16, with
 *   LP_NATIVE_VECTOR_WIDTH=128 (other LLVM code) and in the ASan build: the float atomics'
 *   order changed nothing here, the spread is the 8-bit vs float path's 1/255 rounding;
 *   the fixed-point sums (rnd_pipe_opts.splat_fixed, weights quantised to 1/255, a much coarser
 *   arithmetic than any driver's rounding): >= 66.04 dB.
 * 67.17 dB means 1.25 % of the covered channel values off by one (PSNR = 48.13 dB -
 * 10 log10(fraction off by one)); 60 dB allows 6.5 %, five times that, and lies 6 dB under
 * the lowest value measured. Shader mutations give, in view (b): the perspective term of the
 * Jacobian dropped 34.6 dB (in x only 37.2), two Jacobian entries swapped 34.8, no low-pass
 * 32.2, samples at pixel corners 36.0, cut-off at 3 sigma 34.6, no normalisation 12.1: all
 * 23 dB or more under the bound. View (a)'s splats are minified (split mode deposits most of
 * them), so footprint shape barely shows there: the same mutations give 67.1-68.4 dB (8-bit),
 * which no bound above the rounding spread can reject; it guards the whole image (no
 * normalisation: 6.2 dB) and view (b) the footprints. */
#define GOLDEN_MIN_DB 60.0

/* Guanyin (238k points, colours, no normals): loaded, preprocessed (normals, radii), rendered
 * in two views: (a) the default framing camera at 640x480 with the default parameters (ewa=auto:
 * split on llvmpipe; splats mostly minified, 16 % of the frame covered), and (b) a close-up of
 * the face at 320x240, fov 70, ewa=exact, the eye about 0.08 units from the surface, so splats
 * are 5-10 px in radius and, towards the frame's edges, seen well off the axis: the footprints'
 * Jacobians (the perspective term included) shape the image. Each view: non-blank, the same on
 * a second frame (every channel within 1: float atomics add in a different order per run), the
 * same through the float target (RGBA16F, copied to RGBA8; within 1, the half rounding), opaque.
 * Then, on llvmpipe only, every frame against its golden image with PSNR over covered pixels
 * >= GOLDEN_MIN_DB (see above for the measured spread and margins). Both goldens were made by
 * this pipeline (SPLATD_WRITE_GOLDEN=1 rewrites them from the first 8-bit frame of each view):
 * they guard against regressions, not for correctness, which the analytic tests above check
 * independently of the pipeline (test_tilted_footprints: footprint moments against the test's
 * own finite-difference Jacobian; test_exact_footprint_moments, test_inclined_footprint,
 * test_constant_colour, test_two_planes). tests/data/golden_guanyin_splat.png is view (a),
 * tests/data/golden_guanyin_closeup_exact.png view (b). On another renderer the goldens
 * (llvmpipe's rounding) do not apply: the comparison is skipped with TU_SKIP, never passed. */
typedef struct gview {
    const char *name, *golden;
    int w, h, nframes, ewa;
    double min_cover; /* fraction of the frame */
} gview;

static void test_guanyin(void **state)
{
    fixture *fx = *state;
    pc_prepared pc;
    tu_prep_data("Guanyin.ply", &pc);
    uint32_t id = tu_upload(fx->egl, &pc);
    const gview views[2] = {
        {"default view", "golden_guanyin_splat.png", 640, 480, 4, SP_EWA_AUTO, 0.05},
        {"close-up, ewa=exact", "golden_guanyin_closeup_exact.png", 320, 240, 2, SP_EWA_EXACT,
         0.6}};
    rnd_camera cams[2];
    rnd_camera_frame(pc.bmin, pc.bmax, 640, 480, &cams[0]);
    cams[1] = (rnd_camera){{0.05, 1.0, 0.27}, {0.0, 0.95, 0.0}, {0, 1, 0}, 70, 0, 0, 320, 240};
    pc_prepared_free(&pc);
    /* Per view: 8-bit frames (rendered straight into RGBA8), then float frames; the second
     * frame of a kind checks that nothing a frame leaves behind changes the next. */
    rnd_frame f[2][4];
    memset(f, 0, sizeof f);
    for (int v = 0; v < 2; v++) {
        sp_params p;
        sp_params_defaults(&p);
        p.ewa = views[v].ewa;
        int nf = views[v].nframes;
        for (int k = 0; k < nf; k++) tu_render(fx->egl, id, &cams[v], &p, k >= nf / 2, &f[v][k]);
        size_t npx = (size_t)views[v].w * views[v].h, covered = 0;
        int maxdiff = 0, maxdiff_float = 0, opaque = 1;
        for (size_t i = 0; i < npx; i++) {
            covered += !is_bg(f[v][0].rgba8 + 4 * i);
            for (int k = 1; k < nf; k++)
                for (int c = 0; c < 3; c++) {
                    int d = abs(f[v][0].rgba8[4 * i + c] - f[v][k].rgba8[4 * i + c]);
                    int *m = k < nf / 2 ? &maxdiff : &maxdiff_float;
                    if (d > *m) *m = d;
                }
            for (int k = 0; k < nf; k++) opaque &= f[v][k].rgba8[4 * i + 3] == 255;
        }
        printf("guanyin, %s: %zu of %zu pixels covered, run-to-run max difference %d, 8-bit vs "
               "float target %d\n", views[v].name, covered, npx, maxdiff, maxdiff_float);
        assert_true(covered > views[v].min_cover * npx);
        assert_true(maxdiff <= 1);
        assert_true(maxdiff_float <= 1);
        assert_true(opaque);
    }
    const char *wg = getenv("SPLATD_WRITE_GOLDEN");
    if (wg && *wg == '1')
        for (int v = 0; v < 2; v++) {
            char gpath[4096];
            tu_data(views[v].golden, gpath, sizeof gpath);
            assert_int_equal(tu_png_write(gpath, (uint32_t)views[v].w, (uint32_t)views[v].h, f[v][0].rgba8, 1), 0);
            printf("wrote %s\n", gpath);
        }
    int llvmpipe = strstr(rnd_renderer_string(fx->egl), "llvmpipe") != NULL;
    double worst = INFINITY;
    for (int v = 0; v < 2 && llvmpipe; v++) {
        char gpath[4096];
        tu_data(views[v].golden, gpath, sizeof gpath);
        uint32_t gw, gh;
        uint8_t *g = NULL;
        if (tu_png_read(gpath, 1, &gw, &gh, &g) < 0)
            fail_msg("cannot read the golden image %s", gpath);
        assert_int_equal(gw, views[v].w);
        assert_int_equal(gh, views[v].h);
        size_t npx = (size_t)gw * gh, ncov = 0;
        for (int k = 0; k < views[v].nframes; k++) {
            double db = tu_psnr_covered(f[v][k].rgba8, g, npx, &ncov);
            printf("guanyin, %s, frame %d (%s): PSNR against %s over %zu covered pixels %.2f dB\n",
                   views[v].name, k, k < views[v].nframes / 2 ? "8-bit" : "float", views[v].golden,
                   ncov, db);
            worst = fmin(worst, db);
        }
        free(g);
    }
    for (int v = 0; v < 2; v++)
        for (int k = 0; k < 4; k++) rnd_frame_free(&f[v][k]);
    rnd_release(fx->egl, id);
    if (!llvmpipe)
        TU_SKIP("golden comparison: the goldens are llvmpipe's rounding and the renderer is %s "
                "(the checks above passed)", rnd_renderer_string(fx->egl));
    if (!(worst >= GOLDEN_MIN_DB))
        fail_msg("guanyin: a frame is %.2f dB from its golden image over covered pixels, under "
                 "the bound %.0f dB", worst, GOLDEN_MIN_DB);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hole_filling),
        cmocka_unit_test(test_constant_colour),
        cmocka_unit_test(test_two_planes),
        cmocka_unit_test(test_fixed_point_and_osmesa),
        cmocka_unit_test(test_stripes),
        cmocka_unit_test(test_ewa_antialiasing),
        cmocka_unit_test(test_inclined_footprint),
        cmocka_unit_test(test_exact_footprint_moments),
        cmocka_unit_test(test_tilted_footprints),
        cmocka_unit_test(test_ewa_auto),
        cmocka_unit_test(test_culled_ranges),
        cmocka_unit_test(test_guanyin),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
