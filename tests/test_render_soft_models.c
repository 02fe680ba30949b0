/* test_render_soft_models.c — the `soft` pipeline's Base- and Concentric-Models (Soft
 * Transparency eq. 4-18, per-pixel fragment lists, soft_lists.h) on llvmpipe, against numbers
 * computed here:
 *   - one sphere, Base: on the ray through the centre the opacity is 1 - exp(-lambda r^2) (the
 *     integral of r - |z| over the chord is r^2) within 1 %; every ray through the sphere matches
 *     the closed form of eq. 7 at its distance d from the centre within 1 %;
 *   - two intersecting spheres of different colours, Base: colour and opacity of rays through
 *     them match a numerical integration of the summed densities with eq. 11's colours (4000
 *     steps along the ray) within 2 %;
 *   - a cloud of random soft spheres: Concentric vs Base and Express vs Base mean absolute
 *     differences under the thresholds stated at the test;
 *   - the memory cap: a cap that forces bands of rows gives the uncapped image and no flag; a
 *     row that alone exceeds it, and a pixel with more than 32 overlapping Base spheres, flag the
 *     frame (RND_FRAME_SOFT_TRUNCATED) and still render;
 *   - structure, where an average would hide it: one Concentric sphere's opacity at every pixel
 *     against eq. 13-18 with its count of shells (and not with one more or one less), and stacks
 *     of 1-4 coincident points in each model against what that many layers give.
 * Frames are float (RGBA16F, 11 significant bits) where 1 % is asked, so the check measures the
 * model rather than 8-bit rounding. Lengths are in world units here (the test clouds have no
 * median radius, so soft_lists.h's unit is 1 x splat_scale). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "half.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { W = 161, H = 161 }; /* odd: the middle pixel's centre ray is the view axis */
static const double OFF[3] = {500000.0, 4100000.0, 120.0};
static const double EZ = 6.0; /* camera at local (0, 0, EZ) looking at the origin */

typedef struct sphere {
    float x, y, z, r;
    float rgb[3];
} sphere;

static uint32_t upload_spheres(const sphere *s, int n, float median)
{
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)n, 1);
    for (int i = 0; i < n; i++) {
        pc.pos[3 * i] = s[i].x, pc.pos[3 * i + 1] = s[i].y, pc.pos[3 * i + 2] = s[i].z;
        pc.radius[i] = s[i].r;
        for (int c = 0; c < 3; c++) pc.rgba[4 * i + c] = (uint8_t)lroundf(255.0f * s[i].rgb[c]);
        pc.F[i] = 1.0f;
    }
    pc.radius_median = median;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(tu_ctx, &pc);
    pc_prepared_free(&pc);
    return id;
}

static rnd_camera cam_z(void)
{
    rnd_camera c = {{OFF[0], OFF[1], EZ + OFF[2]}, {OFF[0], OFF[1], OFF[2]}, {0, 1, 0},
                    40, 0.05f, 30.0f, W, H};
    return c;
}

/* The eye ray through pixel (x, y)'s centre: unit direction (the camera is at (0, 0, EZ)). */
static void pixel_ray(int x, int y, double u[3])
{
    double t = tan(20.0 * M_PI / 180.0);
    double d[3] = {((x + 0.5) / W * 2 - 1) * t, ((y + 0.5) / H * 2 - 1) * t, -1};
    double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; k++) u[k] = d[k] / l;
}

/* float RGBA of pixel (x, y) of a float frame */
static void fpix(const rnd_frame *f, int x, int y, float out[4])
{
    for (int c = 0; c < 4; c++) out[c] = half_to_float(f->rgba16f[4 * ((size_t)y * f->width + x) + c]);
}

