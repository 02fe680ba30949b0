/* framing.c — default and orbit cameras (see framing.h). */
#include "framing.h"

#include <math.h>
#include <string.h>

static int flat_in_z(const double ext[3]) { return ext[2] < 0.1 * fmax(ext[0], ext[1]); }

void sp_default_up(const double bmin[3], const double bmax[3], double up[3])
{
    double ext[3];
    for (int i = 0; i < 3; i++) ext[i] = bmax[i] - bmin[i];
    int y_up = flat_in_z(ext) || (ext[1] > ext[0] && ext[1] > ext[2]);
    up[0] = 0;
    up[1] = y_up ? 1 : 0;
    up[2] = y_up ? 0 : 1;
}

/* Distance at which a sphere of radius r fits the frame of the given fov and aspect. */
static double fit_distance(double r, int width, int height, double fov_deg)
{
    double fy = fov_deg * M_PI / 180.0;
    double aspect = height > 0 ? (double)width / height : 1.0;
    double fx = 2 * atan(tan(fy / 2) * aspect);
    return r / sin(0.5 * fmin(fx, fy)) * 1.02; /* a small margin */
}

static double box_radius(const double bmin[3], const double bmax[3], double ctr[3], double ext[3])
{
    for (int i = 0; i < 3; i++) {
        ctr[i] = 0.5 * (bmin[i] + bmax[i]);
        ext[i] = bmax[i] - bmin[i];
    }
    double r = 0.5 * sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
    return r > 0 ? r : 1.0; /* a single point: look at it from about one unit away */
}

void sp_frame_box(const double bmin[3], const double bmax[3], int width, int height,
                  double fov_deg, double eye[3], double target[3], double up[3])
{
    double ctr[3], ext[3];
    double r = box_radius(bmin, bmax, ctr, ext);
    double dir[3];
    sp_default_up(bmin, bmax, up);
    if (flat_in_z(ext)) { /* from above, a little from -y */
        dir[0] = 0, dir[1] = -0.35, dir[2] = 1;
    } else if (up[1] == 1) { /* y up: from the +z-ish diagonal */
        dir[0] = 0.55, dir[1] = 0.45, dir[2] = 1;
    } else { /* z up: from the +y-ish diagonal */
        dir[0] = 0.55, dir[1] = 1, dir[2] = 0.45;
    }
    double l = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    double dist = fit_distance(r, width, height, fov_deg);
    for (int i = 0; i < 3; i++) {
        target[i] = ctr[i];
        eye[i] = ctr[i] + dir[i] / l * dist;
    }
}

void sp_frame_orbit(const double bmin[3], const double bmax[3], const double *up_in, int i, int n,
                    int width, int height, double fov_deg, double eye[3], double target[3],
                    double up[3])
{
    if (up_in) memcpy(up, up_in, 3 * sizeof(double));
    else sp_default_up(bmin, bmax, up);
    double ul = sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
    if (!(ul > 0)) {
        up[0] = 0, up[1] = 0, up[2] = 1, ul = 1;
    }
    for (int k = 0; k < 3; k++) up[k] /= ul;
    /* a = the axis most perpendicular to up, made exactly perpendicular; b = up x a */
    int ax = 0;
    for (int k = 1; k < 3; k++)
        if (fabs(up[k]) < fabs(up[ax])) ax = k;
    double a[3] = {0, 0, 0}, b[3];
    a[ax] = 1;
    double d = a[0] * up[0] + a[1] * up[1] + a[2] * up[2];
    for (int k = 0; k < 3; k++) a[k] -= d * up[k];
    double al = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    for (int k = 0; k < 3; k++) a[k] /= al;
    b[0] = up[1] * a[2] - up[2] * a[1];
    b[1] = up[2] * a[0] - up[0] * a[2];
    b[2] = up[0] * a[1] - up[1] * a[0];
    double ctr[3], ext[3];
    double dist = fit_distance(box_radius(bmin, bmax, ctr, ext), width, height, fov_deg);
    double th = n > 0 ? 2 * M_PI * i / n : 0, el = 25.0 * M_PI / 180.0;
    for (int k = 0; k < 3; k++) {
        double dir = cos(el) * (cos(th) * a[k] + sin(th) * b[k]) + sin(el) * up[k];
        target[k] = ctr[k];
        eye[k] = ctr[k] + dist * dir;
    }
}
