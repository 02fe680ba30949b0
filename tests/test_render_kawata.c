/* test_render_kawata.c — the `kawata` pipeline (Kawata & Kanai's direct point rendering) and
 * shading=edl (Eye-Dome Lighting) on llvmpipe through the public renderer (render.h), against
 * analytic expectations: outlier removal on a noisy plane, recovered normals of a tilted plane,
 * hole filling on a sparse plane, a real position-only scan against a golden image, and EDL's
 * identity at strength 0, its darkening at a depth step against the formula, and a plane facing
 * the camera left as it is.
 *
 * Clouds are built in memory with tu_new_cloud (which gives every attribute); kawata reads only
 * positions and colours (pipe_kawata.c's `needs`), so the normals and radii tu_new_cloud fills
 * in play no part. sigma, which prep computes for a file, is set from the sampling: for points
 * uniformly random over an area A, the median nearest-neighbour distance of a Poisson process
 * of density n / A, sqrt(ln 2 A / (pi n)). Timings are in `make bench`, not here. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cloud.h"
#include "edl.h"
#include "half.h"
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "rng.h"
#include "imgtest.h"
#include "kwcheck.h"
#include "testutil.h"

enum { W = 256, H = 256 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0}; /* a UTM-like offset */

/* Each test runs twice, in a group of its own for each place kawata's passes 1 and 2 can run
 * (the compute shaders, or the host paths: rnd_desc.host_paths off and on, whatever the back
 * end): the same bounds hold for both. */
typedef struct kfix {
    rnd_ctx *r;
    int host_paths;            /* RND_CAP_OFF or RND_CAP_ON */
} kfix;

/* The description of a renderer of the group's kind, with max_set_points points a set (0: the
 * driver's). */
static rnd_desc desc_of(int host_paths, uint32_t max_set_points)
{
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                  .host_paths = host_paths, .max_set_points = max_set_points};
    return d;
}

static rnd_ctx *create(int host_paths, uint32_t max_set_points)
{
    rnd_desc d = desc_of(host_paths, max_set_points);
    sd_err err = {0};
    rnd_ctx *r = rnd_create(&d, &err);
    if (!r) fail_msg("rnd_create: %s", err.msg);
    assert_int_equal(rnd_host_paths(r), host_paths == RND_CAP_ON);
    return r;
}

static int setup_with(void **state, int host_paths)
{
    rnd_desc d = desc_of(host_paths, 0);
    sd_err err = {0};
    kfix *kf = calloc(1, sizeof *kf);
    if (!kf) return -1;
    kf->host_paths = host_paths;
    kf->r = rnd_create(&d, &err);
    if (!kf->r) {
        fprintf(stderr, "rnd_create: %s\n", err.msg);
        free(kf);
        return -1;
    }
    *state = kf;
    return 0;
}

static int setup_gl(void **state)
{
    return setup_with(state, RND_CAP_OFF);
}

static int setup_host(void **state)
{
    return setup_with(state, RND_CAP_ON);
}

static int teardown(void **state)
{
    kfix *kf = *state;
    rnd_destroy(kf->r);
    free(kf);
    return 0;
}

/* The defaults (the group's renderer says where kawata's passes 1 and 2 run). */
static void params_of(const kfix *kf, sp_params *p)
{
    (void)kf;
    sp_params_defaults(p);
}

/* A camera at local (ex, ey, ez) looking at the local origin, up +y. */
static rnd_camera cam_at(double ex, double ey, double ez, float fov, int w, int h)
{
    rnd_camera c = {{ex + OFF[0], ey + OFF[1], ez + OFF[2]}, {OFF[0], OFF[1], OFF[2]},
                    {0, 1, 0}, fov, 0, 0, w, h};
    return c;
}

static int is_bg(const uint8_t *p)
{
    return p[0] == 0 && p[1] == 0 && p[2] == 0;
}

static double uniform(rng *g)
{
    return uni(g);
}

static void set_rgb(pc_prepared *pc, uint64_t i, uint8_t r, uint8_t g, uint8_t b)
{
    pc->rgba[4 * i] = r, pc->rgba[4 * i + 1] = g, pc->rgba[4 * i + 2] = b;
}

/* Median nearest-neighbour distance of n uniformly random points over area a (see top). */
static float poisson_sigma(double a, uint64_t n)
{
    return (float)sqrt(log(2.0) * a / (M_PI * (double)n));
}

/* ---- outliers ---- */

/* A unit square plane z = 0 of N points, white, with Gaussian noise of sd 0.2 % of its size
 * along its normal, and 5 % as many red outliers uniformly in front of it (over the square, at
 * 0.05-0.5 in front: farther than gamma and the depth tolerance of pipe_kawata.c, 0.011 + 4
 * buffer pixels ~ 0.034 here, so they are off the surface, not noise on it). `points` shows the
 * outliers (each is the nearest point of its pixel); kawata must show outlier-coloured (red)
 * pixels on under 0.1 % of its covered pixels (the bound). A pixel is outlier-coloured
 * when red exceeds green by more than 40/255: the plane is grey (r = g = b) after shading, and
 * a red splat blended into grey at weight w gives r - g = 255 w, so this counts every pixel
 * where an outlier contributes more than 16 % of the colour. Measured: points ~10 % red pixels,
 * kawata 0. */
static void test_outliers(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = 60000, NOUT = N / 20 };
    rng g;
    g.s = 11;
    pc_prepared pc;
    tu_new_cloud(&pc, N + NOUT, 0);
    for (uint64_t i = 0; i < N + NOUT; i++) {
        float *p = pc.pos + 3 * i;
        p[0] = (float)(uniform(&g) - 0.5), p[1] = (float)(uniform(&g) - 0.5);
        if (i < N) {
            p[2] = (float)(0.002 * gauss(&g));
        } else {
            p[2] = (float)(0.05 + 0.45 * uniform(&g));
            set_rgb(&pc, i, 255, 0, 0);
        }
    }
    pc.sigma = poisson_sigma(1.0, N);
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, 2.0, 40, W, H);
    int red[2] = {0, 0}, covered[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        sp_params p;
        params_of(kf, &p);
        p.pipeline = k == 0 ? SP_PIPE_POINTS : SP_PIPE_KAWATA;
        rnd_frame f = {0};
        tu_render(r, id, &cam, &p, 0, &f);
        for (int i = 0; i < W * H; i++) {
            const uint8_t *c = f.rgba8 + 4 * i;
            if (is_bg(c)) continue;
            covered[k]++;
            red[k] += c[0] - c[1] > 40;
        }
        if (k == 1)
            printf("outliers: kawata image buffer %dx%d, %llu splats\n", f.buffer_w, f.buffer_h,
                   (unsigned long long)f.splats_drawn);
        rnd_frame_free(&f);
    }
    printf("outliers: points %d red of %d covered (%.2f %%), kawata %d of %d (%.4f %%)\n", red[0],
           covered[0], 100.0 * red[0] / covered[0], red[1], covered[1],
           100.0 * red[1] / covered[1]);
    assert_true(covered[1] > W * H / 4);        /* the plane is there (~45 % of the frame) */
    assert_true(red[0] > covered[0] / 50);      /* points shows outliers: over 2 % */
    assert_true(red[1] * 1000 < covered[1]);    /* kawata: under 0.1 % */
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* ---- normals ---- */

