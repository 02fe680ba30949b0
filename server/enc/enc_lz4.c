/* enc_lz4.c — the lossless frame formats: SPL4 (LZ4 block of top-down RGBA8 behind a 16-byte
 * header; the layout is defined once, in protocol/frame_lz4.h) and raw top-down RGBA8. */
#include <lz4.h>
#include <string.h>

#include "enc_internal.h"
#include "frame_lz4.h"

int enc__lz4(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err)
{
    size_t row = (size_t)f->width * 4, raw = row * (size_t)f->height;
    if (raw > (size_t)LZ4_MAX_INPUT_SIZE)
        return sd_errf(err, SD_EINVAL, "encoder: a %dx%d frame (%zu bytes) is over LZ4's input "
                       "limit of %d bytes", f->width, f->height, raw, LZ4_MAX_INPUT_SIZE);
    size_t bound = (size_t)LZ4_compressBound((int)raw);
    if (enc__reserve(&e->scratch, &e->scratch_cap, raw) ||
        enc__reserve(&e->buf, &e->buf_cap, SP_LZ4_HEADER_SIZE + bound))
        return sd_errf(err, SD_ENOMEM, "encoder: out of memory for a %zu-byte LZ4 frame", raw);
    enc__flip_rows(e->scratch, f->rgba8, row, f->height);
    sp_lz4_header_put(e->buf, (uint32_t)f->width, (uint32_t)f->height);
    int n = LZ4_compress_default((const char *)e->scratch, (char *)e->buf + SP_LZ4_HEADER_SIZE,
                                 (int)raw, (int)bound);
    if (n <= 0)
        return sd_errf(err, SD_EIO, "encoder: LZ4 failed to compress a %dx%d frame", f->width,
                       f->height);
    e->buf_len = SP_LZ4_HEADER_SIZE + (size_t)n;
    *out = e->buf;
    *len = e->buf_len;
    return 0;
}

int enc__raw(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err)
{
    size_t row = (size_t)f->width * 4, raw = row * (size_t)f->height;
    if (enc__reserve(&e->buf, &e->buf_cap, raw))
        return sd_errf(err, SD_ENOMEM, "encoder: out of memory for a %zu-byte raw frame", raw);
    enc__flip_rows(e->buf, f->rgba8, row, f->height);
    e->buf_len = raw;
    *out = e->buf;
    *len = raw;
    return 0;
}
