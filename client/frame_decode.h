/* frame_decode.h — decoding FRAME payloads in the client library: JPEG (TurboJPEG), SPL4
 * (LZ4) and raw RGBA8, always to top-down RGBA8. PNG and EXR are file formats (splatd render,
 * splat render -o); the client saves those bytes as they come and does not decode them.
 *
 * The SPL4 frame's layout is protocol/frame_lz4.h.
 *
 * Errors are the decoder's own FD_E* codes (negative), with a sentence in err. */
#pragma once
#include <stddef.h>
#include <stdint.h>

enum {
    FD_ETRUNC = -1,   /* the payload ends early */
    FD_EFORMAT = -2,  /* malformed payload, or a size other than the FRAME header's */
    FD_ELIMIT = -3,   /* a dimension over SP_FRAME_MAX_DIM (frame_lz4.h) */
    FD_ENOMEM = -4,
    FD_EUNSUP = -5,   /* a format the client does not decode (PNG, EXR: saved as files) */
    FD_EINVAL = -6,   /* a bad argument, or TurboJPEG failed to start */
};

typedef struct fd_ctx fd_ctx;

/* fd_create: a decoder with its TurboJPEG handle and an output buffer that grows on demand.
 * Returns NULL with err filled (out of memory, or TurboJPEG failed to start). */
fd_ctx *fd_create(char *err, size_t errlen);

/* fd_destroy: frees d and its buffers. NULL is allowed. */
void fd_destroy(fd_ctx *d);

/* fd_lz4_header: sp_lz4_header_get (frame_lz4.h) with the decoder's codes: 0, FD_ETRUNC,
 * FD_EFORMAT or FD_ELIMIT, each with err naming the field and byte offset. */
int fd_lz4_header(const uint8_t *data, size_t len, int *width, int *height, char *err,
                  size_t errlen);

/* fd_decode: decodes a FRAME payload of format fmt (SP_FMT_JPEG, SP_FMT_LZ4 or SP_FMT_RAW from
 * params.h) to top-down RGBA8 (alpha 255 for JPEG). width/height are the size the FRAME header
 * announced: required (> 0) for raw; for JPEG and LZ4 the payload's own size must match them
 * when they are > 0. On success returns 0, sets *rgba to width*height*4 bytes and *out_w and
 * *out_h (may be NULL). The pixels belong to d and stay valid until the next call, except for
 * raw, where *rgba points into data itself (no copy). Returns FD_EUNSUP for PNG/EXR/unknown
 * formats, FD_ELIMIT for sizes over SP_FRAME_MAX_DIM, FD_EFORMAT/FD_ETRUNC for corrupt payloads,
 * FD_ENOMEM, all with err filled. */
int fd_decode(fd_ctx *d, int fmt, const uint8_t *data, size_t len, int width, int height,
              const uint8_t **rgba, int *out_w, int *out_h, char *err, size_t errlen);