/* eq. 7 from 0 to b: r b - b sqrt(b^2 + d^2) / 2 - d^2 / 2 (log(sqrt(b^2 + d^2) + b) - log d) */
static double eq7(double r, double d, double b)
{
    double q = sqrt(b * b + d * d);
    double l = d > 0 ? d * d * (log(q + b) - log(d)) : 0.0;
    return r * b - 0.5 * b * q - 0.5 * l;
}

static sp_params base_params(int model, float lambda)
{
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_SOFT, p.model = model, p.t = 0.5f, p.lambda = lambda;
    p.background[0] = p.background[1] = p.background[2] = 0.0f;
    /* the light along the view axis: the spheres' normals (+z) face it, so the shading is
     * exactly 1 and the colours are the model's alone */
    p.light[0] = 0.0f, p.light[1] = 0.0f, p.light[2] = 1.0f;
    return p;
}

/* One white sphere r = 1 at the origin, lambda = 0.8, Base. At pixel (x, y) the ray's distance
 * from the centre is d = |e x u|; the opacity must be 1 - exp(-lambda 2 P(sqrt(r^2 - d^2)))
 * with P eq. 7 from 0, which on the centre ray is 1 - exp(-lambda r^2). The float frame's red
 * channel is that opacity (white over black). Tolerance 1 % of the value, over the rays with
 * d < 0.98 r whose opacity is above 0.02 (near the rim the value tends to 0 and half precision
 * dominates). */
static void test_base_one_sphere(void **state)
{
    (void)state;
    const sphere s[1] = {{0, 0, 0, 1.0f, {1, 1, 1}}};
    uint32_t id = upload_spheres(s, 1, 0.0f);
    rnd_camera cam = cam_z();
    sp_params p = base_params(SP_MODEL_BASE, 0.8f);
    rnd_frame f = {0};
    tu_render(tu_ctx, id, &cam, &p, 1, &f);
    assert_int_equal(f.flags, 0);
    float c[4];
    fpix(&f, W / 2, H / 2, c);
    double want0 = 1.0 - exp(-0.8 * 1.0);
    printf("one sphere, centre ray: opacity %.5f (red %.5f), 1 - exp(-lambda r^2) = %.5f\n",
           c[3], c[0], want0);
    assert_true(fabs(c[0] - want0) <= 0.01 * want0);
    double worst = 0;
    int n = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double u[3];
            pixel_ray(x, y, u);
            /* e x u with e = (0, 0, EZ) */
            double cx = -EZ * u[1], cy = EZ * u[0];
            double d = sqrt(cx * cx + cy * cy);
            if (d >= 0.98) continue;
            double want = 1.0 - exp(-0.8 * 2.0 * eq7(1.0, d, sqrt(1.0 - d * d)));
            if (want < 0.02) continue;
            fpix(&f, x, y, c);
            double e = fabs(c[0] - want) / want;
            if (e > worst) worst = e;
            n++;
        }
    printf("one sphere: %d rays, largest relative error against eq. 7 %.4f\n", n, worst);
    assert_true(n > 3000);
    assert_true(worst <= 0.01);
    rnd_frame_free(&f);
    rnd_release(tu_ctx, id);
}

/* Two spheres r = 1 overlapping: red at (-0.5, 0, 0.3), green at (0.5, 0, -0.3), lambda = 0.7,
 * Base. The reference marches each pixel's ray in 4000 steps over [EZ - 2, EZ + 2] (both
 * spheres inside): density = sum over the spheres containing the point of r - |p - c|, colour by
 * eq. 11 with weights 1 - d_i / r_i (d_i the ray's distance from centre i), front to back.
 * Tolerance: 2 % of each channel's value plus 0.002 (half precision), on every 5th pixel whose
 * reference opacity exceeds 0.05. */
