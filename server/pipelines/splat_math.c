/* splat_math.c — EWA footprint reference and eye-ray coefficients (see splat_math.h). The
 * footprint code follows setup_core() in shaders/splat_raster.comp.glsl; it adds the whole
 * low-pass to the covariance (the exact EWA resampling filter, the pipeline's ewa=exact), where
 * the pipeline's ewa=split adds a quarter per splat and applies the rest in its resolve (see
 * pipe_splat.c). */
#include "splat_math.h"

#include <math.h>

#define M(m, row, col) ((m)[(col) * 4 + (row)])

void splat_ray_coeffs(const float proj[16], int width, int height, float o[4], float d[4])
{
    float w = (float)width, h = (float)height;
    if (M(proj, 3, 3) == 0.0f) {
        /* Perspective: the point of the ray at z = -1 has clip w = 1 (row 3 = (0, 0, -1, 0)),
         * so ndc.x = P00 x - P02 + P03 with ndc.x = 2 sx / w - 1. */
        o[0] = o[1] = o[2] = o[3] = 0.0f;
        d[0] = 2.0f / (w * M(proj, 0, 0));
        d[1] = (M(proj, 0, 2) - M(proj, 0, 3) - 1.0f) / M(proj, 0, 0);
        d[2] = 2.0f / (h * M(proj, 1, 1));
        d[3] = (M(proj, 1, 2) - M(proj, 1, 3) - 1.0f) / M(proj, 1, 1);
    } else {
        /* Orthographic: ndc.x = P00 x + P03; every ray looks along -z. */
        o[0] = 2.0f / (w * M(proj, 0, 0));
        o[1] = (-1.0f - M(proj, 0, 3)) / M(proj, 0, 0);
        o[2] = 2.0f / (h * M(proj, 1, 1));
        o[3] = (-1.0f - M(proj, 1, 3)) / M(proj, 1, 1);
        d[0] = d[1] = d[2] = d[3] = 0.0f;
    }
}

static float dot3(const float a[3], const float b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

int splat_footprint_compute(const float view[16], const float proj[16], int width, int height,
                            const float pos[3], const float nrm[3], float r, float lowpass,
                            float znear, splat_footprint *fp)
{
    float c[3], n[3], clip[4];
    for (int i = 0; i < 3; i++) {
        c[i] = M(view, i, 0) * pos[0] + M(view, i, 1) * pos[1] + M(view, i, 2) * pos[2] +
               M(view, i, 3);
        n[i] = M(view, i, 0) * nrm[0] + M(view, i, 1) * nrm[1] + M(view, i, 2) * nrm[2];
    }
    fp->depth = -c[2];
    if (!(fp->depth > znear)) return 0;
    float nl = dot3(n, n);
    if (nl > 0.0f) {
        float s = 1.0f / sqrtf(nl);
        n[0] *= s, n[1] *= s, n[2] *= s;
    } else {
        n[0] = n[1] = 0.0f, n[2] = 1.0f;
    }
    const float axis[3] = {0.0f, 0.0f, -1.0f};
    const float *toc = M(proj, 3, 3) == 0.0f ? c : axis;
    if (dot3(n, toc) > 0.0f) n[0] = -n[0], n[1] = -n[1], n[2] = -n[2];
    for (int i = 0; i < 3; i++) fp->n_eye[i] = n[i];
    /* Orthonormal tangent basis (Duff et al. 2017). */
    float sg = n[2] >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (sg + n[2]);
    float b = n[0] * n[1] * a;
    float tu[3] = {1.0f + sg * n[0] * n[0] * a, sg * b, -sg * n[0]};
    float tv[3] = {b, sg + n[1] * n[1] * a, -n[1]};
    for (int i = 0; i < 4; i++)
        clip[i] = M(proj, i, 0) * c[0] + M(proj, i, 1) * c[1] + M(proj, i, 2) * c[2] + M(proj, i, 3);
    float iw = 1.0f / clip[3];
    float hw = 0.5f * (float)width, hh = 0.5f * (float)height;
    float gx[3], gy[3];
    for (int k = 0; k < 3; k++) {
        gx[k] = (M(proj, 0, k) - clip[0] * iw * M(proj, 3, k)) * iw * hw;
        gy[k] = (M(proj, 1, k) - clip[1] * iw * M(proj, 3, k)) * iw * hh;
    }
    float sigma = 0.5f * r;
    float ju[2] = {dot3(gx, tu) * sigma, dot3(gy, tu) * sigma};
    float jv[2] = {dot3(gx, tv) * sigma, dot3(gy, tv) * sigma};
    float vxx = ju[0] * ju[0] + jv[0] * jv[0] + lowpass;
    float vxy = ju[0] * ju[1] + jv[0] * jv[1];
    float vyy = ju[1] * ju[1] + jv[1] * jv[1] + lowpass;
    float det = vxx * vyy - vxy * vxy;
    if (!(det > 1e-12f)) return 0;
    fp->cov[0] = vxx, fp->cov[1] = vxy, fp->cov[2] = vyy;
    fp->conic[0] = vyy / det, fp->conic[1] = -vxy / det, fp->conic[2] = vxx / det;
    fp->ext[0] = SPLAT_CUT * sqrtf(vxx);
    fp->ext[1] = SPLAT_CUT * sqrtf(vyy);
    fp->ctr[0] = (clip[0] * iw * 0.5f + 0.5f) * (float)width;
    fp->ctr[1] = (clip[1] * iw * 0.5f + 0.5f) * (float)height;
    return 1;
}
