/* enc_internal.h — shared by the encoder files (encode.c, enc_jpeg.c, enc_png.c, enc_lz4.c,
 * enc_exr.c); not part of the encoder's public interface (encode.h). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "encode.h"

struct enc_ctx {
    void *tj;                     /* tjhandle for compression */
    unsigned char *jpeg;          /* tjAlloc'd worst-case JPEG buffer (TJFLAG_NOREALLOC) */
    unsigned long jpeg_cap;       /* its size in bytes */
    uint8_t *buf;                 /* output of png, lz4, raw and exr */
    size_t buf_len, buf_cap;
    uint8_t *scratch;             /* flipped rows (lz4 input, one EXR chunk) */
    size_t scratch_cap;
    enc_exr_compression exr_compression;
    char lib_msg[256];            /* last message from a library's error callback */
};

/* enc__reserve: makes *buf hold at least need bytes (contents kept); 0 or SD_ENOMEM. */
int enc__reserve(uint8_t **buf, size_t *cap, size_t need);

/* enc__flip_rows: copies height rows of row_bytes each from src to dst in reverse order
 * (bottom-up <-> top-down). src and dst must not overlap. */
void enc__flip_rows(uint8_t *dst, const uint8_t *src, size_t row_bytes, int height);

/* The codecs: each checks what only it needs, encodes f and points *out and *len at e's buffers.
 * f has been validated (size, rgba8 present) by enc_encode. Return 0 or SD_E* with err. */
int enc__jpeg(enc_ctx *e, const rnd_frame *f, int quality, int subsampling, const uint8_t **out,
              size_t *len, sd_err *err);
int enc__png(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err);
int enc__lz4(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err);
int enc__raw(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err);
int enc__exr(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err);