static void test_base_two_spheres(void **state)
{
    (void)state;
    const sphere s[2] = {{-0.5f, 0, 0.3f, 1.0f, {1, 0, 0}}, {0.5f, 0, -0.3f, 1.0f, {0, 1, 0}}};
    uint32_t id = upload_spheres(s, 2, 0.0f);
    rnd_camera cam = cam_z();
    const double lambda = 0.7;
    sp_params p = base_params(SP_MODEL_BASE, (float)lambda);
    rnd_frame f = {0};
    tu_render(tu_ctx, id, &cam, &p, 1, &f);
    double worst = 0;
    int n = 0, both = 0;
    for (int y = 0; y < H; y += 5)
        for (int x = 0; x < W; x += 5) {
            double u[3];
            pixel_ray(x, y, u);
            double dd[2], w[2];
            for (int i = 0; i < 2; i++) {
                double m[3] = {0 - s[i].x, 0 - s[i].y, EZ - s[i].z}; /* eye - centre */
                double b = m[0] * u[0] + m[1] * u[1] + m[2] * u[2];
                double mm = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
                dd[i] = sqrt(fmax(mm - b * b, 0.0));
                w[i] = 1.0 - dd[i] / s[i].r;
            }
            enum { STEPS = 4000 };
            double s0 = EZ - 2.0, s1 = EZ + 2.0, ds = (s1 - s0) / STEPS, T = 1, L[3] = {0, 0, 0};
            int inboth = 0;
            for (int k = 0; k < STEPS; k++) {
                double t = s0 + (k + 0.5) * ds;
                double pt[3] = {t * u[0], t * u[1], EZ + t * u[2]};
                double rho = 0, ws = 0, col[3] = {0, 0, 0};
                int inside = 0;
                for (int i = 0; i < 2; i++) {
                    double e[3] = {pt[0] - s[i].x, pt[1] - s[i].y, pt[2] - s[i].z};
                    double dist = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
                    if (dist >= s[i].r) continue;
                    inside++;
                    rho += s[i].r - dist;
                    ws += w[i];
                    for (int c = 0; c < 3; c++) col[c] += w[i] * s[i].rgb[c];
                }
                if (!inside) continue;
                inboth |= inside == 2;
                double a = 1.0 - exp(-lambda * rho * ds);
                for (int c = 0; c < 3; c++) L[c] += T * a * (ws > 0 ? col[c] / ws : 0);
                T *= 1.0 - a;
            }
            if (1.0 - T < 0.05) continue;
            float g[4];
            fpix(&f, x, y, g);
            for (int c = 0; c < 3; c++) {
                double e = fabs(g[c] - L[c]) - 0.02 * L[c];
                if (e > worst) worst = e;
            }
            double ea = fabs(g[3] - (1.0 - T)) - 0.02 * (1.0 - T);
            if (ea > worst) worst = ea;
            n++, both += inboth;
            if (x == W / 2 && y == H / 2)
                printf("two spheres, centre ray: got (%.4f, %.4f, a %.4f), integration (%.4f, "
                       "%.4f, a %.4f)\n", g[0], g[1], g[3], L[0], L[1], 1.0 - T);
        }
    printf("two spheres: %d rays (%d through both), worst excess over 2 %%: %.5f\n", n, both,
           worst);
    assert_true(n > 200 && both > 50);
    assert_true(worst <= 0.002);
    rnd_frame_free(&f);
    rnd_release(tu_ctx, id);
}

static double mad8(const rnd_frame *a, const rnd_frame *b, int *covered)
{
    double s = 0;
    int n = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) {
        int any = 0;
        for (int c = 0; c < 3; c++) any |= a->rgba8[4 * i + c] > 2 || b->rgba8[4 * i + c] > 2;
        if (!any) continue;
        for (int c = 0; c < 3; c++) s += abs(a->rgba8[4 * i + c] - b->rgba8[4 * i + c]);
        n++;
    }
    *covered = n;
    return n ? s / (3.0 * n) : 0.0;
}

