/* exrtest.h — reading the daemon's EXR frames back in tests (OpenEXR's C reader). */
#pragma once
#include <stdint.h>

/* tu_exr_read: the frame at path (channels A B G R half, Z float, as server/enc writes them)
 * as *rgba16f (w*h*4 halves, RGBA order) and *z (w*h floats), rows top-down as stored.
 * Returns 0, or -1 when the file is not such an EXR (nothing allocated then). */
int tu_exr_read(const char *path, int *w, int *h, uint16_t **rgba16f, float **z);

/* tu_half: an IEEE binary16 value as a float. */
float tu_half(uint16_t h);
