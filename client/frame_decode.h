/* frame_decode.h — decoding FRAME payloads in the client library: JPEG (TurboJPEG), SPL4
 * (LZ4) and raw RGBA8, always to top-down RGBA8. PNG and EXR are file formats (splatd render,
 * splat render -o); the client saves those bytes as they come and does not decode them.
 *
 * The SPL4 frame (format "lz4"), all integers little-endian:
 *
 *   offset size  field
 *   0      4     magic, the bytes 'S' 'P' 'L' '4'
 *   4      4     u32 width in pixels, 1..FD_MAX_DIM
 *   8      4     u32 height in pixels, 1..FD_MAX_DIM
 *   12     4     u32 raw size in bytes, must equal width * height * 4
 *   16     n     one LZ4 block (LZ4_compress_default, not the LZ4 frame format) that
 *                decompresses to exactly raw size bytes: RGBA8 pixels, rows top-down
 *
 * n is the rest of the payload (the message length says where it ends). The decoder checks
 * every field before it allocates: magic, both dimensions, raw size = width*height*4, the
 * dimensions against the ones the FRAME header announced, raw size against the most that n
 * bytes of LZ4 can expand to, and that decompression yields exactly raw size bytes.
 *
 * Errors follow sd_err.h's codes (negative SD_E*), with a sentence in err. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#define FD_LZ4_MAGIC "SPL4"
#define FD_LZ4_HEADER_SIZE 16
#define FD_MAX_DIM 16384      /* largest width or height accepted, as the server's ENC_MAX_DIM */
/* The most an LZ4 block can expand: long matches cost one length byte per 255 output bytes,
 * so n bytes never decode to more than about 255 * n (measured: 10^8 zero bytes -> 392167
 * bytes, 254.99:1). A header whose raw size exceeds 255 * n + 64 is refused unallocated. */
#define FD_LZ4_MAX_RATIO 255

typedef struct fd_ctx fd_ctx;

/* fd_create: a decoder with its TurboJPEG handle and an output buffer that grows on demand.
 * Returns NULL with err filled (out of memory, or TurboJPEG failed to start). */
fd_ctx *fd_create(char *err, size_t errlen);

/* fd_destroy: frees d and its buffers. NULL is allowed. */
void fd_destroy(fd_ctx *d);

/* fd_lz4_header: parses and checks an SPL4 header (payload of len bytes). Returns 0 and sets
 * *width and *height, or SD_ETRUNC (shorter than the header), SD_EFORMAT (magic, raw size not
 * width*height*4, raw size beyond what the payload can expand to), SD_ELIMIT (a dimension
 * outside 1..FD_MAX_DIM), each with err naming the field and byte offset. */
int fd_lz4_header(const uint8_t *data, size_t len, int *width, int *height, char *err,
                  size_t errlen);

/* fd_decode: decodes a FRAME payload of format fmt (SP_FMT_JPEG, SP_FMT_LZ4 or SP_FMT_RAW from
 * params.h) to top-down RGBA8 (alpha 255 for JPEG). width/height are the size the FRAME header
 * announced: required (> 0) for raw; for JPEG and LZ4 the payload's own size must match them
 * when they are > 0. On success returns 0, sets *rgba to width*height*4 bytes and *out_w and
 * *out_h (may be NULL). The pixels belong to d and stay valid until the next call, except for
 * raw, where *rgba points into data itself (no copy). Returns SD_EUNSUP for PNG/EXR/unknown
 * formats, SD_ELIMIT for sizes over FD_MAX_DIM, SD_EFORMAT/SD_ETRUNC for corrupt payloads,
 * SD_ENOMEM, all with err filled. */
int fd_decode(fd_ctx *d, int fmt, const uint8_t *data, size_t len, int width, int height,
              const uint8_t **rgba, int *out_w, int *out_h, char *err, size_t errlen);