/* A plane through the origin tilted 35 degrees about x and 20 about y, N uniformly random points
 * of a unit square in it, no noise, rendered with color=normal (the local normal n as
 * n * 0.5 + 0.5, 8 bits a channel). Over the interior (pixels whose 9x9 neighbourhood is all
 * covered, so no splat of the silhouette takes part) every recovered normal must lie within 3
 * degrees of the truth (the bound). The plane is exact, so the fit is too up to float
 * rounding; the 8-bit read-back adds at most 0.5/255 * 2 per component, under 0.4 degrees.
 * Measured: 0.163 degrees on every interior pixel (the fit is exact, so all show one colour, and
 * that is the 8-bit rounding of the true normal). A fit with A and B swapped, or the normal not
 * turned towards the eye, lands tens of degrees off. */
static void test_tilted_normals(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = 40000, E = 4 };
    const double ax = 35 * M_PI / 180, ay = 20 * M_PI / 180;
    /* Rotation R = Ry(ay) Rx(ax) applied to the square's (u, v, 0) and to its normal (0, 0, 1). */
    const double rx[3][3] = {{1, 0, 0}, {0, cos(ax), -sin(ax)}, {0, sin(ax), cos(ax)}};
    const double ry[3][3] = {{cos(ay), 0, sin(ay)}, {0, 1, 0}, {-sin(ay), 0, cos(ay)}};
    double rot[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            rot[i][j] = 0;
            for (int k = 0; k < 3; k++) rot[i][j] += ry[i][k] * rx[k][j];
        }
    const double nt[3] = {rot[0][2], rot[1][2], rot[2][2]};
    rng g;
    g.s = 12;
    pc_prepared pc;
    tu_new_cloud(&pc, N, 0);
    for (uint64_t i = 0; i < N; i++) {
        double u = uniform(&g) - 0.5, v = uniform(&g) - 0.5;
        for (int k = 0; k < 3; k++) pc.pos[3 * i + k] = (float)(rot[k][0] * u + rot[k][1] * v);
    }
    pc.sigma = poisson_sigma(1.0, N);
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, 2.0, 40, W, H);
    sp_params p;
    params_of(kf, &p);
    p.pipeline = SP_PIPE_KAWATA;
    p.color = SP_COLOR_NORMAL;
    rnd_frame f = {0};
    tu_render(r, id, &cam, &p, 0, &f);
    int interior = 0;
    double sum = 0, worst = 0;
    for (int y = E; y < H - E; y++)
        for (int x = E; x < W - E; x++) {
            int in = 1;
            for (int dy = -E; dy <= E && in; dy++)
                for (int dx = -E; dx <= E && in; dx++)
                    in = !is_bg(f.rgba8 + 4 * ((y + dy) * W + x + dx));
            if (!in) continue;
            const uint8_t *c = f.rgba8 + 4 * (y * W + x);
            double n[3], l = 0, dot = 0;
            for (int k = 0; k < 3; k++) n[k] = c[k] / 255.0 * 2 - 1, l += n[k] * n[k];
            for (int k = 0; k < 3; k++) dot += n[k] / sqrt(l) * nt[k];
            double deg = acos(fmin(1.0, dot)) * 180 / M_PI;
            sum += deg;
            worst = fmax(worst, deg);
            interior++;
        }
    printf("tilted plane: %d interior pixels, normal error mean %.3f max %.3f degrees "
           "(buffer %dx%d)\n", interior, sum / interior, worst, f.buffer_w, f.buffer_h);
    assert_true(interior > W * H / 5);
    assert_true(worst <= 3.0);
    rnd_frame_free(&f);
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* ---- holes ---- */

/* A sparse plane facing the camera: 3000 uniformly random points of a unit square, about 3
 * pixels apart on screen. `points` leaves most of the square's pixels empty; kawata must cover
 * every pixel of the square's projection shrunk by 4 pixels (the splats' cut-off blurs the
 * silhouette by up to 1.5 buffer pixels either way). */
static void test_sparse_holes(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = 3000, M = 4 };
    rng g;
    g.s = 13;
    pc_prepared pc;
    tu_new_cloud(&pc, N, 0);
    for (uint64_t i = 0; i < N; i++) {
        pc.pos[3 * i] = (float)(uniform(&g) - 0.5);
        pc.pos[3 * i + 1] = (float)(uniform(&g) - 0.5);
        pc.pos[3 * i + 2] = 0;
    }
    pc.sigma = poisson_sigma(1.0, N);
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, 2.0, 40, W, H);
    /* The square's half-width in pixels: 0.5 / (2 tan 20deg) * H / 2 */
    double half = 0.5 / (2.0 * tan(20 * M_PI / 180)) * H / 2;
    int x0 = (int)ceil(W / 2.0 - half) + M, x1 = (int)floor(W / 2.0 + half) - M;
    int empty[2] = {0, 0}, total = 0;
    for (int k = 0; k < 2; k++) {
        sp_params p;
        params_of(kf, &p);
        p.pipeline = k == 0 ? SP_PIPE_POINTS : SP_PIPE_KAWATA;
        rnd_frame f = {0};
        tu_render(r, id, &cam, &p, 0, &f);
        total = 0;
        for (int y = x0; y < x1; y++)
            for (int x = x0; x < x1; x++, total++) empty[k] += is_bg(f.rgba8 + 4 * (y * W + x));
        if (k == 1)
            printf("sparse plane: kawata buffer %dx%d, %llu splats\n", f.buffer_w, f.buffer_h,
                   (unsigned long long)f.splats_drawn);
        rnd_frame_free(&f);
    }
    printf("sparse plane: %d pixels inside; empty: points %d, kawata %d\n", total, empty[0],
           empty[1]);
    assert_true(total > 10000);
    assert_true(empty[0] > total / 2); /* the cloud is sparse: points leaves holes */
    assert_int_equal(empty[1], 0);
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* ---- buffer sets ---- */

