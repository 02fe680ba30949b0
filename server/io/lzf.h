/* lzf.h — a bounds-checked LZF decompressor (the format of liblzf, used by PCD
 * binary_compressed).
 *
 * The stream is a sequence of chunks, each starting with a control byte c:
 *   c < 32   a literal run: the next c + 1 input bytes are copied to the output;
 *   c >= 32  a back reference: len = c >> 5, and when len == 7 one more byte is added to it;
 *            the next byte b gives the distance ((c & 31) << 8) + b + 1 back from the current
 *            output position, and len + 2 bytes are copied from there (they may overlap the
 *            bytes being written, which repeats a pattern).
 * Written from that description; every read and write is checked against its buffer. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

/* pc_lzf_decompress: decodes the LZF stream in[0, in_len) into out[0, out_len), which must
 * come out exactly full. name and base are only for messages: the file and the byte offset of
 * in[0] in it. Returns 0; SD_ETRUNC when the stream ends inside a chunk or yields fewer than
 * out_len bytes; SD_EFORMAT when a chunk would write past out_len bytes or a back reference
 * reaches before the start of the output. err names the file offset of the failing chunk.
 * out's contents are unspecified on failure. */
int pc_lzf_decompress(const uint8_t *in, size_t in_len, uint8_t *out, size_t out_len,
                      const char *name, uint64_t base, sd_err *err);

/* The most output one input byte can produce: a 3-byte back reference yields 264 bytes, so an
 * LZF stream of n bytes decodes to at most 88 * n bytes. Callers use it to reject a declared
 * uncompressed size that no stream of the given length could reach, before allocating it. */
#define PC_LZF_MAX_RATIO 88u
