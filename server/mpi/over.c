/* over.c — premultiplied "over" of the ranks' images and the background (over.h). */
#include "over.h"

#include "sd_half.h"

#include <math.h>
#include <string.h>

static uint8_t over8(uint8_t f, uint8_t fa, uint8_t b)
{
    unsigned v = f + ((255u - fa) * b + 127u) / 255u;
    return (uint8_t)(v > 255u ? 255u : v);
}

void ov_op(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix, size_t stride,
           void *user)
{
    (void)user;
    if (stride == OV_PX8) {
        for (size_t i = 0; i < npix; i++) {
            const uint8_t *f = lo + 4 * i, *b = hi + 4 * i;
            uint8_t *o = dst + 4 * i, fa = f[3];
            /* the usual cases, with over8's result: an opaque front, an empty one */
            if (fa == 255) {
                if (o != f) memcpy(o, f, 4);
                continue;
            }
            if ((f[0] | f[1] | f[2] | fa) == 0) {
                if (o != b) memcpy(o, b, 4);
                continue;
            }
            uint8_t r = over8(f[0], fa, b[0]), g = over8(f[1], fa, b[1]);
            uint8_t bl = over8(f[2], fa, b[2]), al = over8(fa, fa, b[3]);
            o[0] = r, o[1] = g, o[2] = bl, o[3] = al;
        }
        return;
    }
    for (size_t i = 0; i < npix; i++) {
        const uint8_t *f = lo + OV_PXF * i, *b = hi + OV_PXF * i;
        uint8_t *o = dst + OV_PXF * i;
        float zf, zb;
        uint16_t hf[4], hb[4], ho[4];
        memcpy(&zf, f, 4);
        memcpy(&zb, b, 4);
        memcpy(hf, f + 4, 8);
        memcpy(hb, b + 4, 8);
        float fa = sd_half_to_float(hf[3]);
        for (int c = 0; c < 4; c++)
            ho[c] = sd_float_to_half(sd_half_to_float(hf[c]) +
                                     (1.0f - fa) * sd_half_to_float(hb[c]));
        float z = zb < zf ? zb : zf;
        memcpy(o, &z, 4);
        memcpy(o + 4, ho, 8);
    }
}

void ov_background8(uint8_t *rgba8, size_t npix, const float bg[3])
{
    uint8_t b[3];
    for (int c = 0; c < 3; c++) b[c] = (uint8_t)lrintf(fminf(fmaxf(bg[c], 0), 1) * 255);
    for (size_t i = 0; i < npix; i++) {
        uint8_t *p = rgba8 + 4 * i;
        for (int c = 0; c < 3; c++) p[c] = over8(p[c], p[3], b[c]);
        p[3] = 255;
    }
}

void ov_backgroundf(const uint8_t *px, size_t npix, const float bg[3], uint16_t *rgba16f,
                    uint8_t *rgba8, float *depth)
{
    for (size_t i = 0; i < npix; i++) {
        const uint8_t *p = px + OV_PXF * i;
        uint16_t h[4];
        memcpy(&depth[i], p, 4);
        memcpy(h, p + 4, 8);
        float a = sd_half_to_float(h[3]);
        for (int c = 0; c < 3; c++) {
            float v = sd_half_to_float(h[c]) + (1.0f - a) * bg[c];
            rgba16f[4 * i + (size_t)c] = sd_float_to_half(v);
            float q = sd_half_to_float(rgba16f[4 * i + (size_t)c]);
            rgba8[4 * i + (size_t)c] = (uint8_t)lrintf(fminf(fmaxf(q, 0), 1) * 255);
        }
        rgba16f[4 * i + 3] = h[3];
        rgba8[4 * i + 3] = 255;
    }
}
