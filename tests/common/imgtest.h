/* imgtest.h — images for the rendering and end-to-end tests: PNG files in and out (libpng's
 * simplified API) and the PSNR over covered pixels that golden comparisons use. */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* tu_png_read: an 8-bit PNG as RGBA8 (malloc'd in *rgba), rows bottom-up when bottom_up (GL's
 * order, like rnd_frame) else top-down. Returns 0, or -1 when the file is not a readable PNG. */
int tu_png_read(const char *path, int bottom_up, uint32_t *w, uint32_t *h, uint8_t **rgba);

/* tu_png_write: writes w x h RGBA8 pixels (rows bottom-up when bottom_up) as a PNG. 0 or -1. */
int tu_png_write(const char *path, uint32_t w, uint32_t h, const uint8_t *rgba, int bottom_up);

/* tu_psnr_covered: PSNR (dB, over R, G, B) of RGBA8 image a against g, both npx pixels, over
 * the pixels covered in either: the background, (0, 0, 0) in both, is left out, since it
 * matches trivially and would inflate the figure by 10 log10(npx / covered). INFINITY when
 * they are equal; *ncov gets the number of pixels compared. */
double tu_psnr_covered(const uint8_t *a, const uint8_t *g, size_t npx, size_t *ncov);

/* tu_psnr_all: PSNR (dB, over R, G, B) of RGBA8 image a against g over all npx pixels, for
 * screen captures compared with a render of the same view; *lit gets the pixels of a with a
 * channel above 8 (a blank capture has none). INFINITY when they are equal. */
double tu_psnr_all(const uint8_t *a, const uint8_t *g, size_t npx, size_t *lit);
