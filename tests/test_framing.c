/* test_framing.c — protocol/framing.c: the up rules of each file family, the first view's
 * angles, the fit that fills the frame (every corner of the box inside, the limiting one on the
 * margin, the projection centred), and orbits (up constant, elevation and distance constant,
 * every frame holding the whole box). Pure arithmetic against hand values; no GL. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "framing.h"
#include "testutil.h"

static double dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void assert_vec(const double v[3], double x, double y, double z, double tol)
{
    if (fabs(v[0] - x) > tol || fabs(v[1] - y) > tol || fabs(v[2] - z) > tol)
        fail_msg("(%.9f, %.9f, %.9f) != (%.9f, %.9f, %.9f)", v[0], v[1], v[2], x, y, z);
}

/* The degrees the view looks below the horizon of up. */
static double looks_down_deg(const sp_view *v) { return asin(-dot(v->dir, v->up)) * 180 / M_PI; }

/* LAS/LAZ/COPC/E57 are z up whatever their shape: a tall box (a tower) too; the view looks
 * SP_ELEVATION_DEG down, turned SP_YAW_DEG from the axis across the longer extent. */
static void test_z_up_rule(void **state)
{
    (void)state;
    sp_view v;
    const double lo[3] = {0, 0, 0}, wide_x[3] = {100, 40, 10};
    sp_view_default(lo, wide_x, SP_UP_Z, NULL, &v);
    assert_vec(v.up, 0, 0, 1, 0);
    assert_true(fabs(looks_down_deg(&v) - SP_ELEVATION_DEG) < 1e-9);
    /* x is the longer: the camera looks along +y (x across the frame, to the right), turned
     * 20 degrees counter-clockwise seen from above: horizontal part (-sin 20, cos 20) */
    double c = cos(SP_ELEVATION_DEG * M_PI / 180), y = SP_YAW_DEG * M_PI / 180;
    assert_vec(v.dir, -sin(y) * c, cos(y) * c, -sin(SP_ELEVATION_DEG * M_PI / 180), 1e-12);
    const double wide_y[3] = {40, 100, 10}, tower[3] = {1, 1, 50};
    sp_view_default(lo, wide_y, SP_UP_Z, NULL, &v);
    /* y is the longer: looking along up x y = -x, turned: (-cos 20, -sin 20) */
    assert_vec(v.dir, -cos(y) * c, -sin(y) * c, -sin(SP_ELEVATION_DEG * M_PI / 180), 1e-12);
    sp_view_default(lo, tower, SP_UP_Z, NULL, &v);
    assert_vec(v.up, 0, 0, 1, 0);
    assert_memory_equal(v.bmax, tower, sizeof tower);
}

/* PLY/XYZ: the flat axis when one extent is under 0.2 of both others (exactly 0.2 is not
 * flat), else +y; georeferenced coordinates are z up whatever the shape. */
static void test_guess_rule(void **state)
{
    (void)state;
    sp_view v;
    const double lo[3] = {0, 0, 0};
    const double bunny[3] = {0.156, 0.152, 0.117}, terrain[3] = {100, 80, 15.9},
                 facade[3] = {1.9, 30, 12}, edge[3] = {100, 80, 16};
    sp_view_default(lo, bunny, SP_UP_GUESS, NULL, &v);
    assert_vec(v.up, 0, 1, 0, 0);
    /* y up, x the longer horizontal extent: looking along up x x = -z (from the front) */
    double c = cos(SP_ELEVATION_DEG * M_PI / 180), y = SP_YAW_DEG * M_PI / 180;
    assert_vec(v.dir, -sin(y) * c, -sin(SP_ELEVATION_DEG * M_PI / 180), -cos(y) * c, 1e-12);
    sp_view_default(lo, terrain, SP_UP_GUESS, NULL, &v);
    assert_vec(v.up, 0, 0, 1, 0);
    sp_view_default(lo, facade, SP_UP_GUESS, NULL, &v);
    assert_vec(v.up, 1, 0, 0, 0);
    sp_view_default(lo, edge, SP_UP_GUESS, NULL, &v); /* 16 = 0.2 x 80: not flat */
    assert_vec(v.up, 0, 1, 0, 0);
    /* UTM: centre (665180, 5648361), 16 m x 41 m: georeferenced, z up */
    const double glo[3] = {665171.4, 5648340.5, 233.5}, ghi[3] = {665187.9, 5648381.9, 245.9};
    assert_int_equal(sp_georeferenced(glo, ghi), 1);
    sp_view_default(glo, ghi, SP_UP_GUESS, NULL, &v);
    assert_vec(v.up, 0, 0, 1, 0);
    /* the threshold: a centre at 1e4 is georeferenced when the extent is at most 1e3 */
    const double a[3] = {9500, 0, 0}, b[3] = {10500, 10, 1}, b2[3] = {10501, 10, 1};
    assert_int_equal(sp_georeferenced(a, b), 1);
    assert_int_equal(sp_georeferenced(a, b2), 0);
}

