/* splat_math.h — the CPU side of EWA surface splatting (pipe_splat.c): the per-frame eye-ray
 * coefficients the shaders use for ray-disc depths, and a reference of the screen-space
 * footprint that shaders/splat_raster.comp.glsl computes per splat, so the mathematics can be
 * unit-tested without a GPU.
 *
 * Conventions: matrices are column-major float[16] (OpenGL), element (row i, column j) at
 * [j * 4 + i]; pixel coordinates run from (0, 0) at the bottom-left corner of the frame to
 * (width, height), pixel centres at k + 0.5. */
#pragma once

/* The EWA cut-off: the footprint is x^T Q x <= SPLAT_CUT^2; the disc's radius is SPLAT_CUT
 * standard deviations of its Gaussian, so with lowpass 0 the footprint is exactly the disc. */
#define SPLAT_CUT 2.0f

typedef struct splat_footprint {
    float ctr[2];     /* projected centre, pixels */
    float cov[3];     /* screen covariance V = J V_r J^T + lowpass I: xx, xy, yy (pixels^2) */
    float conic[3];   /* Q = V^-1: xx, xy, yy */
    float ext[2];     /* half extents of the cut-off ellipse's bounding box, pixels */
    float depth;      /* eye-space depth of the centre (distance along -z) */
    float n_eye[3];   /* unit normal in eye space, turned towards the viewer */
} splat_footprint;

/* splat_ray_coeffs: for projection proj (perspective, or orthographic when proj[15] != 0) and a
 * width x height frame, the eye-space ray through pixel position (sx, sy) is
 *   origin    (o[0] * sx + o[1], o[2] * sy + o[3], 0)
 *   direction (d[0] * sx + d[1], d[2] * sy + d[3], -1).
 * Assumes no x-y shear in proj (proj[4] == proj[1] == 0, true for every frustum and ortho
 * matrix). Writes o and d. */
void splat_ray_coeffs(const float proj[16], int width, int height, float o[4], float d[4]);

/* splat_footprint_compute: the footprint of the disc at pos (local coordinates) with normal nrm
 * and radius r (already multiplied by splat_scale) seen through view and proj in a
 * width x height frame, with low-pass variance `lowpass` pixels^2. Returns 1 with *fp filled, or
 * 0 when the centre is not in front of znear or the covariance is degenerate. */
int splat_footprint_compute(const float view[16], const float proj[16], int width, int height,
                            const float pos[3], const float nrm[3], float r, float lowpass,
                            float znear, splat_footprint *fp);
