/* test_default_view.c — what a new user first sees of each real scan in tests/data: the default
 * view's world up by file family (LAS z up, a PCD's sensor orientation, PLY/PTS by shape), the
 * first view looking down 20-50 degrees where the cloud has a ground, and the rendered frame
 * filled: the drawn pixels' extent at least 80 % of the frame in its limiting direction. The
 * frames are rendered with the points pipeline at 320x180 from prepared clouds (server/prep/
 * view.c's view, the daemon's and the clients' default camera). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "cache.h"
#include "lod.h"
#include "prep.h"
#include "rndtest.h"
#include "testutil.h"
#include "view.h"

enum { W = 320, H = 180 };

/* fill: the extent of the frame's non-background pixels, as fractions of its width and height. */
static void fill(const rnd_frame *f, double *fw, double *fh)
{
    int x0 = f->width, x1 = -1, y0 = f->height, y1 = -1;
    for (int y = 0; y < f->height; y++)
        for (int x = 0; x < f->width; x++) {
            const uint8_t *p = f->rgba8 + 4 * ((size_t)y * f->width + x);
            if (p[0] | p[1] | p[2]) {
                if (x < x0) x0 = x;
                if (x > x1) x1 = x;
                if (y < y0) y0 = y;
                if (y > y1) y1 = y;
            }
        }
    *fw = x1 >= x0 ? (double)(x1 - x0 + 1) / f->width : 0;
    *fh = y1 >= y0 ? (double)(y1 - y0 + 1) / f->height : 0;
}

/* Each file's expected world up (0: x, 1: y, 2: z; -1: a sensor's, checked apart). */
static const struct scan {
    const char *name;
    int up_axis;
    int ground;               /* looks down 20-50 degrees (a z-up or flat cloud) */
} scans[] = {
    {"autzen_trim.las", 2, 1},
    {"file_with_both_wkt_and_geotiff_vlrs.las", 2, 1},
    {"1815.laz", 2, 1},
    {"ellipsoid.laz", 2, 1},
    {"samp11-utm.pcd", 2, 1},       /* georeferenced: z up although a PCD */
    {"autzen-utm.pcd", 2, 1},
    {"points_agisoft.xyz", 2, 1},   /* georeferenced XYZ */
    {"bun000.ply", 1, 0},           /* the Stanford scans are y up */
    {"bunnyData.pts", 1, 0},
    {"Guanyin.ply", 1, 0},
    {"rops_cloud.pcd", -1, 0},      /* PCD, identity VIEWPOINT: looks along -z, +y up */
    {"table_scene_mug_stereo_textured.pcd", -1, 0},
};

static void test_real_scans(void **state)
{
    (void)state;
    for (size_t i = 0; i < sizeof scans / sizeof scans[0]; i++) {
        const struct scan *s = &scans[i];
        pc_prepared pc;
        tu_prep_data(s->name, &pc);
        sp_view v;
        view_of_prepared(&pc, &v);
        if (s->up_axis >= 0) {
            for (int a = 0; a < 3; a++)
                if (v.up[a] != (a == s->up_axis ? 1.0 : 0.0))
                    fail_msg("%s: up (%g %g %g), want axis %d", s->name, v.up[0], v.up[1],
                             v.up[2], s->up_axis);
        }
        double down = asin(-(v.dir[0] * v.up[0] + v.dir[1] * v.up[1] + v.dir[2] * v.up[2])) *
                      180 / M_PI;
        if (s->ground && !(down >= 20 && down <= 50))
            fail_msg("%s: the first view looks %.1f degrees down, want 20-50", s->name, down);
        rnd_camera cam;
        rnd_camera_frame(&v, W, H, 0, &cam);
        sp_params p;
        sp_params_defaults(&p);
        p.pipeline = SP_PIPE_POINTS;
        p.point_size = 2;
        uint32_t id = tu_upload(tu_ctx, &pc);
        rnd_frame f = {0};
        tu_render(tu_ctx, id, &cam, &p, 0, &f);
        double fw, fh;
        fill(&f, &fw, &fh);
        printf("%-40s up (%4.1f %4.1f %4.1f) down %5.1f deg  fill %3.0f %% x %3.0f %%\n", s->name,
               v.up[0], v.up[1], v.up[2], down, 100 * fw, 100 * fh);
        if (!(fmax(fw, fh) >= 0.8))
            fail_msg("%s fills %.0f %% x %.0f %% of the frame: want >= 80 %% in one direction",
                     s->name, 100 * fw, 100 * fh);
        rnd_frame_free(&f);
        rnd_release(tu_ctx, id);
        pc_prepared_free(&pc);
    }
}

