/* e57_bitpack.h — the bit-pack codec of E57 compressed vectors: one bytestream per prototype
 * field, its values packed back to back in the field's bit width, least significant bit first
 * (bit k of the stream is bit k % 8 of byte k / 8), so a value may straddle bytes and the
 * buffers of consecutive data packets simply continue the stream. Integers and scaled integers
 * store value - minimum in e57_field.bits bits; floats their IEEE bits (32 or 64).
 *
 * An e57_bp holds the bytes of one stream not consumed yet: the compressed vector reader
 * appends each packet's buffer for the field when the decoder runs dry, so it holds at most one
 * packet's buffer plus the few bytes of a value cut by the packet's end. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "e57_scan.h"

typedef struct e57_bp {
    uint8_t *buf;   /* pending bytes, then 8 zero bytes (the decoder loads 8 bytes at a time) */
    size_t len;     /* pending bytes */
    size_t cap;     /* allocated bytes (len + 8 at least) */
    uint64_t bit;   /* the next unread bit of buf */
} e57_bp;

/* e57_bp_append: drops the bytes already consumed and appends n bytes. 0 or SD_ENOMEM. */
int e57_bp_append(e57_bp *b, const uint8_t *p, size_t n);
void e57_bp_free(e57_bp *b);

/* e57_bp_avail: how many whole values of `bits` bits the pending bytes hold (SIZE_MAX for a
 * 0-bit field). */
size_t e57_bp_avail(const e57_bp *b, int bits);

/* e57_bp_decode: the next n values of field f (n <= e57_bp_avail) as doubles into out (NULL:
 * skip them). An Integer's or ScaledInteger's raw value above maximum - minimum is an error:
 * returns the index of the first such value (its bits consumed) or -1 when all were in range. */
int64_t e57_bp_decode(e57_bp *b, const e57_field *f, double *out, size_t n);
