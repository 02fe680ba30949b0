/* pca.c — symmetric 3x3 eigen solver and PCA normals; see pca.h. */
#include "pca.h"

#include <math.h>
#include <stddef.h>

void prep_sym3_eigenvalues(const prep_sym3 *a, double ev[3])
{
    /* Scale to unit magnitude so the cubic's coefficients neither overflow nor underflow. */
    double s = fmax(fmax(fmax(fabs(a->xx), fabs(a->xy)), fmax(fabs(a->xz), fabs(a->yy))),
                    fmax(fabs(a->yz), fabs(a->zz)));
    if (s == 0) {
        ev[0] = ev[1] = ev[2] = 0;
        return;
    }
    double xx = a->xx / s, xy = a->xy / s, xz = a->xz / s;
    double yy = a->yy / s, yz = a->yz / s, zz = a->zz / s;
    double p1 = xy * xy + xz * xz + yz * yz;
    double q = (xx + yy + zz) / 3;
    double dx = xx - q, dy = yy - q, dz = zz - q;
    double p2 = dx * dx + dy * dy + dz * dz + 2 * p1;
    double e0, e1, e2;
    if (p2 <= 1e-300) {
        e0 = e1 = e2 = q;
    } else {
        double p = sqrt(p2 / 6);
        /* det(B) / 2 with B = (A - qI) / p */
        double b00 = dx / p, b11 = dy / p, b22 = dz / p;
        double b01 = xy / p, b02 = xz / p, b12 = yz / p;
        double det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) +
                     b02 * (b01 * b12 - b11 * b02);
        double r = det / 2;
        if (r < -1) r = -1;
        if (r > 1) r = 1;
        double phi = acos(r) / 3;
        e2 = q + 2 * p * cos(phi);                      /* largest */
        e0 = q + 2 * p * cos(phi + 2.0943951023931957); /* smallest: phi + 2 pi / 3 */
        e1 = 3 * q - e2 - e0;
    }
    ev[0] = e0 * s;
    ev[1] = e1 * s;
    ev[2] = e2 * s;
    /* Rounding can swap nearly equal values; keep them ascending. */
    if (ev[1] < ev[0]) { double t = ev[0]; ev[0] = ev[1]; ev[1] = t; }
    if (ev[2] < ev[1]) { double t = ev[1]; ev[1] = ev[2]; ev[2] = t; }
    if (ev[1] < ev[0]) { double t = ev[0]; ev[0] = ev[1]; ev[1] = t; }
}

static void cross(const double a[3], const double b[3], double c[3])
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The largest cross product of two rows of (a - lambda I) into v (not normalised); returns its
 * squared length and, in *rowsq, the largest squared row length (the scale to compare against). */
static double null_vector(const prep_sym3 *a, double lambda, double v[3], double *rowsq)
{
    double r0[3] = {a->xx - lambda, a->xy, a->xz};
    double r1[3] = {a->xy, a->yy - lambda, a->yz};
    double r2[3] = {a->xz, a->yz, a->zz - lambda};
    double c[3][3];
    cross(r0, r1, c[0]);
    cross(r0, r2, c[1]);
    cross(r1, r2, c[2]);
    int best = 0;
    double bl = -1;
    for (int i = 0; i < 3; i++) {
        double l = dot3(c[i], c[i]);
        if (l > bl) { bl = l; best = i; }
    }
    v[0] = c[best][0]; v[1] = c[best][1]; v[2] = c[best][2];
    *rowsq = fmax(fmax(dot3(r0, r0), dot3(r1, r1)), dot3(r2, r2));
    return bl;
}

/* Any unit vector perpendicular to the unit vector u. */
static void perpendicular(const double u[3], double v[3])
{
    double ax = fabs(u[0]), ay = fabs(u[1]), az = fabs(u[2]);
    double e[3] = {0, 0, 0};
    if (ax <= ay && ax <= az) e[0] = 1;
    else if (ay <= az) e[1] = 1;
    else e[2] = 1;
    cross(u, e, v);
    double l = sqrt(dot3(v, v));
    v[0] /= l; v[1] /= l; v[2] /= l;
}

double prep_sym3_smallest(const prep_sym3 *a, double v[3])
{
    double ev[3];
    prep_sym3_eigenvalues(a, ev);
    double rowsq, l = null_vector(a, ev[0], v, &rowsq);
    /* The cross product is reliable when it is not tiny against the rows it came from, i.e.
     * when the two larger eigenvalues are separated from the smallest one. */
    if (rowsq > 0 && l > 1e-20 * rowsq * rowsq) {
        l = sqrt(l);
        v[0] /= l; v[1] /= l; v[2] /= l;
        return ev[0];
    }
    /* lambda_min is (nearly) double: its eigenspace is the plane perpendicular to the largest
     * eigenvalue's eigenvector; take any vector of it. */
    double u[3], rs2;
    double lu = null_vector(a, ev[2], u, &rs2);
    if (rs2 > 0 && lu > 1e-20 * rs2 * rs2 && ev[2] - ev[0] > 1e-12 * fabs(ev[2])) {
        lu = sqrt(lu);
        u[0] /= lu; u[1] /= lu; u[2] /= lu;
        perpendicular(u, v);
        return ev[0];
    }
    v[0] = 0; v[1] = 0; v[2] = 1; /* isotropic: every direction is an eigenvector */
    return ev[0];
}

void prep_pca_normal(const float *pos, uint32_t self, const uint32_t *nbr, int k, float n[3],
                     float *curv)
{
    const float *o = pos + 3 * (size_t)self;
    double sx = 0, sy = 0, sz = 0, sxx = 0, sxy = 0, sxz = 0, syy = 0, syz = 0, szz = 0;
    for (int j = 0; j < k; j++) {
        const float *p = pos + 3 * (size_t)nbr[j];
        double x = (double)p[0] - o[0], y = (double)p[1] - o[1], z = (double)p[2] - o[2];
        sx += x; sy += y; sz += z;
        sxx += x * x; sxy += x * y; sxz += x * z;
        syy += y * y; syz += y * z; szz += z * z;
    }
    double m = k + 1; /* the point itself sits at the origin: it adds only to the count */
    double mx = sx / m, my = sy / m, mz = sz / m;
    prep_sym3 c = {sxx / m - mx * mx, sxy / m - mx * my, sxz / m - mx * mz,
                   syy / m - my * my, syz / m - my * mz, szz / m - mz * mz};
    double v[3];
    double l0 = prep_sym3_smallest(&c, v);
    n[0] = (float)v[0]; n[1] = (float)v[1]; n[2] = (float)v[2];
    if (curv) {
        double tr = c.xx + c.yy + c.zz;
        *curv = tr > 0 ? (float)(fmax(l0, 0) / tr) : 0.0f;
    }
}