/* A cloud split into several buffer sets (rnd_desc.max_set_points, as the renderer does for
 * clouds over GL_MAX_TEXTURE_BUFFER_SIZE / 3 points) draws exactly what one set draws: passes 1
 * and 2 key points by their cloud-wide index and pass 3 resolves each set's own points
 * (pipe_kawata.c), so the frames must be equal bit for bit, in colour and in depth. The scene
 * is test_outliers' plane with its outliers, whose last points (the outliers) land in the last
 * set, under the camera of test_outliers and a closer, tilted one. */
static void test_buffer_sets(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = 20000, NOUT = N / 20 };
    rnd_ctx *r4 = create(kf->host_paths, 6000);
    rng g;
    g.s = 14;
    pc_prepared pc;
    tu_new_cloud(&pc, N + NOUT, 0);
    for (uint64_t i = 0; i < N + NOUT; i++) {
        float *p = pc.pos + 3 * i;
        p[0] = (float)(uniform(&g) - 0.5), p[1] = (float)(uniform(&g) - 0.5);
        p[2] = i < N ? (float)(0.002 * gauss(&g)) : (float)(0.05 + 0.45 * uniform(&g));
        if (i >= N) set_rgb(&pc, i, 255, 0, 0);
        else set_rgb(&pc, i, (uint8_t)(100 + i % 100), 200, (uint8_t)(i % 256));
    }
    pc.sigma = poisson_sigma(1.0, N);
    tu_finish_cloud(&pc, OFF);
    uint32_t id1 = tu_upload(r, &pc), id4 = tu_upload(r4, &pc);
    const rnd_camera cams[2] = {cam_at(0, 0, 2.0, 40, W, H), cam_at(0.4, -0.3, 1.2, 50, W, H)};
    for (int v = 0; v < 2; v++) {
        sp_params p;
        params_of(kf, &p);
        p.pipeline = SP_PIPE_KAWATA;
        rnd_frame f1 = {0}, f4 = {0};
        tu_render(r, id1, &cams[v], &p, 1, &f1);
        tu_render(r4, id4, &cams[v], &p, 1, &f4);
        size_t n = (size_t)W * H, covered = 0;
        for (size_t i = 0; i < n; i++) covered += !is_bg(f1.rgba8 + 4 * i);
        int same = memcmp(f1.rgba8, f4.rgba8, n * 4) == 0 &&
                   memcmp(f1.depth, f4.depth, n * sizeof *f1.depth) == 0;
        printf("buffer sets, view %d: %zu covered, %llu splats one set, %llu four; identical %d\n",
               v, covered, (unsigned long long)f1.splats_drawn,
               (unsigned long long)f4.splats_drawn, same);
        assert_true(covered > n / 5);
        assert_int_equal(f1.splats_drawn, f4.splats_drawn);
        assert_true(same);
        rnd_frame_free(&f1);
        rnd_frame_free(&f4);
    }
    rnd_release(r, id1);
    rnd_release(r4, id4);
    rnd_destroy(r4);
    pc_prepared_free(&pc);
}

/* ---- the other back end ---- */

/* OSMesa (the software fallback, gl_osmesa.c) draws kawata and EDL exactly as EGL does: the
 * same llvmpipe runs behind both, so the frames of test_buffer_sets' scene (kawata with
 * shading=edl, 8-bit and float targets) must be equal bit for bit. Where OSMesa cannot be
 * opened the comparison is impossible and skipped with the reason. The EGL frames are made
 * first; then a second EGL renderer is created and destroyed, which leaves EGL with no current
 * context, and only then the OSMesa one (as test_render_splat's test_fixed_point_and_osmesa
 * does). Rendering with the two back ends alternately in one process sent the EGL renderer's
 * calls to no context (GL errors, incomplete framebuffers): eglMakeCurrent of the context EGL
 * believes current does not rebind after OSMesa took the shared dispatch. The daemon opens one
 * back end, so this is a limit of tests, not of the renderer's use. */
static void test_osmesa(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = 20000 };
    rng g;
    g.s = 15;
    pc_prepared pc;
    tu_new_cloud(&pc, N, 0);
    for (uint64_t i = 0; i < N; i++) {
        float *p = pc.pos + 3 * i;
        p[0] = (float)(uniform(&g) - 0.5), p[1] = (float)(uniform(&g) - 0.5);
        p[2] = (float)(0.2 * p[0] * p[0] + 0.002 * gauss(&g)); /* a curved, noisy sheet */
        set_rgb(&pc, i, (uint8_t)(100 + i % 100), 180, (uint8_t)(i % 256));
    }
    pc.sigma = poisson_sigma(1.0, N);
    tu_finish_cloud(&pc, OFF);
    rnd_camera cam = cam_at(0.3, 0.4, 1.6, 45, W, H);
    sp_params p;
    params_of(kf, &p);
    p.pipeline = SP_PIPE_KAWATA;
    p.shading = SP_SHADING_EDL;
    rnd_frame fe[2] = {{0}, {0}}, fo[2] = {{0}, {0}};
    uint32_t ide = tu_upload(r, &pc);
    for (int fl = 0; fl < 2; fl++) tu_render(r, ide, &cam, &p, fl, &fe[fl]);
    rnd_release(r, ide);
    rnd_desc de = desc_of(kf->host_paths, 0);
    sd_err err = {0};
    rnd_destroy(rnd_create(&de, &err));
    rnd_desc d = desc_of(kf->host_paths, 0);
    d.backend = RND_BACKEND_OSMESA;
    rnd_ctx *ro = rnd_create(&d, &err);
    if (ro) {
        uint32_t ido = tu_upload(ro, &pc);
        for (int fl = 0; fl < 2; fl++) tu_render(ro, ido, &cam, &p, fl, &fo[fl]);
        rnd_release(ro, ido);
        rnd_destroy(ro);
    }
    pc_prepared_free(&pc);
    size_t n = (size_t)W * H, covered = 0;
    for (size_t i = 0; i < n; i++) covered += !is_bg(fe[0].rgba8 + 4 * i);
    assert_true(covered > n / 5);
    int same[2] = {0, 0};
    for (int fl = 0; fl < 2 && ro; fl++) {
        same[fl] = memcmp(fe[fl].rgba8, fo[fl].rgba8, n * 4) == 0;
        printf("osmesa, %s target: %zu covered, identical to egl %d\n", fl ? "float" : "8-bit",
               covered, same[fl]);
    }
    for (int fl = 0; fl < 2; fl++) rnd_frame_free(&fe[fl]), rnd_frame_free(&fo[fl]);
    if (!ro) TU_SKIP("OSMesa back end unavailable: %s", err.msg);
    assert_true(same[0] && same[1]);
}