/* PCD: the view PCL's viewer gives, direction R^T (0,0,-1) and up R^T (0,1,0): the identity
 * looks along -z; table_scene_mug's VIEWPOINT 0 0 0 0 1 0 0 (180 degrees about x) looks along
 * +z with -y up; a 90-degree turn about y (w = cos 45, y = sin 45) looks along +x. A
 * georeferenced PCD is z up. */
static void test_sensor_rule(void **state)
{
    (void)state;
    sp_view v;
    const double lo[3] = {-1, -1, 0.5}, hi[3] = {1, 1, 2.5};
    sp_view_default(lo, hi, SP_UP_SENSOR, NULL, &v);
    assert_vec(v.dir, 0, 0, -1, 1e-15);
    assert_vec(v.up, 0, 1, 0, 1e-15);
    const double mug[4] = {0, 1, 0, 0};
    sp_view_default(lo, hi, SP_UP_SENSOR, mug, &v);
    assert_vec(v.dir, 0, 0, 1, 1e-15);
    assert_vec(v.up, 0, -1, 0, 1e-15);
    /* R = 90 degrees about +y, (x, z) -> (x cos a + z sin a, -x sin a + z cos a); R^T turns
     * by -90 degrees: (0, 0, -1) -> (1, 0, 0) */
    const double yaw[4] = {cos(M_PI / 4), 0, sin(M_PI / 4), 0};
    sp_view_default(lo, hi, SP_UP_SENSOR, yaw, &v);
    assert_vec(v.dir, 1, 0, 0, 1e-12);
    assert_vec(v.up, 0, 1, 0, 1e-12);
    /* any length of quaternion: scaled by 3, the same */
    const double yaw3[4] = {3 * cos(M_PI / 4), 0, 3 * sin(M_PI / 4), 0};
    sp_view_default(lo, hi, SP_UP_SENSOR, yaw3, &v);
    assert_vec(v.dir, 1, 0, 0, 1e-12);
    const double glo[3] = {500000, 5400000, 100}, ghi[3] = {500300, 5400400, 180};
    sp_view_default(glo, ghi, SP_UP_SENSOR, mug, &v);
    assert_vec(v.up, 0, 0, 1, 0);
}

/* The camera frame of eye, target, up: projects p to normalised image coordinates, x in
 * [-1, 1] across the width, y across the height. */
static void project(const double eye[3], const double target[3], const double up[3], double fov,
                    int w, int h, const double p[3], double *x, double *y, double *z)
{
    double d[3], r[3], u[3], q[3];
    for (int i = 0; i < 3; i++) d[i] = target[i] - eye[i], q[i] = p[i] - eye[i];
    double l = sqrt(dot(d, d));
    for (int i = 0; i < 3; i++) d[i] /= l;
    r[0] = d[1] * up[2] - d[2] * up[1], r[1] = d[2] * up[0] - d[0] * up[2],
    r[2] = d[0] * up[1] - d[1] * up[0];
    l = sqrt(dot(r, r));
    for (int i = 0; i < 3; i++) r[i] /= l;
    u[0] = r[1] * d[2] - r[2] * d[1], u[1] = r[2] * d[0] - r[0] * d[2], u[2] = r[0] * d[1] - r[1] * d[0];
    double t = tan(fov * M_PI / 360);
    *z = dot(q, d);
    *x = dot(q, r) / (*z * t * w / h);
    *y = dot(q, u) / (*z * t);
}

/* Every corner of the box in front and inside the frame; returns the largest |x| and |y| and
 * their sums (max + min: 0 when the projection is centred) through the pointers. */
static void corners_in(const double eye[3], const double target[3], const double up[3],
                       const double lo[3], const double hi[3], int w, int h, double *mx,
                       double *my, double *cx, double *cy)
{
    double xlo = 1e9, xhi = -1e9, ylo = 1e9, yhi = -1e9;
    for (int k = 0; k < 8; k++) {
        double p[3] = {k & 1 ? hi[0] : lo[0], k & 2 ? hi[1] : lo[1], k & 4 ? hi[2] : lo[2]};
        double x, y, z;
        project(eye, target, up, SP_DEFAULT_FOV, w, h, p, &x, &y, &z);
        assert_true(z > 0);
        xlo = fmin(xlo, x), xhi = fmax(xhi, x), ylo = fmin(ylo, y), yhi = fmax(yhi, y);
    }
    *mx = fmax(fabs(xlo), fabs(xhi)), *my = fmax(fabs(ylo), fabs(yhi));
    *cx = xlo + xhi, *cy = ylo + yhi;
}

