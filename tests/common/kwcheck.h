/* kwcheck.h — kawata's host path (the host paths' passes 1-3, pipelines/kawata_cpu.h) against its
 * compute shaders (kawata_raster.comp, kawata_fit.comp STAGE 1), within the precision the GLSL
 * specification allows the shaders, not bit for bit: what a conforming GPU must meet.
 *
 * The precision (GLSL 4.50, 4.7.1, the table ARB_shader_precision brought in): + and * are
 * correctly rounded (relative error u = 2^-24 each), a / b within 2.5 units in the last place
 * (<= 5 u |a / b|), conversions exact; without `precise` a * b + c may also be fused, and a
 * matrix product's sums come in the compiler's order. From that, for a point p and its clip
 * coordinates c = M (p, 1) (kawata_raster.comp):
 *   each component of c, an inner product of 4 terms in any order, fused or not, is within
 *   g4 = 4u / (1 - 4u) times the sum of its terms' magnitudes, E_c = g4 sum_j |M_ij p_j|
 *   (Higham, Accuracy and Stability of Numerical Algorithms, 3.1: the bound holds for every
 *   order of summation);
 *   the depth key d = c.w within E_d = E_c(w); the buffer coordinate b = (c.x / d * 0.5 + 0.5)
 *   * size within E_b = size (0.5 |q| (E_x / |c.x| + E_d / |d| + 5u) + u (0.5 |q| + 0.5)) + u
 *   |b|, q = c.x / d (first-order in u: the bound is doubled below, which covers the neglected
 *   u^2 terms many times over).
 * The host computes one admissible evaluation, so host and GPU may differ by twice each bound.
 * A point whose interval b +- 2 E_b straddles a pixel edge, or whose depth is within 2 E_d of
 * the near or far plane, is "ambiguous": a conforming GPU may put it in another pixel, or drop
 * it. Within one buffer pixel, the nearest point is open when another point lies within the
 * two points' 2 E_d of it; the farthest within gamma is open when a point's step lies within
 * the steps' error of gamma or of a quantisation level's edge (pipe_kawata.c's qscale).
 *
 * kw_compare then asserts, buffer pixel by buffer pixel: depth, near and far equal wherever no
 * ambiguity is open (depth: equal, or within 2 E_d of the nearest point's own depth); pts
 * (STAGE 1: the two points in eye space and their colours) where near and far agree, each eye
 * coordinate within 2 E_c of the view matrix's product and each colour within 3 units in the
 * last place (unpackUnorm4x8 is c / 255.0: a division, 2.5 ulp, against the host's correctly
 * rounded one); and since the fit and the gather after them are one GL program on both sides
 * (the same inputs give the same outputs: GL's invariance rules), every splat and every frame
 * pixel equal unless an input that differs lies within their reach: a splat reads the 3x3 buffer
 * pixels around it, a frame pixel the 5x5 splats around its buffer pixel, so 1 and 3 buffer
 * pixels (4 for the frame: its buffer pixel is the floor of a scaled coordinate). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "render.h"

typedef struct kw_cmp {
    size_t covered;            /* buffer pixels with a nearest point (host) */
    size_t open;               /* buffer pixels with an ambiguity open (see the top) */
    size_t differ;             /* buffer pixels whose arrays or pts differ (all open) */
    size_t pixels;             /* frame pixels that differ (all within reach) */
} kw_cmp;

/* kw_compare: gl and host are frames of one view of one cloud of cloud_n points
 * (rnd_set_kawata_probe on, so that kawata_arrays is there; 8-bit or float), drawn by a renderer
 * without and with the host paths (rnd_desc.host_paths); pos holds n local positions, every
 * point the frames may have drawn (more do no harm: they only open more pixels), in cloud-wide
 * index order when indexed is 1 (else, for a LOD pool's points, the eye positions are bounded
 * by the largest coordinate); offset and bmin/bmax are the cloud's file-coordinate offset and
 * bounds, so that the view is rnd__view_setup's for cam. Fails the running test on a
 * difference the precision above does not allow, and fills *out. */
void kw_compare(const rnd_frame *gl, const rnd_frame *host, const float *pos, uint64_t n,
                int indexed, uint64_t cloud_n, const double offset[3], const double bmin[3],
                const double bmax[3], const rnd_camera *cam, const char *what, kw_cmp *out);
