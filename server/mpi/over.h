/* over.h — premultiplied "over" of the ranks' images for soft and olt under splatd --mpi, and
 * the background put under the result once, on rank 0.
 *
 * Every rank renders its part with a black background and coverage in alpha
 * (rnd_set_coverage): per pixel premultiplied colour C and coverage A (0 where nothing was
 * drawn, 1 under an opaque splat, the accumulated "over" of the soft discs elsewhere). Two
 * images composite, front over back, as C = Cf + (1 - Af) Cb, A = Af + (1 - Af) Ab; the
 * background comes last: C + (1 - A) bg. That is what the GL's blending does in one image
 * (ONE, ONE_MINUS_SRC_ALPHA over a target cleared to the background), so one rank's image
 * with the background put under it is the single-process frame when the background is black
 * (bit for bit: the RGB channels are blended exactly as without coverage), and within the
 * background's rounding (one 8-bit rounding instead of one per disc) otherwise.
 *
 * Pixel forms (compose.h's stride):
 *   OV_PX8  RGBA8 (8-bit frames): rounded to 8 bits at each composite, as the GL rounds at
 *           each blend;
 *   OV_PXF  eye depth (float, +inf empty) then RGBA16F (float frames): composited in float,
 *           stored as half; the depth is the nearer one (the nearest solid surface of all
 *           ranks, as the single frame's). */
#pragma once
#include <stddef.h>
#include <stdint.h>

enum { OV_PX8 = 4, OV_PXF = 12 };

/* ov_op: cmp_op for OV_PX8 or OV_PXF pixels (by stride); lo is in front. */
void ov_op(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix, size_t stride,
           void *user);

/* ov_background8: rgba8 (npix pixels, OV_PX8) = the composite with bg (linear RGB in [0, 1])
 * under it, alpha 1 (8-bit frames are opaque). */
void ov_background8(uint8_t *rgba8, size_t npix, const float bg[3]);

/* ov_backgroundf: from npix OV_PXF pixels px: rgba16f = colour with bg under it, alpha the
 * coverage (as the float target keeps it); rgba8 = that colour in 8 bits, alpha 1; depth. */
void ov_backgroundf(const uint8_t *px, size_t npix, const float bg[3], uint16_t *rgba16f,
                    uint8_t *rgba8, float *depth);

