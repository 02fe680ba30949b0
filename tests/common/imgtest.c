/* imgtest.c — see imgtest.h. */
#include "imgtest.h"

#include <math.h>
#include <png.h>
#include <stdlib.h>
#include <string.h>

int tu_png_read(const char *path, int bottom_up, uint32_t *w, uint32_t *h, uint8_t **rgba)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&im, path)) return -1;
    im.format = PNG_FORMAT_RGBA;
    uint8_t *px = malloc(PNG_IMAGE_SIZE(im));
    /* A negative stride makes the first row in memory the bottom one. */
    png_int_32 stride = bottom_up ? -(png_int_32)PNG_IMAGE_ROW_STRIDE(im) : 0;
    if (!px || !png_image_finish_read(&im, NULL, px, stride, NULL)) {
        free(px);
        png_image_free(&im);
        return -1;
    }
    *w = im.width;
    *h = im.height;
    *rgba = px;
    return 0;
}

int tu_png_write(const char *path, uint32_t w, uint32_t h, const uint8_t *rgba, int bottom_up)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    im.width = w, im.height = h;
    im.format = PNG_FORMAT_RGBA;
    png_int_32 stride = (png_int_32)(w * 4);
    return png_image_write_to_file(&im, path, 0, rgba, bottom_up ? -stride : stride, NULL) ? 0
                                                                                          : -1;
}

double tu_psnr_covered(const uint8_t *a, const uint8_t *g, size_t npx, size_t *ncov)
{
    double se = 0;
    size_t n = 0;
    for (size_t i = 0; i < npx; i++) {
        const uint8_t *p = a + 4 * i, *q = g + 4 * i;
        if (!(p[0] | p[1] | p[2]) && !(q[0] | q[1] | q[2])) continue;
        n++;
        for (int c = 0; c < 3; c++) {
            double d = (double)p[c] - q[c];
            se += d * d;
        }
    }
    *ncov = n;
    if (n == 0) return INFINITY;
    double mse = se / (3.0 * n);
    return mse > 0 ? 10 * log10(255.0 * 255.0 / mse) : INFINITY;
}

double tu_psnr_all(const uint8_t *a, const uint8_t *g, size_t npx, size_t *lit)
{
    double se = 0;
    size_t l = 0;
    for (size_t i = 0; i < npx; i++) {
        const uint8_t *p = a + 4 * i, *q = g + 4 * i;
        l += p[0] > 8 || p[1] > 8 || p[2] > 8;
        for (int c = 0; c < 3; c++) se += (double)(p[c] - q[c]) * (p[c] - q[c]);
    }
    *lit = l;
    double mse = se / (3.0 * (double)(npx ? npx : 1));
    return mse > 0 ? 10 * log10(255.0 * 255.0 / mse) : INFINITY;
}