/* The sensor rule on the PCD files: rops_cloud's identity VIEWPOINT looks along -z with +y up
 * (its points lie at z -1.4 to -1.0, in front); table_scene_mug's VIEWPOINT 0 0 0 0 1 0 0 looks
 * along +z with -y up (its points lie at z 0.7 to 2.6, in front, y down as the camera saw
 * them). */
static void test_pcd_viewpoint(void **state)
{
    (void)state;
    pc_prepared pc;
    sp_view v;
    tu_prep_data("rops_cloud.pcd", &pc);
    view_of_prepared(&pc, &v);
    assert_true(v.dir[0] == 0 && v.dir[1] == 0 && v.dir[2] == -1);
    assert_true(v.up[0] == 0 && v.up[1] == 1 && v.up[2] == 0);
    pc_prepared_free(&pc);
    tu_prep_data("table_scene_mug_stereo_textured.pcd", &pc);
    assert_int_equal(pc.has_sensor_q, 1);
    view_of_prepared(&pc, &v);
    assert_true(fabs(v.dir[2] - 1) < 1e-12 && fabs(v.up[1] + 1) < 1e-12);
    pc_prepared_free(&pc);
    /* the sensor's rotation goes through both caches: built, then loaded */
    char dir[4096], src[4096];
    tu_tmpdir(dir, sizeof dir);
    tu_data("table_scene_mug_stereo_textured.pcd", src, sizeof src);
    for (int pass = 0; pass < 2; pass++) {
        cache_desc cd = {.dir = dir};
        cache_result res;
        sd_err err = {0};
        assert_int_equal(cache_open_cloud(src, &cd, &pc, &res, &err), 0);
        assert_int_equal(res.hit, pass);
        view_of_prepared(&pc, &v);
        assert_true(fabs(v.dir[2] - 1) < 1e-12 && fabs(v.up[1] + 1) < 1e-12);
        pc_prepared_free(&pc);
        lod_desc ld = {.dir = dir, .grid_bits = 4, .leaf_max = 20000};
        lod_cloud lc;
        lod_result lr;
        assert_int_equal(lod_open_cloud(src, &ld, &lc, &lr, &err), 0);
        assert_int_equal(lr.hit, pass);
        view_of_lod(&lc, &v);
        assert_true(fabs(v.dir[2] - 1) < 1e-12 && fabs(v.up[1] + 1) < 1e-12);
        lod_cloud_free(&lc);
    }
    tu_rm_rf(dir);
}

/* The framed box leaves far outliers out: a plane of 10,000 points 100 x 100 with five points
 * 1,000 units above it frames the plane (z 0 to 0), while the same plane with a 1-unit bump
 * (part of the cloud) keeps the bump. */
static void test_outliers_left_out(void **state)
{
    (void)state;
    enum { N = 10000 };
    static float pos[3 * (N + 5)];
    for (int i = 0; i < N; i++) {
        pos[3 * i] = (float)(i % 100), pos[3 * i + 1] = (float)(i / 100);
        pos[3 * i + 2] = (i % 100 > 90 && i / 100 > 90) ? 1.0f : 0.0f; /* 81 points: a bump */
    }
    for (int i = N; i < N + 5; i++) pos[3 * i] = 50, pos[3 * i + 1] = 50, pos[3 * i + 2] = 1000;
    const double off[3] = {0, 0, 0}, lo[3] = {0, 0, 0}, hi[3] = {99, 99, 1000};
    double vmin[3], vmax[3];
    view_box(pos, N + 5, off, lo, hi, vmin, vmax);
    assert_true(vmax[2] == 1.0 && vmin[2] == 0.0);
    assert_true(vmax[0] == 99 && vmax[1] == 99 && vmin[0] == 0 && vmin[1] == 0);
    /* fewer than 16 points: the bounds as they are */
    view_box(pos + 3 * (N - 10), 15, off, lo, hi, vmin, vmax);
    assert_true(vmax[2] == 1000);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_real_scans),
        cmocka_unit_test(test_pcd_viewpoint),
        cmocka_unit_test(test_outliers_left_out),
    };
    return cmocka_run_group_tests(tests, tu_egl_group_setup, tu_egl_group_teardown);
}
