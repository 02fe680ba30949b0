/* framing.c — default views and the cameras made from them (see framing.h). */
#include "framing.h"

#include <math.h>
#include <string.h>

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross3(const double a[3], const double b[3], double o[3])
{
    double t[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    memcpy(o, t, sizeof t);
}

static double norm3(double a[3])
{
    double l = sqrt(dot3(a, a));
    if (l > 0)
        for (int i = 0; i < 3; i++) a[i] /= l;
    return l;
}

int sp_georeferenced(const double bmin[3], const double bmax[3])
{
    double cx = fabs(0.5 * (bmin[0] + bmax[0])), cy = fabs(0.5 * (bmin[1] + bmax[1]));
    double ext = fmax(bmax[0] - bmin[0], bmax[1] - bmin[1]);
    double c = fmax(cx, cy);
    return c >= SP_GEOREF_MIN && c >= 10 * ext;
}

/* Rotates v about the unit axis k by ang radians (Rodrigues). */
static void rotate(double v[3], const double k[3], double ang)
{
    double kxv[3], c = cos(ang), s = sin(ang), kv = dot3(k, v);
    cross3(k, v, kxv);
    for (int i = 0; i < 3; i++) v[i] = v[i] * c + kxv[i] * s + k[i] * kv * (1 - c);
}

/* R^T v for the rotation of the unit quaternion q = (w, x, y, z): the rotation by the
 * conjugate quaternion. */
static void quat_rotate_inv(const double q_in[4], const double v[3], double o[3])
{
    double q[4] = {q_in[0], -q_in[1], -q_in[2], -q_in[3]};
    double l = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(l > 0)) {
        memcpy(o, v, 3 * sizeof(double));
        return;
    }
    for (int i = 0; i < 4; i++) q[i] /= l;
    /* o = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z) */
    double u[3] = {q[1], q[2], q[3]}, t[3], t2[3];
    cross3(u, v, t);
    for (int i = 0; i < 3; i++) t[i] *= 2;
    cross3(u, t, t2);
    for (int i = 0; i < 3; i++) o[i] = v[i] + q[0] * t[i] + t2[i];
}

void sp_view_default(const double bmin[3], const double bmax[3], int rule, const double q[4],
                     sp_view *v)
{
    memset(v, 0, sizeof *v);
    memcpy(v->bmin, bmin, sizeof v->bmin);
    memcpy(v->bmax, bmax, sizeof v->bmax);
    double ext[3];
    for (int i = 0; i < 3; i++) ext[i] = fmax(bmax[i] - bmin[i], 0);
    if (rule == SP_UP_SENSOR && !sp_georeferenced(bmin, bmax)) {
        static const double id[4] = {1, 0, 0, 0};
        const double fwd[3] = {0, 0, -1}, up[3] = {0, 1, 0};
        quat_rotate_inv(q ? q : id, fwd, v->dir);
        quat_rotate_inv(q ? q : id, up, v->up);
        norm3(v->dir);
        norm3(v->up);
        return;
    }
    int ua = 2; /* the up axis */
    if (rule == SP_UP_GUESS && !sp_georeferenced(bmin, bmax)) {
        int least = 0;
        for (int i = 1; i < 3; i++)
            if (ext[i] < ext[least]) least = i;
        int flat = 1;
        for (int i = 0; i < 3; i++)
            if (i != least && !(ext[least] < SP_FLAT_RATIO * ext[i])) flat = 0;
        ua = flat ? least : 1;
    }
    v->up[ua] = 1;
    /* the right axis: the larger of the two horizontal extents (the first in x, y, z order
     * on a tie) runs across the frame; the camera looks along up x right */
    int h0 = ua == 0 ? 1 : 0, h1 = ua == 2 ? 1 : 2;
    int ra = ext[h1] > ext[h0] ? h1 : h0;
    double right[3] = {0, 0, 0}, dir[3];
    right[ra] = 1;
    cross3(v->up, right, dir);
    rotate(dir, v->up, SP_YAW_DEG * M_PI / 180);
    double el = SP_ELEVATION_DEG * M_PI / 180;
    for (int i = 0; i < 3; i++) v->dir[i] = cos(el) * dir[i] - sin(el) * v->up[i];
    norm3(v->dir);
}

/* The camera frame of a view: d (looking along), u (up, perpendicular to d), r = d x u. When
 * up is parallel to dir, any perpendicular axis serves. */
