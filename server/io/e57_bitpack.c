/* e57_bitpack.c — the bit-pack codec's decoder (e57_bitpack.h). */
#include "e57_bitpack.h"

#include <stdlib.h>
#include <string.h>

static uint64_t load64(const uint8_t *p)
{
    uint64_t v;
    memcpy(&v, p, 8);
#if __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    v = __builtin_bswap64(v);
#endif
    return v;
}

int e57_bp_append(e57_bp *b, const uint8_t *p, size_t n)
{
    size_t drop = (size_t)(b->bit / 8);
    if (drop) {
        memmove(b->buf, b->buf + drop, b->len - drop);
        b->len -= drop;
        b->bit -= 8 * (uint64_t)drop;
    }
    if (n > SIZE_MAX - b->len - 8) return -1;
    if (b->len + n + 8 > b->cap) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap < b->len + n + 8) cap *= 2;
        uint8_t *q = realloc(b->buf, cap);
        if (!q) return -1;
        b->buf = q;
        b->cap = cap;
    }
    if (n) memcpy(b->buf + b->len, p, n);
    b->len += n;
    memset(b->buf + b->len, 0, 8);
    return 0;
}

void e57_bp_free(e57_bp *b)
{
    free(b->buf);
    memset(b, 0, sizeof *b);
}

size_t e57_bp_avail(const e57_bp *b, int bits)
{
    if (bits == 0) return SIZE_MAX;
    uint64_t left = 8 * (uint64_t)b->len - b->bit;
    return (size_t)(left / (uint64_t)bits);
}

/* take: the next k bits (1 <= k <= 56: one 8-byte load holds them at any bit offset). */
static inline uint64_t take(e57_bp *b, int k)
{
    uint64_t v = load64(b->buf + b->bit / 8) >> (b->bit % 8);
    b->bit += (uint64_t)k;
    return v & ((UINT64_C(1) << k) - 1);
}

/* take_wide: the next k bits, 1 <= k <= 64 (over 56: the low 32 bits, then the rest). */
static inline uint64_t take_wide(e57_bp *b, int k)
{
    if (k <= 56) return take(b, k);
    uint64_t lo = take(b, 32);
    uint64_t hi = take(b, k - 32);
    return lo | hi << 32;
}

/* aligned: values of whole bytes (8, 16, 32, 64 bits) starting on a byte: read as they lie
 * (the common layout: doubles, floats, 8- and 16-bit integers). Returns as e57_bp_decode. */
static int64_t aligned(e57_bp *b, const e57_field *f, double *out, size_t n)
{
    const int k = f->bits, nb = k / 8;
    const uint8_t *p = b->buf + b->bit / 8;
    b->bit += (uint64_t)n * (uint64_t)k;
    if (!out) {
        if (f->kind == E57_FLOAT || f->kind == E57_DOUBLE) return -1;
    } else if (f->kind == E57_DOUBLE) {
        memcpy(out, p, 8 * n);
        return -1;
    } else if (f->kind == E57_FLOAT) {
        for (size_t i = 0; i < n; i++) {
            float x;
            memcpy(&x, p + 4 * i, 4);
            out[i] = x;
        }
        return -1;
    }
    const uint64_t range = (uint64_t)f->max - (uint64_t)f->min;
    const int scaled = f->kind == E57_SCALED;
    int64_t bad = -1;
    for (size_t i = 0; i < n; i++) {
        uint64_t raw = 0;
        if (nb == 1) raw = p[i];
        else if (nb == 2) raw = (uint64_t)p[2 * i] | (uint64_t)p[2 * i + 1] << 8;
        else for (int j = nb - 1; j >= 0; j--) raw = raw << 8 | p[(size_t)nb * i + (size_t)j];
        if (raw > range) {
            if (bad < 0) bad = (int64_t)i;
            raw = range;
        }
        if (!out) continue;
        int64_t v = (int64_t)((uint64_t)f->min + raw);
        out[i] = scaled ? (double)v * f->scale + f->offset : (double)v;
    }
    return bad;
}

int64_t e57_bp_decode(e57_bp *b, const e57_field *f, double *out, size_t n)
{
    const int k = f->bits;
    int64_t bad = -1;
#if __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    if (k && k % 8 == 0 && b->bit % 8 == 0) return aligned(b, f, out, n);
#endif
    if (f->kind == E57_FLOAT || f->kind == E57_DOUBLE) {
        for (size_t i = 0; i < n; i++) {
            uint64_t raw = take_wide(b, k);
            if (!out) continue;
            if (k == 32) {
                uint32_t w = (uint32_t)raw;
                float x;
                memcpy(&x, &w, 4);
                out[i] = x;
            } else {
                memcpy(&out[i], &raw, 8);
            }
        }
        return -1;
    }
    const uint64_t range = (uint64_t)f->max - (uint64_t)f->min;
    const double scale = f->scale, off = f->offset;
    const int scaled = f->kind == E57_SCALED;
    for (size_t i = 0; i < n; i++) {
        uint64_t raw = k == 0 ? 0 : take_wide(b, k);
        if (raw > range) {
            if (bad < 0) bad = (int64_t)i;
            raw = range;
        }
        if (!out) continue;
        int64_t v = (int64_t)((uint64_t)f->min + raw); /* wraps into [min, max] */
        out[i] = scaled ? (double)v * scale + off : (double)v;
    }
    return bad;
}
