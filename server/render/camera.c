/* camera.c — default camera, view and projection matrices, near/far, frustum culling. */
#include "camera.h"
#include "framing.h"

#include <math.h>
#include <string.h>

static void dsub(const double a[3], const double b[3], double o[3])
{
    for (int i = 0; i < 3; i++) o[i] = a[i] - b[i];
}

static double ddot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void dcross(const double a[3], const double b[3], double o[3])
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

static double dnorm(double a[3])
{
    double l = sqrt(ddot(a, a));
    if (l > 0)
        for (int i = 0; i < 3; i++) a[i] /= l;
    return l;
}

void rnd_camera_frame(const sp_view *v, int width, int height, double fov_deg, rnd_camera *cam)
{
    memset(cam, 0, sizeof *cam);
    cam->width = width;
    cam->height = height;
    cam->fov_deg = (float)(fov_deg > 0 && fov_deg < 180 ? fov_deg : SP_DEFAULT_FOV);
    sp_frame_fit(v, width, height, cam->fov_deg, cam->eye, cam->target, cam->up);
}

/* Column-major 4x4 product o = a * b. */
static void mat_mul(const float a[16], const float b[16], float o[16])
{
    for (int c = 0; c < 4; c++)
        for (int r = 0; r < 4; r++) {
            float s = 0;
            for (int k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
            o[c * 4 + r] = s;
        }
}

int rnd__view_setup(const rnd_camera *cam, const double offset[3], const float bmin[3],
                    const float bmax[3], rnd_view *v, sd_err *err)
{
    memset(v, 0, sizeof *v);
    if (cam->width <= 0 || cam->height <= 0)
        return sd_errf(err, SD_EINVAL, "camera size %dx%d is not positive", cam->width,
                       cam->height);
    if (!(cam->fov_deg > 0 && cam->fov_deg < 180))
        return sd_errf(err, SD_EINVAL, "camera fov %g degrees is outside (0, 180)",
                       (double)cam->fov_deg);
    double eye[3], tgt[3], f[3], s[3], u[3];
    for (int i = 0; i < 3; i++) {
        if (!isfinite(cam->eye[i]) || !isfinite(cam->target[i]) || !isfinite(cam->up[i]))
            return sd_errf(err, SD_EINVAL, "camera eye, target or up is not finite");
        eye[i] = cam->eye[i] - offset[i];
        tgt[i] = cam->target[i] - offset[i];
    }
    dsub(tgt, eye, f);
    if (dnorm(f) <= 0) return sd_errf(err, SD_EINVAL, "camera eye and target are the same point");
    dcross(f, cam->up, s);
    if (dnorm(s) <= 1e-12 * sqrt(ddot(cam->up, cam->up)) || ddot(cam->up, cam->up) == 0)
        return sd_errf(err, SD_EINVAL, "camera up is zero or parallel to the view direction");
    dcross(s, f, u);

    /* near/far from the box's corners when not given. */
    double dmin = INFINITY, dmax = 0, diag2 = 0;
    for (int i = 0; i < 3; i++) diag2 += (double)(bmax[i] - bmin[i]) * (bmax[i] - bmin[i]);
    double diag = sqrt(diag2);
    for (int k = 0; k < 8; k++) {
        double p[3] = {k & 1 ? bmax[0] : bmin[0], k & 2 ? bmax[1] : bmin[1],
                       k & 4 ? bmax[2] : bmin[2]};
        double d[3];
        dsub(p, eye, d);
        dmin = fmin(dmin, ddot(d, f));
        dmax = fmax(dmax, sqrt(ddot(d, d)));
    }
    double floor_near = diag > 0 ? diag * 1e-4 : 1e-4 * fmax(dmax, 1e-3);
    double zn = cam->znear > 0 ? cam->znear : fmax(dmin * 0.99, floor_near);
    double zf = cam->zfar > 0 ? cam->zfar : fmax(dmax * 1.01, zn * 2);
    if (!(zf > zn))
        return sd_errf(err, SD_EINVAL, "camera far %g is not beyond near %g", zf, zn);

    float *V = v->view;
    for (int i = 0; i < 3; i++) {
        V[i * 4 + 0] = (float)s[i];
        V[i * 4 + 1] = (float)u[i];
        V[i * 4 + 2] = (float)-f[i];
        V[i * 4 + 3] = 0;
    }
    V[12] = (float)-ddot(s, eye);
    V[13] = (float)-ddot(u, eye);
    V[14] = (float)ddot(f, eye);
    V[15] = 1;

    double fov = cam->fov_deg * M_PI / 180.0;
    double t = 1.0 / tan(fov / 2), aspect = (double)cam->width / cam->height;
    float *P = v->proj;
    memset(P, 0, 16 * sizeof *P);
    P[0] = (float)(t / aspect);
    P[5] = (float)t;
    P[10] = (float)(-(zf + zn) / (zf - zn));
    P[11] = -1;
    P[14] = (float)(-2 * zf * zn / (zf - zn));
    mat_mul(P, V, v->viewproj);
    for (int i = 0; i < 3; i++) v->eye[i] = (float)eye[i];
    v->znear = (float)zn;
    v->zfar = (float)zf;
    v->fov_y = (float)fov;
    v->width = cam->width;
    v->height = cam->height;
    return 0;
}

int rnd__aabb_in_frustum(const float m[16], const float bmin[3], const float bmax[3])
{
    /* Gribb-Hartmann planes: row3 +- row0, row1, row2 of the (column-major) matrix. */
    for (int p = 0; p < 6; p++) {
        int row = p / 2;
        float sg = (p & 1) ? -1.0f : 1.0f;
        float pl[4];
        for (int c = 0; c < 4; c++) pl[c] = m[c * 4 + 3] + sg * m[c * 4 + row];
        /* The box corner farthest along the plane normal (the "p-vertex"). */
        float d = pl[3];
        for (int i = 0; i < 3; i++) d += pl[i] * (pl[i] >= 0 ? bmax[i] : bmin[i]);
        if (d < 0) return 0;
    }
    return 1;
}

uint32_t rnd__cull(const rnd_view *v, const rnd_chunk *c, uint64_t nc, uint64_t budget,
                   rnd_chunk *out, uint64_t *points)
{
    uint32_t n = 0;
    uint64_t total = 0;
    for (uint64_t i = 0; i < nc; i++) {
        if (budget && total >= budget) break;
        if (!c[i].count || !rnd__aabb_in_frustum(v->viewproj, c[i].bmin, c[i].bmax)) continue;
        uint32_t k = c[i].count;
        if (budget && total + k > budget) k = (uint32_t)(budget - total);
        rnd_chunk *last = n ? &out[n - 1] : NULL;
        if (last && last->set == c[i].set && last->first + last->count == c[i].first) {
            last->count += k;
            for (int a = 0; a < 3; a++) {
                last->bmin[a] = last->bmin[a] < c[i].bmin[a] ? last->bmin[a] : c[i].bmin[a];
                last->bmax[a] = last->bmax[a] > c[i].bmax[a] ? last->bmax[a] : c[i].bmax[a];
            }
        } else {
            out[n] = c[i];
            out[n].count = k;
            n++;
        }
        total += k;
    }
    *points = total;
    return n;
}

void rnd__screen_rect(const rnd_view *v, const float bmin[3], const float bmax[3], int margin,
                      int rect[4])
{
    const float *m = v->viewproj;
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    rect[0] = 0, rect[1] = 0, rect[2] = v->width, rect[3] = v->height;
    for (int k = 0; k < 8; k++) {
        double p[3] = {k & 1 ? bmax[0] : bmin[0], k & 2 ? bmax[1] : bmin[1],
                       k & 4 ? bmax[2] : bmin[2]};
        double c[4];
        for (int r = 0; r < 4; r++)
            c[r] = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r];
        if (c[3] < 0.5 * v->znear) return; /* near or behind the eye: keep the whole frame */
        double sx = (c[0] / c[3] * 0.5 + 0.5) * v->width;
        double sy = (c[1] / c[3] * 0.5 + 0.5) * v->height;
        lo[0] = fmin(lo[0], sx), hi[0] = fmax(hi[0], sx);
        lo[1] = fmin(lo[1], sy), hi[1] = fmax(hi[1], sy);
    }
    int dim[2] = {v->width, v->height};
    for (int a = 0; a < 2; a++) {
        double l = floor(lo[a]) - margin, h = ceil(hi[a]) + margin;
        rect[a] = (int)fmax(0, fmin(l, dim[a]));
        rect[2 + a] = (int)fmax(rect[a], fmin(h, dim[a]));
    }
}