static void basis(const double dir[3], const double up_in[3], double d[3], double u[3], double r[3])
{
    memcpy(d, dir, 3 * sizeof(double));
    if (!(norm3(d) > 0)) d[0] = 0, d[1] = 0, d[2] = -1;
    memcpy(u, up_in, 3 * sizeof(double));
    double k = dot3(u, d);
    for (int i = 0; i < 3; i++) u[i] -= k * d[i];
    if (!(norm3(u) > 1e-9)) {
        int ax = 0; /* the axis most perpendicular to d */
        for (int i = 1; i < 3; i++)
            if (fabs(d[i]) < fabs(d[ax])) ax = i;
        u[0] = u[1] = u[2] = 0;
        u[ax] = 1;
        k = dot3(u, d);
        for (int i = 0; i < 3; i++) u[i] -= k * d[i];
        norm3(u);
    }
    cross3(d, u, r);
}

/* The up vector a camera is given: world up itself (constant over orbits and drags, as the
 * renderer makes it perpendicular to the view), unless the view looks along it, when the
 * camera frame's own up u serves. */
static void world_up(const double wup[3], const double u[3], double up[3])
{
    double w[3] = {wup[0], wup[1], wup[2]};
    if (norm3(w) > 0 && dot3(w, u) > 1e-6) memcpy(up, w, sizeof w);
    else memcpy(up, u, 3 * sizeof(double));
}

/* The half-widths of the frame on the image plane at unit distance, less the margin. */
static void half_tan(int width, int height, double fov_deg, double *tx, double *ty)
{
    if (!(fov_deg > 0 && fov_deg < 180)) fov_deg = SP_DEFAULT_FOV;
    double aspect = width > 0 && height > 0 ? (double)width / height : 1.0;
    double t = tan(0.5 * fov_deg * M_PI / 180);
    *ty = t * (1 - SP_FILL_MARGIN);
    *tx = t * aspect * (1 - SP_FILL_MARGIN);
}

/* The points a camera fits (v's hull, else the box's corners) relative to the box's centre c,
 * in the camera frame (d, u, r): pr, pu, pd. Returns their number. */
static int corners(const sp_view *v, const double d[3], const double u[3], const double r[3],
                   double c[3], double pr[SP_VIEW_PTS], double pu[SP_VIEW_PTS],
                   double pd[SP_VIEW_PTS])
{
    for (int i = 0; i < 3; i++) c[i] = 0.5 * (v->bmin[i] + v->bmax[i]);
    int n = v->npts > 0 && v->npts <= SP_VIEW_PTS ? (int)v->npts : 8;
    for (int k = 0; k < n; k++) {
        double p[3];
        for (int i = 0; i < 3; i++)
            p[i] = (v->npts ? v->pts[k][i] : (k >> i) & 1 ? v->bmax[i] : v->bmin[i]) - c[i];
        pr[k] = dot3(p, r), pu[k] = dot3(p, u), pd[k] = dot3(p, d);
    }
    return n;
}

void sp_view_hull(sp_view *v, const double *p, uint64_t n)
{
    int dirs[SP_VIEW_PTS][3], nd = 0;
    for (int x = -1; x <= 1; x++)
        for (int y = -1; y <= 1; y++)
            for (int z = -1; z <= 1; z++)
                if (x || y || z) dirs[nd][0] = x, dirs[nd][1] = y, dirs[nd][2] = z, nd++;
    /* the box's extents scale the directions, so that a diagonal is the box's diagonal */
    double e[3], c[3], best[SP_VIEW_PTS];
    for (int i = 0; i < 3; i++) {
        e[i] = v->bmax[i] - v->bmin[i];
        if (!(e[i] > 0)) e[i] = 1;
        c[i] = 0.5 * (v->bmin[i] + v->bmax[i]);
    }
    for (int k = 0; k < nd; k++) best[k] = -INFINITY;
    v->npts = 0;
    for (uint64_t j = 0; j < n; j++) {
        const double *q = p + 3 * j;
        int in = 1;
        for (int i = 0; i < 3; i++) in &= q[i] >= v->bmin[i] && q[i] <= v->bmax[i];
        if (!in) continue;
        for (int k = 0; k < nd; k++) {
            double s = 0;
            for (int i = 0; i < 3; i++) s += dirs[k][i] * (q[i] - c[i]) / e[i];
            if (s > best[k]) {
                best[k] = s;
                memcpy(v->pts[k], q, 3 * sizeof(double));
            }
        }
        v->npts = SP_VIEW_PTS;
    }
}

/* A distance that keeps every corner in front of the eye: at least a thousandth of the box's
 * diagonal beyond the nearest corner, and one unit for a box of a single point. */