/* 400 random soft spheres (radius 0.12-0.2, random colours) in a 2.4 x 2.4 x 1.2 box, the
 * length unit u = the median radius (0.16), lambda = 0.5, seen from EZ. Mean absolute difference
 * per channel (8-bit levels) over the pixels any of the frames covers:
 *   Concentric vs Base < 6 levels (measured 3.9): each sphere carries the same total density
 *   (soft_lists.h), distributed differently (eq. 13-15 put more near the centre ray);
 *   Express vs Base < 12 levels (measured 8.4): the paper calls them visually alike (its
 *   Fig. 6-7), not equal: Express's centre opacity is lambda where Base's is
 *   1 - exp(-lambda r^2 / u^2), and its discs are composited per axis order, not integrated per
 *   ray.
 * Also each pair must differ (> 0.2 levels), or the models would not be distinct. */
static void test_models_alike(void **state)
{
    (void)state;
    enum { N = 400 };
    sphere s[N];
    uint64_t seed = 7;
    for (int i = 0; i < N; i++) {
        float v[7];
        for (int k = 0; k < 7; k++) {
            seed = seed * 6364136223846793005ull + 1442695040888963407ull;
            v[k] = (float)(seed >> 33) / (float)(1u << 31);
        }
        s[i] = (sphere){2.4f * v[0] - 1.2f, 2.4f * v[1] - 1.2f, 1.2f * v[2] - 0.6f,
                        0.12f + 0.08f * v[3], {v[4], v[5], v[6]}};
    }
    uint32_t id = upload_spheres(s, N, 0.16f);
    rnd_camera cam = cam_z();
    rnd_frame fb = {0}, fc = {0}, fe = {0};
    sp_params p = base_params(SP_MODEL_BASE, 0.5f);
    tu_render(tu_ctx, id, &cam, &p, 0, &fb);
    p.model = SP_MODEL_CONCENTRIC;
    tu_render(tu_ctx, id, &cam, &p, 0, &fc);
    p.model = SP_MODEL_EXPRESS;
    tu_render(tu_ctx, id, &cam, &p, 0, &fe);
    int nc, ne;
    double dc = mad8(&fc, &fb, &nc), de = mad8(&fe, &fb, &ne);
    printf("random spheres: concentric vs base %.2f levels (%d px), express vs base %.2f (%d px)\n",
           dc, nc, de, ne);
    assert_true(nc > 5000);
    assert_true(dc < 6.0 && dc > 0.2);
    assert_true(de < 12.0 && de > 0.2);
    assert_int_equal(fb.flags, 0);
    assert_int_equal(fc.flags, 0);
    rnd_frame_free(&fb), rnd_frame_free(&fc), rnd_frame_free(&fe);
    rnd_release(tu_ctx, id);
}

/* The memory cap (soft_frag_mib). 60 spheres r = 1 stacked along the view axis (every ray
 * through the middle meets all of them): Base needs 120 samples a pixel there.
 *   - soft_frag_mib = 1 (65536 samples) with Concentric on 20 spheres: too much for the frame
 *     at once but not for a row, so bands: the image equals the uncapped one (tolerance 1
 *     level: the sort of equal keys may differ) and flags stay 0;
 *   - Concentric on 60 spheres r = 2 at cap 1 MiB: a middle row alone needs more: flagged;
 *   - Base on the 60 spheres with the default cap, after a larger frame: more than 32 overlap
 *     in a pixel: flagged. */
