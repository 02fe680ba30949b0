/* test_splat_math.c — the CPU reference of the EWA footprint (server/splat_math.c, the same
 * mathematics as shaders/splat_raster.comp.glsl) against closed forms: the screen covariance of
 * a facing disc, the cos(theta) aspect of a tilted one, the low-pass term, the conic as the
 * covariance's inverse, and the eye-ray coefficients as the inverse of the projection. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <string.h>

#include "splat_math.h"
#include "testutil.h"

enum { W = 640, H = 480 };

/* gluPerspective, column-major. */
static void perspective(float m[16], double fovy_deg, double aspect, double n, double f)
{
    memset(m, 0, 16 * sizeof *m);
    double t = 1.0 / tan(fovy_deg * M_PI / 360.0);
    m[0] = (float)(t / aspect), m[5] = (float)t;
    m[10] = (float)((f + n) / (n - f)), m[11] = -1;
    m[14] = (float)(2 * f * n / (n - f));
}

static void identity(float m[16])
{
    memset(m, 0, 16 * sizeof *m);
    m[0] = m[5] = m[10] = m[15] = 1;
}

/* A disc of radius r at distance d on the optical axis, tilted by theta about the x axis, with
 * low-pass L: the Jacobian at the axis is diag(sx, sy) / d on the eye x, y components (the z
 * component's derivative vanishes there), so the covariance is exactly
 * diag((r/2 sx/d)^2 + L, (r/2 sy/d cos theta)^2 + L) with sx = W/2 P00, sy = H/2 P11, and the
 * conic its inverse. Float arithmetic on values of order 1e2-1e3: 1e-5 relative. */
static void test_axis_disc(void **state)
{
    (void)state;
    float view[16], proj[16];
    identity(view);
    perspective(proj, 50, (double)W / H, 0.1, 100);
    const double d = 7.5, r = 0.2;
    const double thetas[4] = {0, 30, 60, 80};
    const float lps[2] = {0.0f, 1.0f};
    for (int ti = 0; ti < 4; ti++)
        for (int li = 0; li < 2; li++) {
            double th = thetas[ti] * M_PI / 180;
            const float pos[3] = {0, 0, (float)-d};
            const float nrm[3] = {0, (float)sin(th), (float)cos(th)};
            splat_footprint fp;
            assert_int_equal(splat_footprint_compute(view, proj, W, H, pos, nrm, (float)r, lps[li], 0.1f, &fp), 1);
            double sx = 0.5 * W * proj[0] / d, sy = 0.5 * H * proj[5] / d;
            double vxx = pow(0.5 * r * sx, 2) + lps[li];
            double vyy = pow(0.5 * r * sy * cos(th), 2) + lps[li];
            assert_true(fabs(fp.cov[0] - vxx) <= 1e-5 * vxx);
            assert_true(fabs(fp.cov[2] - vyy) <= 1e-5 * vyy);
            assert_true(fabs(fp.cov[1]) <= 1e-5 * vxx);
            /* Q V = I */
            double q00 = fp.conic[0] * fp.cov[0] + fp.conic[1] * fp.cov[1];
            double q01 = fp.conic[0] * fp.cov[1] + fp.conic[1] * fp.cov[2];
            double q11 = fp.conic[1] * fp.cov[1] + fp.conic[2] * fp.cov[2];
            assert_true(fabs(q00 - 1) < 1e-5 && fabs(q11 - 1) < 1e-5 && fabs(q01) < 1e-5);
            /* Cut-off box: SPLAT_CUT standard deviations; centre at the frame's middle. */
            assert_true(fabs(fp.ext[0] - SPLAT_CUT * sqrt(vxx)) <= 1e-5 * fp.ext[0]);
            assert_true(fabs(fp.ctr[0] - W / 2.0) < 1e-3 && fabs(fp.ctr[1] - H / 2.0) < 1e-3);
            assert_true(fabs(fp.depth - d) < 1e-5 * d);
            if (li == 0) {
                /* Without the low-pass the footprint's aspect is cos(theta) and its major
                 * semi-axis at the cut-off is the projected radius. */
                double aspect = sqrt(fp.cov[2] / fp.cov[0]) * (sy / sx);
                assert_true(fabs(aspect - cos(th)) < 1e-5);
                assert_true(fabs(fp.ext[0] - r * sx) <= 1e-5 * r * sx);
            }
        }
}

/* Anywhere in the frame, the covariance is the Jacobian of the real projection (measured by
 * central differences of the projected disc rim in double precision) applied to the disc's
 * Gaussian: J V_r J^T with V_r = (r/2)^2 I in an orthonormal tangent basis, i.e.
 * sigma^2 (J_u J_u^T + J_v J_v^T) for ANY orthonormal (u, v); compared at 1e-3 relative (the
 * difference step and float rounding). The normal is turned towards the eye. */