/* ---- a real scan ---- */

/* The lowest PSNR over covered pixels accepted against golden_bunny_kawata.png. The golden was
 * made by this pipeline (SPLATD_WRITE_GOLDEN=1 rewrites it) and guards against regressions; the
 * analytic tests above check correctness. Float atomics play no part in kawata's colours
 * (passes 1-2 use integer atomics only, and the fit and the gather are deterministic), so
 * frames repeat bit for bit; the bound allows llvmpipe's rounding to differ by one in 6.5 % of
 * the channel values (48.13 dB - 10 log10(0.065)), as test_render_splat's golden bound does.
 * Measured: identical (inf dB) with LP_NUM_THREADS 1, 2 and 8, LP_NATIVE_VECTOR_WIDTH=128 and
 * in the ASan build; 89.6 dB since the fit's determinants and normal length are written out
 * with `precise` (for the host fit to repeat them word for word): a rounding shift, the golden
 * kept. Shader mutations land far under the bound: A and B swapped in the fit
 * 26.4 dB, gamma 100x 23.3 dB, the splats' cut-off 0.55x 12.3 dB, the fit's second round
 * disabled 47.4 dB. */
#define GOLDEN_MIN_DB 60.0

/* tests/data/bunnyData.pts (30,571 positions, no colours, no normals): loaded and prepared (for
 * sigma, as the daemon does), rendered with kawata at 320x240 from the default camera: the frame
 * is non-blank, repeats exactly on a second render, and matches its golden image (llvmpipe
 * only: another renderer's rounding differs, and the comparison is skipped, never passed). */
static void test_bunny(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { BW = 320, BH = 240 };
    pc_prepared pc;
    tu_prep_data("bunnyData.pts", &pc);
    assert_false(pc.attrs & PC_ATTR_RGB);
    assert_true(pc.sigma > 0);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam;
    tu_camera_box(pc.bmin, pc.bmax, BW, BH, &cam);
    pc_prepared_free(&pc);
    sp_params p;
    params_of(kf, &p);
    p.pipeline = SP_PIPE_KAWATA;
    rnd_frame f[2] = {{0}, {0}};
    for (int k = 0; k < 2; k++) tu_render(r, id, &cam, &p, 0, &f[k]);
    size_t covered = 0, differ = 0;
    for (int i = 0; i < BW * BH; i++) {
        covered += !is_bg(f[0].rgba8 + 4 * i);
        differ += memcmp(f[0].rgba8 + 4 * i, f[1].rgba8 + 4 * i, 4) != 0;
    }
    printf("bunny: %zu of %d pixels covered, buffer %dx%d, %llu splats, %zu differ between two "
           "frames\n", covered, BW * BH, f[0].buffer_w, f[0].buffer_h,
           (unsigned long long)f[0].splats_drawn, differ);
    assert_true(covered > (size_t)BW * BH / 10);
    assert_int_equal(differ, 0);
    char gpath[4096];
    tu_data("golden_bunny_kawata.png", gpath, sizeof gpath);
    const char *wg = getenv("SPLATD_WRITE_GOLDEN");
    if (wg && *wg == '1') {
        assert_int_equal(tu_png_write(gpath, BW, BH, f[0].rgba8, 1), 0);
        printf("wrote %s\n", gpath);
    }
    int llvmpipe = strstr(rnd_renderer_string(r), "llvmpipe") != NULL;
    double db = INFINITY;
    size_t ncov = 0;
    if (llvmpipe) {
        uint32_t gw, gh;
        uint8_t *g = NULL;
        if (tu_png_read(gpath, 1, &gw, &gh, &g) < 0) fail_msg("cannot read %s", gpath);
        assert_int_equal(gw, BW);
        assert_int_equal(gh, BH);
        db = tu_psnr_covered(f[0].rgba8, g, (size_t)BW * BH, &ncov);
        free(g);
        printf("bunny: PSNR against the golden over %zu covered pixels %.2f dB\n", ncov, db);
    }
    rnd_frame_free(&f[0]);
    rnd_frame_free(&f[1]);
    rnd_release(r, id);
    if (!llvmpipe)
        TU_SKIP("golden comparison: the golden is llvmpipe's rounding and the renderer is %s",
                rnd_renderer_string(r));
    if (!(db >= GOLDEN_MIN_DB))
        fail_msg("bunny: %.2f dB from the golden, under %.0f dB", db, GOLDEN_MIN_DB);
}

/* ---- pass 2's step clamp ---- */

/* Pass 2 quantises a point's depth step behind the nearest into levels (pipe_kawata.c: uint(step
 * qscale), qscale = (qmax - 1) / gamma) and clamps the level to qtop - 1 = qmax - 2, so that a
 * step of exactly gamma, whose product may round to qmax - 1, saturates with the rest; among
 * equal levels the greater index wins. A scene that reaches the clamp: 2^19 + 3 points (20 index
 * bits, qmax = 4095), the filler off the view axis, and on it, seen from the local origin down
 * -z so that a point's eye depth is exactly -z: F at depth gamma (the nearest), A at 2 gamma (a
 * step of exactly gamma) and B, of a greater index, a step gamma - delta with delta half a level
 * (level qtop - 1 without any clamp). gamma is chosen among a few kawata_gamma values so that
 * gamma qscale rounds to qmax - 1 (the clamp's branch taken; computed here with the pipeline's
 * float operations, each correctly rounded on any GL). With the clamp A and B tie and B wins;
 * without it A would. The probe must show near = F and far = B at level qtop - 1. */