static void test_memory_cap(void **state)
{
    (void)state;
    enum { N = 60 };
    sphere s[N];
    for (int i = 0; i < N; i++)
        s[i] = (sphere){0.01f * i, 0, -2.0f + 4.0f * i / N, 1.0f, {1, 0.5f, 0.25f}};
    uint32_t id20 = upload_spheres(s, 20, 0.0f);
    for (int i = 0; i < N; i++) s[i].r = 2.0f; /* ~13 shells a sphere: a row needs > 65536 */
    uint32_t id60 = upload_spheres(s, N, 0.0f);
    rnd_camera cam = cam_z();
    sp_params p = base_params(SP_MODEL_CONCENTRIC, 0.1f);
    rnd_frame a = {0}, b = {0};
    tu_render(tu_ctx, id20, &cam, &p, 0, &a);
    p.soft_frag_mib = 1;
    tu_render(tu_ctx, id20, &cam, &p, 0, &b);
    int worst = 0;
    for (size_t i = 0; i < (size_t)W * H * 4; i++) {
        int d = abs(a.rgba8[i] - b.rgba8[i]);
        worst = d > worst ? d : worst;
    }
    printf("memory cap: 20 spheres, concentric, bands at 1 MiB vs one pass: max %d levels, "
           "flags %u, %u\n", worst, a.flags, b.flags);
    assert_true(worst <= 1);
    assert_int_equal(a.flags, 0);
    assert_int_equal(b.flags, 0);
    tu_render(tu_ctx, id60, &cam, &p, 0, &b);
    printf("memory cap: 60 spheres, concentric at 1 MiB: flags %u\n", b.flags);
    assert_int_equal(b.flags & RND_FRAME_SOFT_TRUNCATED, RND_FRAME_SOFT_TRUNCATED);
    p.model = SP_MODEL_BASE;
    p.soft_frag_mib = 512;
    /* a larger frame first: its buffers stay, and the flag must still be read where this
     * frame's blend writes it */
    rnd_camera big = cam;
    big.width = 2 * W, big.height = 2 * H;
    rnd_frame c2 = {0};
    tu_render(tu_ctx, id20, &big, &p, 0, &c2);
    rnd_frame_free(&c2);
    tu_render(tu_ctx, id60, &cam, &p, 0, &b);
    printf("memory cap: 60 spheres, base: flags %u\n", b.flags);
    assert_int_equal(b.flags & RND_FRAME_SOFT_TRUNCATED, RND_FRAME_SOFT_TRUNCATED);
    rnd_frame_free(&a), rnd_frame_free(&b);
    rnd_release(tu_ctx, id20), rnd_release(tu_ctx, id60);
}

/* ---- structure: layers and shells that show in the pixels ---- */

/* The distance from (cx, cy, cz) to pixel (x, y)'s centre ray. */
static double ray_dist(int x, int y, double cx, double cy, double cz)
{
    double u[3], m[3] = {-cx, -cy, EZ - cz}; /* eye - centre */
    pixel_ray(x, y, u);
    double b = m[0] * u[0] + m[1] * u[1] + m[2] * u[2];
    return sqrt(fmax(m[0] * m[0] + m[1] * m[1] + m[2] * m[2] - b * b, 0.0));
}

/* The Concentric-Model's optical depth (in units of the unit length) along a ray at distance d
 * from the centre of a sphere of radius R with N shells of radii r_j = R (1 - j / N): inside
 * shell j and outside shell j + 1 the density is mu'_j = R / (N r_j) (1 - d / r_j) (eq. 13,
 * 15, 16-18), times kappa = R K[N]. */
static double conc_tau(double d, double R, int N, double K)
{
    double tau = 0.0;
    for (int j = 0; j < N; j++) {
        double rj = R * (1.0 - (double)j / N), rn = R * (1.0 - (double)(j + 1) / N);
        if (d >= rj) break;
        double ch = 2.0 * sqrt(rj * rj - d * d);
        double chn = j + 1 < N && d < rn ? 2.0 * sqrt(rn * rn - d * d) : 0.0;
        tau += R / (N * rj) * (1.0 - d / rj) * (ch - chn);
    }
    return R * K * tau;
}

/* K[N] from its definition (soft_lists.h): the Base-Model's optical depth integrated over a unit
 * sphere's disc (2 pi / 6 for r = 1, from eq. 7) over
 * the Concentric-Model's with N shells and K = 1, integrated here by Simpson's rule on 20000
 * intervals (independently of soft_lists_kappa's midpoint rule). */