static double in_front(const sp_view *v, const double *pd, int np, double dist)
{
    double diag = 0;
    for (int i = 0; i < 3; i++) diag += (v->bmax[i] - v->bmin[i]) * (v->bmax[i] - v->bmin[i]);
    diag = sqrt(diag);
    if (!(diag > 0)) return fmax(dist, 1.0);
    for (int k = 0; k < np; k++) dist = fmax(dist, -pd[k] + 1e-3 * diag);
    return dist;
}

void sp_frame_fit(const sp_view *v, int width, int height, double fov_deg, double eye[3],
                  double target[3], double up[3])
{
    double d[3], u[3], r[3], c[3], pr[SP_VIEW_PTS], pu[SP_VIEW_PTS], pd[SP_VIEW_PTS], tx, ty;
    basis(v->dir, v->up, d, u, r);
    half_tan(width, height, fov_deg, &tx, &ty);
    int np = corners(v, d, u, r, c, pr, pu, pd);
    /* Corner k is inside when |p_r - s_r| <= tx (p_d + D) (and likewise along u): feasible for
     * some shift s_r when D >= (max(p_r - tx p_d) - min(p_r + tx p_d)) / (2 tx); the shift
     * then centres the projection. */
    double lo_r = INFINITY, hi_r = -INFINITY, lo_u = INFINITY, hi_u = -INFINITY;
    for (int k = 0; k < np; k++) {
        hi_r = fmax(hi_r, pr[k] - tx * pd[k]);
        lo_r = fmin(lo_r, pr[k] + tx * pd[k]);
        hi_u = fmax(hi_u, pu[k] - ty * pd[k]);
        lo_u = fmin(lo_u, pu[k] + ty * pd[k]);
    }
    double dist = fmax((hi_r - lo_r) / (2 * tx), (hi_u - lo_u) / (2 * ty));
    dist = in_front(v, pd, np, dist);
    double sr = 0.5 * (hi_r + lo_r), su = 0.5 * (hi_u + lo_u);
    for (int i = 0; i < 3; i++) {
        target[i] = c[i] + sr * r[i] + su * u[i];
        eye[i] = target[i] - dist * d[i];
    }
    world_up(v->up, u, up);
}

/* The direction of orbit camera i of n: the default view's azimuth turned by 2 pi i / n about
 * up, SP_ELEVATION_DEG below the horizon. */
static void orbit_dir(const sp_view *v, const double up[3], int i, int n, double dir[3])
{
    double h[3];
    memcpy(h, v->dir, sizeof h);
    double k = dot3(h, up);
    for (int a = 0; a < 3; a++) h[a] -= k * up[a];
    if (!(norm3(h) > 1e-9)) { /* the view looks straight along up: start from any side */
        double d[3], u[3], r[3];
        basis(up, v->dir, d, u, r);
        memcpy(h, u, sizeof h);
    }
    if (n > 0) rotate(h, up, 2 * M_PI * i / n);
    double el = SP_ELEVATION_DEG * M_PI / 180;
    for (int a = 0; a < 3; a++) dir[a] = cos(el) * h[a] - sin(el) * up[a];
    norm3(dir);
}

void sp_frame_orbit(const sp_view *v, const double *up_in, int i, int n, int width, int height,
                    double fov_deg, double eye[3], double target[3], double up[3])
{
    double axis[3];
    memcpy(axis, up_in ? up_in : v->up, sizeof axis);
    if (!(norm3(axis) > 0)) axis[0] = 0, axis[1] = 0, axis[2] = 1;
    double tx, ty, dist = 0, c[3];
    half_tan(width, height, fov_deg, &tx, &ty);
    int m = n > 0 ? n : 1;
    /* the distance at which the box, centred on the target, fits from every camera */
    for (int j = 0; j < m; j++) {
        double dir[3], d[3], u[3], r[3], pr[SP_VIEW_PTS], pu[SP_VIEW_PTS], pd[SP_VIEW_PTS];
        orbit_dir(v, axis, j, n, dir);
        basis(dir, axis, d, u, r);
        int np = corners(v, d, u, r, c, pr, pu, pd);
        for (int k = 0; k < np; k++)
            dist = fmax(dist, fmax(fabs(pr[k]) / tx, fabs(pu[k]) / ty) - pd[k]);
        dist = in_front(v, pd, np, dist);
    }
    double dir[3], d[3], r[3], u[3];
    orbit_dir(v, axis, i, n, dir);
    basis(dir, axis, d, u, r);
    world_up(axis, u, up);
    for (int a = 0; a < 3; a++) {
        target[a] = c[a];
        eye[a] = c[a] - dist * d[a];
    }
}