static void test_far_step_clamp(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { N = (1 << 19) + 3 };
    const uint32_t ibits = 20, qmax = (1u << (32 - ibits)) - 1u, qtop = qmax - 1u;
    /* the filler's box and an anchor at the eye set the bounds: (-0.5, -0.5, -1) to (0.5, 0.5, 0) */
    const float lo[3] = {-0.5f, -0.5f, -1.0f}, hi[3] = {0.5f, 0.5f, 0.0f};
    double diag = 0;
    for (int i = 0; i < 3; i++) diag += ((double)hi[i] - lo[i]) * (hi[i] - lo[i]);
    float gfrac = 0, gamma = 0, qscale = 0;
    for (int k = 0; k < 200 && !gfrac; k++) {
        float g = 0.0075f + 1e-6f * (float)k;
        float gm = (float)(g * sqrt(diag)), qs = (float)(qmax - 1) / gm;
        if ((uint32_t)(gm * qs) >= qtop) gfrac = g, gamma = gm, qscale = qs;
    }
    assert_true(gfrac > 0);
    const float delta = 0.5f / qscale;
    pc_prepared pc;
    tu_new_cloud(&pc, N, 0);
    rng g;
    g.s = 99;
    for (uint64_t i = 0; i < N - 3; i++) {
        float *q = pc.pos + 3 * i;
        q[0] = (float)(0.2 + 0.3 * uniform(&g)) * (i % 2 ? 1 : -1);
        q[1] = (float)(uniform(&g) - 0.5);
        q[2] = (float)(-0.5 - 0.5 * uniform(&g));
    }
    float *q0 = pc.pos; /* the filler's corners, and the anchor at the eye */
    q0[0] = lo[0], q0[1] = lo[1], q0[2] = lo[2];
    q0[3] = hi[0], q0[4] = hi[1], q0[5] = -0.5f;
    q0[6] = 0.4f, q0[7] = 0.4f, q0[8] = 0.0f;
    const uint32_t iF = N - 3, iA = N - 2, iB = N - 1;
    pc.pos[3 * iF + 2] = -gamma;
    pc.pos[3 * iA + 2] = -2.0f * gamma;
    pc.pos[3 * iB + 2] = -(2.0f * gamma - delta);
    for (uint32_t i = iF; i <= iB; i++) pc.pos[3 * i] = pc.pos[3 * i + 1] = 0.0f;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    pc_prepared_free(&pc);
    rnd_camera cam = {{OFF[0], OFF[1], OFF[2]}, {OFF[0], OFF[1], OFF[2] - 1.0}, {0, 1, 0},
                      40, 0.5f * gamma, 2.0f, 64, 64};
    sp_params p;
    params_of(kf, &p);
    p.pipeline = SP_PIPE_KAWATA;
    p.kawata_gamma = gfrac;
    rnd_frame f = {0};
    rnd_set_kawata_probe(r, 1);
    tu_render(r, id, &cam, &p, 0, &f);
    rnd_set_kawata_probe(r, 0);
    assert_non_null(f.kawata_arrays);
    size_t nb = (size_t)f.buffer_w * f.buffer_h, q = nb;
    for (size_t i = 0; i < nb; i++)
        if (f.kawata_arrays[nb + i] == iF) q = i;
    assert_true(q < nb);
    uint32_t far = f.kawata_arrays[2 * nb + q];
    printf("far step clamp: gamma %.7g (kawata_gamma %.7g), gamma qscale %.3f; near %u, far "
           "index %u level %u (want %u and %u: B %u, A %u)\n", (double)gamma, (double)gfrac,
           (double)(gamma * qscale), f.kawata_arrays[nb + q], far & ((1u << ibits) - 1u),
           far >> ibits, iB, qtop, iB, iA);
    assert_int_equal(far & ((1u << ibits) - 1u), iB);
    assert_int_equal(far >> ibits, qtop);
    rnd_frame_free(&f);
    rnd_release(r, id);
}

/* ---- the two places of passes 1 and 2 ---- */

/* host_vs_gl: cloud pc, uploaded as idg to gl (no host paths) and idh to host (host paths),
 * drawn by kawata at cam with kawata_rho_scale rho and colour mode color, its arrays probed
 * (rnd_set_kawata_probe), compared by kw_compare (kwcheck.h: within what the GLSL
 * specification allows the shaders); at least min_covered buffer pixels must have a nearest
 * point, so that a comparison of empty arrays cannot pass, and the splats probed must be those
 * counted. */
static void host_vs_gl(rnd_ctx *gl, uint32_t idg, rnd_ctx *host, uint32_t idh,
                       const pc_prepared *pc, const rnd_camera *cam, float rho, int color,
                       const char *what, size_t min_covered)
{
    rnd_frame f[2] = {{0}, {0}};
    rnd_ctx *r[2] = {gl, host};
    const uint32_t id[2] = {idg, idh};
    sp_params p;
    sp_params_defaults(&p);
    p.pipeline = SP_PIPE_KAWATA;
    p.kawata_rho_scale = rho;
    p.color = color;
    for (int k = 0; k < 2; k++) {
        rnd_set_kawata_probe(r[k], 1);
        tu_render(r[k], id[k], cam, &p, 0, &f[k]);
        rnd_set_kawata_probe(r[k], 0);
    }
    kw_cmp c;
    kw_compare(&f[0], &f[1], pc->pos, pc->n, 1, pc->n, pc->offset, pc->bmin, pc->bmax, cam, what,
               &c);
    size_t nb = (size_t)f[1].buffer_w * f[1].buffer_h, nspl = 0;
    for (size_t i = 0; i < nb; i++) nspl += f[1].kawata_arrays[19 * nb + 8 * i + 3] != 0;
    assert_int_equal(nspl, f[1].splats_drawn);
    assert_true(c.covered >= min_covered);
    rnd_frame_free(&f[0]);
    rnd_frame_free(&f[1]);
}

/* The host paths' passes 1-3 (kawata_cpu.h) against the compute shaders, within the precision a
 * conforming GPU owes the shaders (kwcheck.h says which and why), on real scans (Guanyin.ply,
 * 640x360 at the default rho and at rho 1, the buffer then the frame, a close-up that the
 * frustum cuts, and every colour mode: rgb, intensity and the others on the host, field's
 * colour map in the GL after the host's passes 1-2; bunnyData.pts) and on a cloud split into
 * buffer sets of 6000 points (bunnyData.pts: 6 sets, points keyed by their cloud-wide index;
 * with intensities 0-999 for color=intensity). On llvmpipe, whose division is IEEE's and whose
 * STAGE 1 products are not fused, nothing differs at all. */