static void test_off_axis_against_differences(void **state)
{
    (void)state;
    float view[16], proj[16];
    identity(view);
    perspective(proj, 60, (double)W / H, 0.1, 100);
    const float pos[3] = {1.3f, -0.7f, -4.0f};
    const double nraw[3] = {0.3, 0.5, -0.8}; /* faces away: must be flipped */
    double nl = sqrt(nraw[0] * nraw[0] + nraw[1] * nraw[1] + nraw[2] * nraw[2]);
    const float nrm[3] = {(float)(nraw[0] / nl), (float)(nraw[1] / nl), (float)(nraw[2] / nl)};
    const float r = 0.3f;
    splat_footprint fp;
    assert_int_equal(splat_footprint_compute(view, proj, W, H, pos, nrm, r, 0, 0.1f, &fp), 1);
    double dotnc = fp.n_eye[0] * pos[0] + fp.n_eye[1] * pos[1] + fp.n_eye[2] * pos[2];
    assert_true(dotnc < 0);
    /* A tangent basis other than the implementation's. */
    double n[3] = {fp.n_eye[0], fp.n_eye[1], fp.n_eye[2]};
    double u[3] = {n[1], -n[0], 0};
    double ul = sqrt(u[0] * u[0] + u[1] * u[1]);
    u[0] /= ul, u[1] /= ul;
    double v[3] = {n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]};
    double sigma = 0.5 * r, eps = 1e-4;
    double cov[3] = {0, 0, 0};
    for (int k = 0; k < 2; k++) {
        const double *t = k ? v : u;
        double j[2];
        double sp[2][2];
        for (int sgn = 0; sgn < 2; sgn++) {
            double e = sgn ? eps : -eps, q[3];
            for (int i = 0; i < 3; i++) q[i] = pos[i] + e * t[i];
            double cx = proj[0] * q[0] + proj[8] * q[2], cy = proj[5] * q[1] + proj[9] * q[2];
            double cw = -q[2];
            sp[sgn][0] = (cx / cw * 0.5 + 0.5) * W, sp[sgn][1] = (cy / cw * 0.5 + 0.5) * H;
        }
        j[0] = (sp[1][0] - sp[0][0]) / (2 * eps), j[1] = (sp[1][1] - sp[0][1]) / (2 * eps);
        cov[0] += sigma * sigma * j[0] * j[0];
        cov[1] += sigma * sigma * j[0] * j[1];
        cov[2] += sigma * sigma * j[1] * j[1];
    }
    for (int i = 0; i < 3; i++) assert_true(fabs(fp.cov[i] - cov[i]) <= 1e-3 * fabs(cov[0]));
    /* Behind the near plane: no footprint. */
    const float behind[3] = {0, 0, 0.5f};
    assert_int_equal(splat_footprint_compute(view, proj, W, H, behind, nrm, r, 1, 0.1f, &fp), 0);
}

/* The eye rays: the point o + t d (t = 1) of the ray through pixel position (sx, sy) projects
 * back onto (sx, sy), for a perspective (origin 0) and an orthographic projection (direction
 * -z); 1e-3 px. */
static void test_ray_coeffs(void **state)
{
    (void)state;
    float persp[16], ortho[16];
    perspective(persp, 45, (double)W / H, 0.5, 50);
    memset(ortho, 0, sizeof ortho);
    ortho[0] = 2.0f / 8, ortho[5] = 2.0f / 6, ortho[10] = -2.0f / 99, ortho[12] = 0.1f;
    ortho[13] = -0.2f, ortho[14] = -101.0f / 99, ortho[15] = 1;
    const float *projs[2] = {persp, ortho};
    const double pts[3][2] = {{0.5, 0.5}, {123.25, 401.75}, {639.5, 0.5}};
    for (int k = 0; k < 2; k++) {
        const float *P = projs[k];
        float o[4], d[4];
        splat_ray_coeffs(P, W, H, o, d);
        for (int i = 0; i < 3; i++) {
            double sx = pts[i][0], sy = pts[i][1];
            double e[3] = {o[0] * sx + o[1] + d[0] * sx + d[1], o[2] * sy + o[3] + d[2] * sy + d[3], -1};
            if (k == 1) e[2] = -3; /* any depth along an orthographic ray */
            double cx = P[0] * e[0] + P[8] * e[2] + P[12], cy = P[5] * e[1] + P[9] * e[2] + P[13];
            double cw = P[3] * e[0] + P[7] * e[1] + P[11] * e[2] + P[15];
            double px = (cx / cw * 0.5 + 0.5) * W, py = (cy / cw * 0.5 + 0.5) * H;
            assert_true(fabs(px - sx) < 1e-3 && fabs(py - sy) < 1e-3);
        }
    }
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_axis_disc),
        cmocka_unit_test(test_off_axis_against_differences),
        cmocka_unit_test(test_ray_coeffs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
