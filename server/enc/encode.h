/* encode.h — frame encoders: JPEG (TurboJPEG), PNG (libpng), LZ4 ("SPL4"), raw RGBA8, and EXR
 * (OpenEXR C API, half RGBA + float Z), in memory for the daemon and to files for scripted jobs.
 *
 * Input is an rnd_frame as the renderer leaves it: rows bottom-up (GL order). Every output is
 * top-down (the first row is the top of the image), which is what JPEG, PNG and EXR viewers
 * and the client decoder expect.
 *
 * Output formats (p->format, SP_FMT_*):
 *   jpeg  baseline JFIF, quality p->quality (1-100), subsampling p->subsampling
 *         (444|422|420|gray); alpha dropped.
 *   png   8-bit RGBA, zlib level 1 (frames favour speed over size).
 *   lz4   the SPL4 frame, defined in client/frame_decode.h (16-byte little-endian header
 *         {'SPL4', u32 width, u32 height, u32 raw size = width*height*4} + one LZ4 block of the
 *         top-down RGBA8 bytes).
 *   raw   width*height*4 bytes RGBA8, top-down, no header (size comes with the frame).
 *   exr   scanline OpenEXR, channels A B G R (half, from f->rgba16f) and Z (float, f->depth),
 *         increasing-Y line order, PIZ compression unless enc_set_exr_compression says
 *         otherwise; needs f->rgba16f and f->depth.
 *
 * Threading: an enc_ctx belongs to one thread at a time (one per encoder thread); different
 * contexts may encode concurrently. enc_write_file is thread-safe (it uses its own context). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "frame_lz4.h"
#include "params.h"
#include "render.h"
#include "sd_err.h"

#define ENC_MAX_DIM SP_FRAME_MAX_DIM /* largest width or height accepted (render.h's default limit is 8192) */

typedef struct enc_ctx enc_ctx;

/* EXR compressions selectable with enc_set_exr_compression. PIZ is the default: lossless, and
 * on the bench frame (tests/bench/enc_bench.c) 4% smaller and twice as fast as ZIP. RLE is
 * 4x faster than PIZ for files 1.5x larger. */
typedef enum { ENC_EXR_PIZ = 0, ENC_EXR_ZIP, ENC_EXR_RLE, ENC_EXR_NONE } enc_exr_compression;

/* enc_create: a new encoder with its TurboJPEG handle; buffers grow on first use.
 * Returns NULL with err filled (SD_ENOMEM, or SD_EINVAL when TurboJPEG cannot start). */
enc_ctx *enc_create(sd_err *err);

/* enc_destroy: frees e and every buffer it handed out. NULL is allowed. */
void enc_destroy(enc_ctx *e);

/* enc_set_exr_compression: compression for later EXR frames of e. Returns 0, or SD_EINVAL for
 * a value outside enc_exr_compression. */
int enc_set_exr_compression(enc_ctx *e, enc_exr_compression c, sd_err *err);

/* enc_encode: encodes frame f in format p->format (quality and subsampling from p for JPEG).
 * On success returns 0 and sets *out and *out_len to bytes owned by e, valid until the next call
 * on e or enc_destroy. The JPEG buffer is allocated once for the worst case of the frame size
 * (tjBufSize) and reused, so frames of the same size never reallocate. Returns a negative
 * SD_E* code with err filled: SD_EINVAL for a bad frame, size or parameter (or EXR without
 * float data), SD_ENOMEM, SD_EIO when a codec library fails. */
int enc_encode(enc_ctx *e, const rnd_frame *f, const sp_params *p, const uint8_t **out,
               size_t *out_len, sd_err *err);

/* enc_format_from_path: the SP_FMT_* of a file name's extension, case-insensitive: .jpg/.jpeg,
 * .png, .exr, .raw. Returns the format (>= 0), or SD_EINVAL with err naming the extension. */
int enc_format_from_path(const char *path, sd_err *err);

/* enc_write_file: encodes f in the format of path's extension (enc_format_from_path; JPEG
 * quality and subsampling from p, defaults when p is NULL; EXR with PIZ) and writes it to
 * path. The bytes go to a new temporary file in the same directory, which is renamed over
 * path only when complete, so a failed write leaves neither a truncated file nor a temporary
 * one. Returns 0, or a negative SD_E* code with err naming the path (SD_EIO for file system
 * errors, otherwise as enc_encode). */
int enc_write_file(const char *path, const rnd_frame *f, const sp_params *p, sd_err *err);