static double kappa_ref(int N)
{
    enum { M = 20000 };
    double mass = 0.0;
    for (int q = 0; q <= M; q++) {
        double d = (double)q / M, w = q == 0 || q == M ? 1 : q % 2 ? 4 : 2;
        mass += w * conc_tau(d, 1.0, N, 1.0) * d;
    }
    mass /= 3.0 * M;
    return (1.0 / 6.0) / mass;
}

/* The shells the Concentric-Model gives one sphere: N = 1 + floor(R_px / 4), R_px its screen
 * radius at its centre's depth (soft_frag.comp: one more shell every 4 pixels), so a white
 * sphere r = 1 at the origin, 6 away, has 10. Its opacity at every pixel must be
 * 1 - exp(-lambda conc_tau(d)) for N = 10 (float frame: 1 % of the value plus 0.002 for half
 * precision, rays with d < 0.98 and an opacity over 0.02): the profile has a kink at every
 * shell, so the count shows where an average would not. With N = 9 or 11 the same frame must
 * miss that tolerance by far (its largest error at least 3 times the bound), so that the test
 * tells the shell count apart. */
static void test_concentric_shells(void **state)
{
    (void)state;
    const sphere s[1] = {{0, 0, 0, 1.0f, {1, 1, 1}}};
    uint32_t id = upload_spheres(s, 1, 0.0f);
    rnd_camera cam = cam_z();
    const double lambda = 0.6;
    sp_params p = base_params(SP_MODEL_CONCENTRIC, (float)lambda);
    rnd_frame f = {0};
    tu_render(tu_ctx, id, &cam, &p, 1, &f);
    assert_int_equal(f.flags, 0);
    double rpx = 1.0 / tan(20.0 * M_PI / 180.0) * 0.5 * H / EZ;
    int N = 1 + (int)floor(rpx / 4.0);
    assert_int_equal(N, 10);
    double worst[3] = {0, 0, 0};
    int n = 0;
    for (int k = 0; k < 3; k++) {
        int nk = N - 1 + k;
        double K = kappa_ref(nk);
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                double d = ray_dist(x, y, 0, 0, 0);
                if (d >= 0.98) continue;
                double want = 1.0 - exp(-lambda * conc_tau(d, 1.0, nk, K));
                if (want < 0.02) continue;
                float c[4];
                fpix(&f, x, y, c);
                double e = fabs(c[0] - want) / (0.01 * want + 0.002);
                worst[k] = fmax(worst[k], e);
                n += k == 1;
            }
    }
    printf("concentric, one sphere (R %.1f px, %d shells): %d rays; largest error over the "
           "bound with %d / %d / %d shells: %.2f / %.2f / %.2f\n", rpx, N, n, N - 1, N, N + 1,
           worst[0], worst[1], worst[2]);
    assert_true(n > 3000);
    assert_true(worst[1] <= 1.0);
    assert_true(worst[0] >= 3.0 && worst[2] >= 3.0);
    rnd_frame_free(&f);
    rnd_release(tu_ctx, id);
}

/* Stacks of k = 1, 2, 3 and 4 coincident white soft points (r = 0.4, side by side at x = -1.35,
 * -0.45, 0.45, 1.35, facing the camera), each model: the count of layers must show in every
 * pixel near each stack's centre, against what k layers give:
 *   Express: k discs of opacity lambda (cos(pi d / r) + 1) / 2 one over the other:
 *     1 - (1 - Phi)^k (d the pixel centre's screen distance over the screen radius; d < 0.5);
 *   Base: densities add: 1 - exp(-lambda k 2 P(sqrt(r^2 - d^2))) with eq. 7 (every ray within
 *     0.9 r);
 *   Concentric: 1 - exp(-lambda k conc_tau(d)) with N = 1 + floor(R_px / 4) = 4 shells.
 * Float frames; tolerance 1 % of the value plus 0.002 (half precision); and the values of k
 * and k + 1 layers lie far apart at each stack's centre (so one layer lost or added fails). */