static void test_host_vs_gl(void **state)
{
    (void)state;
    enum { FW = 640, FH = 360 };
    tu_scans sc;
    tu_scans_load(&sc, FW, FH);
    pc_prepared *g = &sc.g, *b = &sc.b;
    rnd_ctx *gl = create(RND_CAP_OFF, 0), *host = create(RND_CAP_ON, 0);
    uint32_t gg = tu_upload(gl, g), gh = tu_upload(host, g);
    uint32_t bg = tu_upload(gl, b), bh = tu_upload(host, b);
    host_vs_gl(gl, gg, host, gh, g, &sc.cg, 3.5f, SP_COLOR_RGB, "Guanyin", 1000);
    static const char *const cname[5] = {"rgb", "field", "normal", "depth", "intensity"};
    for (int col = SP_COLOR_FIELD; col <= SP_COLOR_INTENSITY; col++) {
        char what[64];
        snprintf(what, sizeof what, "Guanyin color=%s", cname[col]);
        host_vs_gl(gl, gg, host, gh, g, &sc.cg, 3.5f, col, what, 1000);
    }
    host_vs_gl(gl, gg, host, gh, g, &sc.cg, 0.25f, SP_COLOR_RGB, "Guanyin rho 1", 10000);
    host_vs_gl(gl, gg, host, gh, g, &sc.close, 3.5f, SP_COLOR_RGB, "Guanyin close-up", 1000);
    host_vs_gl(gl, bg, host, bh, b, &sc.cb, 3.5f, SP_COLOR_RGB, "bunny", 500);
    rnd_destroy(gl);
    rnd_destroy(host);
    gl = create(RND_CAP_OFF, 6000), host = create(RND_CAP_ON, 6000);
    bg = tu_upload_intensities(gl, b), bh = tu_upload_intensities(host, b);
    host_vs_gl(gl, bg, host, bh, b, &sc.cb, 3.5f, SP_COLOR_RGB, "bunny in 6 buffer sets", 500);
    host_vs_gl(gl, bg, host, bh, b, &sc.cb, 0.25f, SP_COLOR_RGB, "bunny in 6 sets, rho 1", 500);
    host_vs_gl(gl, bg, host, bh, b, &sc.cb, 3.5f, SP_COLOR_INTENSITY,
               "bunny in 6 sets, color=intensity", 500);
    rnd_destroy(gl);
    rnd_destroy(host);
    tu_scans_free(&sc);
}

/* ---- EDL ---- */

/* A grid of nx x ny points, spacing h, at height z, x from x0, centred on y = 0, colour c. */
static void grid(pc_prepared *pc, uint64_t first, int nx, int ny, float h, float x0, float z,
                 uint8_t c)
{
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            uint64_t k = first + (uint64_t)j * nx + i;
            pc->pos[3 * k] = x0 + i * h;
            pc->pos[3 * k + 1] = (j - 0.5f * (ny - 1)) * h;
            pc->pos[3 * k + 2] = z;
            set_rgb(pc, k, c, c, c);
        }
}

/* edl_strength 0 leaves every pipeline's frame as shading=lambert draws it, bit for bit (8-bit
 * and float targets), on a scene with depth steps (two planes), where any strength > 0 does
 * change it (checked, so the comparison can fail). */
static void test_edl_strength_zero(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { S = 120 };
    pc_prepared pc;
    tu_new_cloud(&pc, 2 * S * S, 0);
    grid(&pc, 0, S, S, 0.006f, -0.5f, 0.0f, 200);
    grid(&pc, S * S, S, S, 0.006f, -0.1f, 0.3f, 200);
    pc.sigma = 0.006f;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0.1, 0.2, 2.0, 40, W, H);
    for (int pipe = 0; pipe < SP_PIPE_COUNT; pipe++)
        for (int fl = 0; fl < 2; fl++) {
            rnd_frame f[3] = {{0}, {0}, {0}};
            for (int k = 0; k < 3; k++) {
                sp_params p;
                params_of(kf, &p);
                p.pipeline = pipe;
                if (k > 0) p.shading = SP_SHADING_EDL;
                p.edl_strength = k == 1 ? 0.0f : 1.0f;
                tu_render(r, id, &cam, &p, fl, &f[k]);
            }
            size_t n = (size_t)W * H * 4;
            int same = memcmp(f[0].rgba8, f[1].rgba8, n) == 0;
            if (fl) same &= memcmp(f[0].rgba16f, f[1].rgba16f, n * 2) == 0 &&
                            memcmp(f[0].depth, f[1].depth, n) == 0;
            int changed = memcmp(f[0].rgba8, f[2].rgba8, n) != 0;
            printf("edl strength 0, pipeline %d, %s target: identical %d; strength 1 changes it "
                   "%d\n", pipe, fl ? "float" : "8-bit", same, changed);
            assert_true(same);
            assert_true(changed);
            for (int k = 0; k < 3; k++) rnd_frame_free(&f[k]);
        }
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* At a depth step of known size: a plane at eye depth 4.5 (x < 0) in front of one at depth 5,
 * both facing the camera, white, drawn by `points` (exact eye depths, dense enough to cover
 * every pixel). For every pixel of the far plane, the neighbours at edl_radius 1 (the shader's 4
 * directions) that lie on the near plane are counted from the read-back depth, and the expected
 * shade is exp(-RND_EDL_SCALE * strength / 4 * count * log2(5 / 4.5)); the measured colour
 * ratio (EDL frame / lambert frame) must match it within 1 % (the bound; 8-bit rounding
 * adds at most 0.5/255 / shade < 0.4 % at the shades here, >= 0.56). The pixels next to the
 * step on its far side are darkened (count 1), those farther from it are not (count 0), and
 * the near plane's pixels keep their colour exactly (their neighbours are farther:
 * max(0, .) = 0). */