/* sp_frame_fit: the box fills the frame up to the margin in its limiting direction, centred;
 * the camera looks along the view's direction, with world up as its up. */
static void test_fit_fills(void **state)
{
    (void)state;
    const double boxes[][2][3] = {
        {{0, 0, 0}, {100, 40, 10}}, {{-0.09, 0.03, -0.06}, {0.06, 0.19, 0.06}},
        {{665171, 5648340, 233}, {665188, 5648382, 246}}, {{0, 0, 0}, {1, 1, 50}},
        {{0, 0, 0}, {1000, 1000, 0}}, /* a flat plane: zero extent in z */
    };
    const int sizes[][2] = {{1280, 720}, {480, 640}, {100, 100}};
    for (size_t b = 0; b < sizeof boxes / sizeof boxes[0]; b++)
        for (int rule = SP_UP_GUESS; rule <= SP_UP_SENSOR; rule++)
            for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
                sp_view v;
                sp_view_default(boxes[b][0], boxes[b][1], rule, NULL, &v);
                double eye[3], target[3], up[3];
                int w = sizes[s][0], h = sizes[s][1];
                sp_frame_fit(&v, w, h, SP_DEFAULT_FOV, eye, target, up);
                double mx, my, cx, cy;
                corners_in(eye, target, up, boxes[b][0], boxes[b][1], w, h, &mx, &my, &cx, &cy);
                double lim = 1 - SP_FILL_MARGIN;
                if (!(mx <= lim + 1e-9 && my <= lim + 1e-9 && fmax(mx, my) > lim - 1e-9))
                    fail_msg("box %zu rule %d %dx%d: |x| %.6f |y| %.6f, want max = %.3f", b, rule,
                             w, h, mx, my, lim);
                /* centred in the limiting direction (and in the other within its slack) */
                if (mx > my) assert_true(fabs(cx) < 1e-9);
                else assert_true(fabs(cy) < 1e-9);
                /* looks along dir, up perpendicular to it and on up's side */
                double d[3], l;
                for (int i = 0; i < 3; i++) d[i] = target[i] - eye[i];
                l = sqrt(dot(d, d));
                for (int i = 0; i < 3; i++) d[i] /= l;
                assert_vec(d, v.dir[0], v.dir[1], v.dir[2], 1e-9);
                assert_vec(up, v.up[0], v.up[1], v.up[2], 1e-15);
            }
    /* a single point: seen from one unit away, not from inside it */
    const double pt[3] = {5, 5, 5};
    sp_view v;
    sp_view_default(pt, pt, SP_UP_Z, NULL, &v);
    double eye[3], target[3], up[3];
    sp_frame_fit(&v, 640, 480, SP_DEFAULT_FOV, eye, target, up);
    double dd = 0;
    for (int i = 0; i < 3; i++) dd += (eye[i] - 5) * (eye[i] - 5);
    assert_true(fabs(sqrt(dd) - 1) < 1e-12);
}

/* Orbits: up constant, 30 degrees above the horizon, the same distance from the box's centre
 * on every frame, the box inside every frame and touching the margin on at least one; frame 0
 * has the default view's azimuth and i = n/4 is a quarter turn counter-clockwise from above. */
