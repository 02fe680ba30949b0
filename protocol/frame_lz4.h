/* frame_lz4.h — the SPL4 frame (the FRAME payload of format "lz4"): lossless RGBA8, written by
 * the daemon's encoder and read by libsplatclient. All integers little-endian:
 *
 *   offset size  field
 *   0      4     magic, the bytes 'S' 'P' 'L' '4'
 *   4      4     u32 width in pixels, 1..SP_FRAME_MAX_DIM
 *   8      4     u32 height in pixels, 1..SP_FRAME_MAX_DIM
 *   12     4     u32 raw size in bytes, must equal width * height * 4
 *   16     n     one LZ4 block (LZ4_compress_default, not the LZ4 frame format) that
 *                decompresses to exactly raw size bytes: RGBA8 pixels, rows top-down
 *
 * n is the rest of the payload (the message length says where it ends). A reader checks every
 * field before it allocates: magic, both dimensions, raw size = width*height*4, and raw size
 * against the most that n bytes of LZ4 can expand to (sp_lz4_header_get does all of that). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#define SP_LZ4_MAGIC "SPL4"
enum {
    SP_LZ4_HEADER_SIZE = 16,
    SP_FRAME_MAX_DIM = 16384, /* largest width or height of a frame, either side */
    /* The most an LZ4 block can expand: long matches cost one length byte per 255 output
     * bytes, so n bytes never decode to more than about 255 * n (measured: 10^8 zero bytes ->
     * 392167 bytes, 254.99:1). A header whose raw size exceeds 255 * n + 64 is refused. */
    SP_LZ4_MAX_RATIO = 255,
};

/* Results of sp_lz4_header_get. */
enum { SP_LZ4_OK = 0, SP_LZ4_ETRUNC = -1, SP_LZ4_EFORMAT = -2, SP_LZ4_ELIMIT = -3 };

/* sp_lz4_header_put: writes the 16-byte header of a width x height frame to out. */
void sp_lz4_header_put(uint8_t out[SP_LZ4_HEADER_SIZE], uint32_t width, uint32_t height);

/* sp_lz4_header_get: parses and checks the header of an SPL4 payload of len bytes. Returns
 * SP_LZ4_OK with *width and *height set, or SP_LZ4_ETRUNC (shorter than the header),
 * SP_LZ4_EFORMAT (magic; raw size not width*height*4 or beyond what the block can expand
 * to), SP_LZ4_ELIMIT (a dimension outside 1..SP_FRAME_MAX_DIM), with err (may be NULL)
 * naming the field and its byte offset. */
int sp_lz4_header_get(const uint8_t *data, size_t len, uint32_t *width, uint32_t *height,
                      char *err, size_t errlen);