static void test_edl_step(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { S = 800 };
    const float strength = 0.05f;
    pc_prepared pc;
    tu_new_cloud(&pc, 2 * S * S, 0);
    const float h = 2.0f / S; /* 2 x 2 planes, ~0.5 pixel spacing at these depths */
    grid(&pc, 0, S / 2, S, h, -1.0f, 0.5f, 255);      /* near: x in [-1, 0), z = 0.5 */
    grid(&pc, (uint64_t)S * S / 2, S / 2, S, h, 0.0f, 0.0f, 255); /* far: x in [0, 1) */
    grid(&pc, (uint64_t)S * S, S / 2, S, h, -1.0f + h / 2, 0.0f, 255); /* far, behind */
    pc.sigma = h;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, 5.0, 20, W, H);
    cam.znear = 1.0f, cam.zfar = 10.0f;
    sp_params p;
    params_of(kf, &p);
    p.pipeline = SP_PIPE_POINTS;
    rnd_frame base = {0}, ef = {0};
    tu_render(r, id, &cam, &p, 1, &base);
    p.shading = SP_SHADING_EDL;
    p.edl_strength = strength;
    tu_render(r, id, &cam, &p, 0, &ef);
    const int off[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
    const double step = log2(5.0 / 4.5);
    int checked[3] = {0, 0, 0}, near_px = 0, near_changed = 0;
    double worst = 0;
    for (int y = 1; y < H - 1; y++)
        for (int x = 1; x < W - 1; x++) {
            float z = base.depth[y * W + x];
            if (!isfinite(z)) continue;
            const uint8_t *b = base.rgba8 + 4 * (y * W + x), *e = ef.rgba8 + 4 * (y * W + x);
            if (fabsf(z - 4.5f) < 1e-3f) {
                near_px++;
                near_changed += memcmp(b, e, 3) != 0;
                continue;
            }
            assert_true(fabsf(z - 5.0f) < 1e-3f);
            int cnt = 0, all = 1;
            for (int k = 0; k < 4; k++) {
                float zn = base.depth[(y + off[k][1]) * W + x + off[k][0]];
                all &= isfinite(zn);
                cnt += fabsf(zn - 4.5f) < 1e-3f;
            }
            if (!all || b[0] != 255) continue;
            double want = exp(-RND_EDL_SCALE * strength / 4.0 * cnt * step);
            double got = e[0] / 255.0;
            double rel = fabs(got - want) / want;
            worst = fmax(worst, rel);
            if (cnt < 3) checked[cnt]++;
        }
    printf("edl step: far-plane pixels with 0/1/2 nearer neighbours %d/%d/%d, shade at "
           "the step %.4f, worst relative error %.4f; near-plane pixels %d, changed %d\n",
           checked[0], checked[1], checked[2],
           exp(-RND_EDL_SCALE * strength / 4.0 * step), worst, near_px, near_changed);
    assert_true(checked[1] > 100); /* the step's column along most of the frame's height */
    assert_true(checked[0] > W * H / 4);
    assert_true(near_px > W * H / 4);
    assert_true(worst <= 0.01);
    assert_int_equal(near_changed, 0);
    rnd_frame_free(&ef);
    rnd_frame_free(&base);
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* A flat plane facing the camera has one eye depth everywhere, so EDL (default strength 1)
 * darkens none of its pixels: the frame equals shading=lambert's bit for bit, in every
 * pipeline (points: exact depths; kawata: weighted means of equal depths, exact; splat:
 * ray-disc depths that may differ in the last bits, whose shade rounds to 1 in 8 bits). */
static void test_edl_flat(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { S = 300 };
    pc_prepared pc;
    tu_new_cloud(&pc, S * S, 0);
    grid(&pc, 0, S, S, 0.004f, -0.6f, 0.0f, 180);
    pc.sigma = 0.004f;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, 2.0, 40, W, H);
    for (int pipe = 0; pipe < SP_PIPE_COUNT; pipe++) {
        rnd_frame f[2] = {{0}, {0}};
        for (int k = 0; k < 2; k++) {
            sp_params p;
            params_of(kf, &p);
            p.pipeline = pipe;
            p.shading = k ? SP_SHADING_EDL : SP_SHADING_LAMBERT;
            tu_render(r, id, &cam, &p, 0, &f[k]);
        }
        int covered = 0, darker = 0;
        for (int i = 0; i < W * H; i++) {
            covered += !is_bg(f[0].rgba8 + 4 * i);
            darker += memcmp(f[0].rgba8 + 4 * i, f[1].rgba8 + 4 * i, 3) != 0;
        }
        printf("edl flat plane, pipeline %d: %d covered, %d changed\n", pipe, covered, darker);
        assert_true(covered > W * H / 4);
        assert_int_equal(darker, 0);
        rnd_frame_free(&f[0]);
        rnd_frame_free(&f[1]);
    }
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

/* The shade edl.frag must give a pixel of eye depth z whose neighbours at radius r are z_n
 * (+inf: background), in double: exp(-k log2 prod_n z / clamp(z_n, z / 2^15, z)), 1 for a
 * background pixel. */
static double edl_shade(const float *depth, int w, int h, int x, int y, int r, double k)
{
    double z = depth[(size_t)y * w + x];
    if (!isfinite(z)) return 1.0;
    const int off[4][2] = {{r, 0}, {0, r}, {-r, 0}, {0, -r}};
    double prod = 1.0;
    for (int q = 0; q < 4; q++) {
        int nx = x + off[q][0], ny = y + off[q][1];
        double zn = nx < 0 || ny < 0 || nx >= w || ny >= h ? INFINITY
                                                           : depth[(size_t)ny * w + nx];
        zn = zn < z / 32768.0 ? z / 32768.0 : zn > z ? z : zn;
        prod *= z / zn;
    }
    return exp(-k * log2(prod));
}

/* The relative error a conforming GPU may give that shade (GLSL 4.50, 4.7.1; u = 2^-24, first
 * order in u; edl.frag's operations in turn): the four ratios z / z_n, divisions of exact
 * inputs (the clamp and z / 2^15 are exact), 2.5 ulp <= 5u each, and their three products, u
 * each: prod within 23u relative; log2 within 2^-21 absolute inside [0.5, 2] and 3 ulp <= 6u |L|
 * outside, plus prod's error carried, 23u / ln 2; x = -k L one more rounding (u |x|, k being the
 * same float uniform here); exp within (3 + 2 |x|) ulp <= (3 + 2 |x|) 2u relative, plus |dx|.
 * Doubled for the terms of order u^2 and for the reference's own rounding. */
static double edl_rel_bound(double shade, double k)
{
    const double u = 0x1p-24;
    if (shade >= 1.0) return 2 * 6 * u; /* L = 0: exact ratios of 1, exp(0) within 3 ulp */
    double x = log(shade), L = -x / k;
    double dl = (L <= 1.0 ? 0x1p-21 : 6 * u * L) + 23 * u / log(2.0);
    double dx = k * dl + u * fabs(x);
    return 2 * (dx + (3 + 2 * fabs(x)) * 2 * u);
}

/* edl.frag's branches on the GL, against edl_shade within what the specification allows: a scene
 * drawn by `points` (one point a pixel, white, exact eye depths read back) of 8x8 blocks at eye
 * depth 1000, each with a centre pixel of one kind: as deep (no shade), a neighbour at depth
 * 0.02 (ratio 50000: clamped to 2^15, the clamp's upper branch), at 0.05 (ratio 20000: not
 * clamped), at 1500 (farther: the clamp's lower branch, nothing added), or empty (a background
 * neighbour: nothing added); around the blocks, background pixels inside the pass's rectangle
 * (the background branch: the grey background stays exactly as shading=lambert leaves it; the
 * pass's rectangle is the whole frame here, as the points near the eye put the cloud's box
 * there). At radius 1 and 3,
 * strength 0.001 (k = 0.075: a clamped neighbour alone leaves shade 0.325, against 0.288
 * unclamped: 9 levels apart), 8-bit and half-float targets:
 *   8-bit: |byte - 255 shade| <= 2 + 255 shade e, e = edl_rel_bound: the blend is carried out
 *   at no less than the target's 8 bits (GL 4.5, 17.3.6.1) and its result converted to one of
 *   the two nearest bytes (2.3.5.2): at most one level each;
 *   half: |half - shade| <= shade (e + 2^-10): half's own rounding is 2^-11 relative, the blend
 *   at no less than half's precision another.
 * Each kind of pixel must be there (checked), so that no branch goes untried. */
static void test_edl_branches(void **state)
{
    const kfix *kf = *state;
    rnd_ctx *r = kf->r;
    enum { B = 8, NB = 20, X0 = 48 };
    const double Z = 1000.0, E0 = 10.0, tn = tan(40.0 * M_PI / 360.0);
    pc_prepared pc;
    tu_new_cloud(&pc, (uint64_t)NB * NB * B * B, 0);
    uint64_t n = 0;
    for (int py = X0; py < X0 + NB * B; py++)
        for (int px = X0; px < X0 + NB * B; px++) {
            int bx = (px - X0) / B, by = (py - X0) / B, kind = (bx + 3 * by) % 5;
            int centre = (px - X0) % B == B / 2 && (py - X0) % B == B / 2;
            double d = Z;
            if (centre && kind == 1) d = Z / 50000.0;
            if (centre && kind == 2) d = Z / 20000.0;
            if (centre && kind == 3) d = 1.5 * Z;
            if (centre && kind == 4) continue; /* empty */
            double sx = (px + 0.5) / W * 2 - 1, sy = (py + 0.5) / H * 2 - 1;
            float *q = pc.pos + 3 * n;
            q[0] = (float)(sx * d * tn), q[1] = (float)(sy * d * tn), q[2] = (float)(E0 - d);
            set_rgb(&pc, n, 255, 255, 255);
            n++;
        }
    pc.n = n;
    tu_finish_cloud(&pc, OFF);
    uint32_t id = tu_upload(r, &pc);
    rnd_camera cam = cam_at(0, 0, E0, 40, W, H);
    cam.znear = 0.01f, cam.zfar = 2000.0f;
    const float strength = 0.001f;
    for (int rad = 1; rad <= 3; rad += 2) {
        sp_params p;
        params_of(kf, &p);
        p.pipeline = SP_PIPE_POINTS;
        p.shading = SP_SHADING_EDL;
        p.edl_strength = strength;
        p.edl_radius = (float)rad;
        p.background[0] = p.background[1] = p.background[2] = 0.4f;
        rnd_frame f8 = {0}, ff = {0}, fl = {0};
        tu_render(r, id, &cam, &p, 0, &f8);
        tu_render(r, id, &cam, &p, 1, &ff);
        p.shading = SP_SHADING_LAMBERT;
        tu_render(r, id, &cam, &p, 0, &fl);
        const double k = (double)(RND_EDL_SCALE * strength / 4.0f);
        size_t clamped = 0, unclamped = 0, farther = 0, bgnb = 0, bgpx = 0, flat = 0;
        double worst8 = 0, worst16 = 0;
        for (int y = X0 - 8; y < X0 + NB * B + 8; y++)
            for (int x = X0 - 8; x < X0 + NB * B + 8; x++) {
                size_t i = (size_t)y * W + x;
                float z = ff.depth[i];
                if (!isfinite(z)) { /* the background branch: left exactly as lambert has it */
                    bgpx++;
                    assert_memory_equal(f8.rgba8 + 4 * i, fl.rgba8 + 4 * i, 4);
                    assert_true(fabs(half_to_float(ff.rgba16f[4 * i]) - 0.4) < 1e-3);
                    continue;
                }
                const int off[4][2] = {{rad, 0}, {0, rad}, {-rad, 0}, {0, -rad}};
                for (int q = 0; q < 4; q++) {
                    float zn = ff.depth[(size_t)(y + off[q][1]) * W + x + off[q][0]];
                    clamped += zn < z / 32768.0f;
                    unclamped += zn >= z / 32768.0f && zn < z * 0.999f;
                    farther += isfinite(zn) && zn > z;
                    bgnb += !isfinite(zn);
                }
                double want = edl_shade(ff.depth, W, H, x, y, rad, k);
                flat += want == 1.0;
                double e = edl_rel_bound(want, k);
                for (int c = 0; c < 3; c++) {
                    double d8 = fabs(f8.rgba8[4 * i + c] - 255.0 * want) - 255.0 * want * e;
                    double d16 = fabs(half_to_float(ff.rgba16f[4 * i + c]) - want) / want - e;
                    worst8 = fmax(worst8, d8), worst16 = fmax(worst16, d16);
                }
            }
        printf("edl branches, radius %d: neighbours clamped %zu, unclamped nearer %zu, farther "
               "%zu, background %zu; background pixels %zu, unshaded pixels %zu; 8-bit within "
               "%.3f levels of the bound's shade, half within %.2e relative\n", rad, clamped,
               unclamped, farther, bgnb, bgpx, flat, worst8, worst16);
        assert_true(clamped >= 4 * 40 && unclamped >= 4 * 40 && farther >= 40);
        assert_true(bgnb >= 4 * 40 && bgpx >= 8 * NB * B && flat > 1000);
        assert_true(worst8 <= 2.0);
        assert_true(worst16 <= 1.0 / 1024);
        rnd_frame_free(&f8);
        rnd_frame_free(&ff);
        rnd_frame_free(&fl);
    }
    rnd_release(r, id);
    pc_prepared_free(&pc);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_outliers),
        cmocka_unit_test(test_tilted_normals),
        cmocka_unit_test(test_sparse_holes),
        cmocka_unit_test(test_buffer_sets),
        cmocka_unit_test(test_osmesa),
        cmocka_unit_test(test_bunny),
        cmocka_unit_test(test_edl_strength_zero),
        cmocka_unit_test(test_edl_step),
        cmocka_unit_test(test_edl_flat),
        cmocka_unit_test(test_edl_branches),
        cmocka_unit_test(test_far_step_clamp),
    };
    /* once: the two places of passes 1-3 compared (each with a renderer of its own) */
    const struct CMUnitTest once[] = {
        cmocka_unit_test(test_host_vs_gl),
    };
    int failed = cmocka_run_group_tests_name("host paths off", tests, setup_gl, teardown);
    failed += cmocka_run_group_tests_name("host paths on", tests, setup_host, teardown);
    failed += cmocka_run_group_tests_name("once", once, NULL, NULL);
    return failed;
}