static void test_orbit(void **state)
{
    (void)state;
    const double lo[3] = {0, 0, 0}, hi[3] = {100, 40, 10};
    sp_view v;
    sp_view_default(lo, hi, SP_UP_Z, NULL, &v);
    const int n = 12, w = 960, h = 720;
    double dist0 = -1, worst = 0;
    double h0[2] = {0, 0};
    for (int i = 0; i < n; i++) {
        double eye[3], target[3], up[3];
        sp_frame_orbit(&v, NULL, i, n, w, h, SP_DEFAULT_FOV, eye, target, up);
        assert_vec(target, 50, 20, 5, 1e-12);
        assert_vec(up, 0, 0, 1, 1e-12);
        double d[3];
        for (int k = 0; k < 3; k++) d[k] = target[k] - eye[k];
        double l = sqrt(dot(d, d));
        if (dist0 < 0) dist0 = l;
        assert_true(fabs(l - dist0) < 1e-9 * l);
        assert_true(fabs(asin(-d[2] / l) * 180 / M_PI - SP_ELEVATION_DEG) < 1e-9);
        double az = atan2(d[1], d[0]);
        if (i == 0) {
            h0[0] = cos(az), h0[1] = sin(az);
            assert_true(fabs(az - atan2(v.dir[1], v.dir[0])) < 1e-12);
        }
        double want = atan2(h0[1], h0[0]) + 2 * M_PI * i / n;
        assert_true(fabs(remainder(az - want, 2 * M_PI)) < 1e-12);
        double mx, my, cx, cy;
        corners_in(eye, target, up, lo, hi, w, h, &mx, &my, &cx, &cy);
        assert_true(mx <= 1 - SP_FILL_MARGIN + 1e-9 && my <= 1 - SP_FILL_MARGIN + 1e-9);
        worst = fmax(worst, fmax(mx, my));
    }
    assert_true(fabs(worst - (1 - SP_FILL_MARGIN)) < 1e-9);
    /* another axis given: turns about it */
    const double upx[3] = {2, 0, 0};
    double eye[3], target[3], up[3];
    sp_frame_orbit(&v, upx, 3, 8, w, h, SP_DEFAULT_FOV, eye, target, up);
    assert_vec(up, 1, 0, 0, 1e-12);
    double d[3];
    for (int k = 0; k < 3; k++) d[k] = target[k] - eye[k];
    assert_true(fabs(asin(-d[0] / sqrt(dot(d, d))) * 180 / M_PI - SP_ELEVATION_DEG) < 1e-9);
}

/* The hull: the extreme points of a sphere's sample along the 26 directions; the camera fitted
 * to them comes closer than one fitted to the box's corners, and still holds every point of the
 * sample inside the frame (the margin covers the hull's approximation); points outside the box
 * are no candidates. */
static void test_hull_fit(void **state)
{
    (void)state;
    enum { N = 4000 };
    static double p[3 * (N + 1)];
    for (int i = 0; i < N; i++) { /* a Fibonacci sphere of radius 1 about (10, 20, 30) */
        double z = 1 - (2 * i + 1.0) / N, r = sqrt(1 - z * z), a = i * M_PI * (3 - sqrt(5));
        p[3 * i] = 10 + r * cos(a), p[3 * i + 1] = 20 + r * sin(a), p[3 * i + 2] = 30 + z;
    }
    p[3 * N] = 10, p[3 * N + 1] = 20, p[3 * N + 2] = 40; /* outside the box: ignored */
    const double lo[3] = {9, 19, 29}, hi[3] = {11, 21, 31};
    sp_view box, v;
    sp_view_default(lo, hi, SP_UP_Z, NULL, &box);
    v = box;
    sp_view_hull(&v, p, N + 1);
    assert_int_equal(v.npts, SP_VIEW_PTS);
    int top = -1; /* the +z direction's extreme: the sphere's north pole, not the outlier */
    for (int k = 0; k < SP_VIEW_PTS; k++)
        if (v.pts[k][2] > 30.99) top = k;
    assert_true(top >= 0 && v.pts[top][2] < 31);
    double e0[3], t0[3], u0[3], e1[3], t1[3], u1[3];
    sp_frame_fit(&box, 640, 480, SP_DEFAULT_FOV, e0, t0, u0);
    sp_frame_fit(&v, 640, 480, SP_DEFAULT_FOV, e1, t1, u1);
    double d0 = 0, d1 = 0;
    for (int i = 0; i < 3; i++) d0 += (e0[i] - t0[i]) * (e0[i] - t0[i]), d1 += (e1[i] - t1[i]) * (e1[i] - t1[i]);
    assert_true(sqrt(d1) < 0.8 * sqrt(d0));
    double mx = 0, my = 0;
    for (int i = 0; i < N; i++) {
        double x, y, z;
        project(e1, t1, u1, SP_DEFAULT_FOV, 640, 480, p + 3 * i, &x, &y, &z);
        mx = fmax(mx, fabs(x)), my = fmax(my, fabs(y));
    }
    if (!(mx <= 1 && my <= 1 && fmax(mx, my) > 0.9)) fail_msg("|x| %.4f |y| %.4f", mx, my);
    /* no point inside the box: no hull */
    sp_view_hull(&v, p + 3 * N, 1);
    assert_int_equal(v.npts, 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_z_up_rule),
        cmocka_unit_test(test_guess_rule),
        cmocka_unit_test(test_sensor_rule),
        cmocka_unit_test(test_fit_fills),
        cmocka_unit_test(test_orbit),
        cmocka_unit_test(test_hull_fit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