static void test_layer_count(void **state)
{
    (void)state;
    enum { NS = 4 };
    const float r = 0.4f, xs[NS] = {-1.35f, -0.45f, 0.45f, 1.35f};
    sphere s[1 + 2 + 3 + 4];
    int m = 0;
    for (int k = 0; k < NS; k++)
        for (int j = 0; j <= k; j++) s[m++] = (sphere){xs[k], 0, 0, r, {1, 1, 1}};
    uint32_t id = upload_spheres(s, m, 0.0f);
    rnd_camera cam = cam_z();
    const double rpx = r / tan(20.0 * M_PI / 180.0) * 0.5 * H / EZ;
    const int N = 1 + (int)floor(rpx / 4.0);
    const double K = kappa_ref(N);
    const int models[3] = {SP_MODEL_EXPRESS, SP_MODEL_BASE, SP_MODEL_CONCENTRIC};
    const char *const mname[3] = {"express", "base", "concentric"};
    const double lambdas[3] = {0.3, 1.5, 1.5};
    for (int mi = 0; mi < 3; mi++) {
        sp_params p = base_params(models[mi], (float)lambdas[mi]);
        rnd_frame f = {0};
        tu_render(tu_ctx, id, &cam, &p, 1, &f);
        double worst = 0, centre[NS];
        int n = 0;
        for (int k = 0; k < NS; k++) {
            /* the stack's centre pixel and screen position (camera on the axis: x scales) */
            double sx = (xs[k] / (EZ * tan(20.0 * M_PI / 180.0)) * 0.5 + 0.5) * W;
            for (int y = 0; y < H; y++)
                for (int x = (int)(sx - rpx) - 1; x <= (int)(sx + rpx) + 1; x++) {
                    if (x < 0 || x >= W) continue;
                    double want;
                    if (models[mi] == SP_MODEL_EXPRESS) {
                        double dd = hypot(x + 0.5 - sx, y + 0.5 - 0.5 * H) / rpx;
                        if (dd >= 0.5) continue;
                        double phi = lambdas[mi] * (cos(M_PI * dd) + 1.0) / 2.0;
                        want = 1.0 - pow(1.0 - phi, k + 1);
                    } else {
                        double d = ray_dist(x, y, xs[k], 0, 0);
                        if (d >= 0.9 * r) continue;
                        double tau = models[mi] == SP_MODEL_BASE
                                         ? 2.0 * eq7(r, d, sqrt(r * r - d * d))
                                         : conc_tau(d, r, N, K);
                        want = 1.0 - exp(-lambdas[mi] * (k + 1) * tau);
                    }
                    float c[4];
                    fpix(&f, x, y, c);
                    worst = fmax(worst, fabs(c[0] - want) / (0.01 * want + 0.002));
                    n++;
                }
            float c[4];
            fpix(&f, (int)sx, H / 2, c);
            centre[k] = c[0];
        }
        printf("layers 1-4, %s: centre opacities %.4f %.4f %.4f %.4f; %d pixels, largest error "
               "over the bound %.2f\n", mname[mi], centre[0], centre[1], centre[2], centre[3], n,
               worst);
        assert_true(n > 100);
        assert_true(worst <= 1.0);
        for (int k = 0; k + 1 < NS; k++) assert_true(centre[k + 1] - centre[k] > 0.03);
        rnd_frame_free(&f);
    }
    rnd_release(tu_ctx, id);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_base_one_sphere),
        cmocka_unit_test(test_base_two_spheres),
        cmocka_unit_test(test_models_alike),
        cmocka_unit_test(test_memory_cap),
        cmocka_unit_test(test_concentric_shells),
        cmocka_unit_test(test_layer_count),
    };
    return cmocka_run_group_tests(tests, tu_egl_group_setup, tu_egl_group_teardown);
}
