/* exrtest.c — EXR frames read back for tests (exrtest.h). */
#include "exrtest.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <openexr.h>

float tu_half(uint16_t h)
{
    int e = (h >> 10) & 31, m = h & 1023;
    float v = e == 0 ? ldexpf((float)m, -24)
            : e == 31 ? (m ? NAN : INFINITY)
                      : ldexpf((float)(m | 1024), e - 25);
    return (h & 0x8000) ? -v : v;
}

int tu_exr_read(const char *path, int *w, int *h, uint16_t **rgba16f, float **z)
{
    *rgba16f = NULL;
    *z = NULL;
    exr_context_t c = NULL;
    if (exr_start_read(&c, path, NULL) != EXR_ERR_SUCCESS) return -1;
    exr_attr_box2i_t dw;
    int32_t lines = 0;
    int ok = exr_get_data_window(c, 0, &dw) == EXR_ERR_SUCCESS &&
             exr_get_scanlines_per_chunk(c, 0, &lines) == EXR_ERR_SUCCESS && lines > 0;
    int ww = ok ? dw.max.x - dw.min.x + 1 : 0, hh = ok ? dw.max.y - dw.min.y + 1 : 0;
    ok = ok && ww > 0 && hh > 0 && ww <= 16384 && hh <= 16384;
    uint16_t *col = ok ? calloc((size_t)ww * hh * 4, 2) : NULL;
    float *zz = ok ? calloc((size_t)ww * hh, 4) : NULL;
    ok = ok && col && zz;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int started = 0;
    for (int y = 0; ok && y < hh; y += lines) {
        exr_chunk_info_t ci;
        ok = exr_read_scanline_chunk_info(c, 0, dw.min.y + y, &ci) == EXR_ERR_SUCCESS &&
             (started ? exr_decoding_update(c, 0, &ci, &dec)
                      : exr_decoding_initialize(c, 0, &ci, &dec)) == EXR_ERR_SUCCESS;
        for (int k = 0; ok && k < dec.channel_count; k++) {
            exr_coding_channel_info_t *ch = &dec.channels[k];
            size_t row = (size_t)(ci.start_y - dw.min.y) * (size_t)ww;
            const char *at = strchr("RGBA", ch->channel_name[0]);
            if (ch->channel_name[0] == 'Z') {
                ch->decode_to_ptr = (uint8_t *)(zz + row);
                ch->user_pixel_stride = 4;
                ch->user_line_stride = ww * 4;
                ch->user_data_type = EXR_PIXEL_FLOAT;
                ch->user_bytes_per_element = 4;
            } else if (at && ch->channel_name[0] && !ch->channel_name[1]) {
                ch->decode_to_ptr = (uint8_t *)(col + row * 4 + (at - "RGBA"));
                ch->user_pixel_stride = 8;
                ch->user_line_stride = ww * 8;
                ch->user_data_type = EXR_PIXEL_HALF;
                ch->user_bytes_per_element = 2;
            } else {
                ok = 0; /* a channel the daemon does not write */
            }
        }
        if (ok && !started) {
            ok = exr_decoding_choose_default_routines(c, 0, &dec) == EXR_ERR_SUCCESS;
            started = 1;
        }
        if (ok) ok = exr_decoding_run(c, 0, &dec) == EXR_ERR_SUCCESS;
    }
    if (started) exr_decoding_destroy(c, &dec);
    exr_finish(&c);
    if (!ok) {
        free(col);
        free(zz);
        return -1;
    }
    *w = ww, *h = hh, *rgba16f = col, *z = zz;
    return 0;
}
