/* laz_arith.h — the entropy decoder of LASzip-compressed LAS (LAZ): an arithmetic decoder with
 * adaptive bit and symbol models, raw-bit reads, and the integer decompressor built on them.
 *
 * The coder is the one LASzip uses (after Amir Said's FastAC): 32-bit interval, renormalised a
 * byte at a time below 2^24; symbol models keep counts that are rescaled into a 15-bit
 * cumulative distribution every update cycle (cycle starts at (n+6)/2, grows by 5/4, capped at
 * 8(n+6)); bit models use 13-bit probabilities with a cycle capped at 64. Models over 4
 * symbols carry a lookup table that narrows the search for the decoded symbol (its size is
 * ours: it changes speed, never the symbol). Every other constant below is a fact of the
 * format: a different value decodes different points.
 *
 * The integer decompressor reads a correction to a prediction: a symbol k (the number of bits
 * of the correction, per context), then the correction itself from a model of 2^k symbols (k up
 * to 8) or a model of 256 symbols plus k-8 raw bits, and maps it back to a signed value.
 *
 * Reading past the end of the compressed bytes gives zeros and sets dec->overrun: the caller
 * reports the chunk as truncated. Internal to the LAZ reader (laz_ prefix). */
#pragma once
#include <stddef.h>
#include <stdint.h>

typedef struct laz_dec {
    const uint8_t *p, *end; /* the compressed bytes still to read */
    uint32_t value, length;
    int overrun;            /* set when a read went past end */
} laz_dec;

typedef struct laz_bitmodel {
    uint32_t bit0_prob, bit0_count, bit_count, cycle, until;
} laz_bitmodel;

typedef struct laz_model {
    uint32_t *count;        /* n counts, then (same block) dist and table */
    uint16_t *dist;         /* n cumulative probabilities (15 bits) */
    uint8_t *table;         /* the decoder table of a model of 5 .. 256 symbols, else NULL */
    uint16_t *table16;      /* the same over 256 symbols (GPS time's multiplier), else NULL */
    uint32_t n, last, total, cycle, until;
} laz_model;

typedef struct laz_ic {
    uint32_t contexts, bits_high, corr_bits, corr_range;
    int32_t corr_min;
    unsigned k;             /* the bit count of the last correction (LASzip's getK) */
    laz_model *mbits;       /* contexts models of corr_bits + 1 symbols */
    laz_bitmodel corr0;     /* the correction when k is 0 */
    laz_model *corr;        /* corr[k] for k = 1 .. corr_bits (corr[0] unused) */
} laz_ic;

/* laz_dec_init: starts decoding the bytes [p, end): reads the first 4 bytes. Every step of the
 * decoder keeps value < length once it holds at the start; a stream starting with 4 bytes of
 * 0xFF (which no encoder writes: its code lies below the initial length 2^32 - 1) is corrupt:
 * dec->overrun is set, and value made one less so that the decoder's bounds still hold. */
void laz_dec_init(laz_dec *d, const uint8_t *p, const uint8_t *end);

/* laz_model_init: (re)starts m as a fresh model of n symbols (2 <= n <= 2048), allocating on
 * first use. Returns 0, or -1 when out of memory. */
int laz_model_init(laz_model *m, uint32_t n);
void laz_model_free(laz_model *m);
void laz_bitmodel_init(laz_bitmodel *m);

/* laz_ic_create: an integer decompressor of bits (4..32, 0 meaning 32: full-range values; LAZ
 * uses 16 and 32) and contexts contexts, bits_high 8 as LASzip uses everywhere. Returns 0 or -1
 * (out of memory, or bits 1..3). */
int laz_ic_create(laz_ic *ic, unsigned bits, unsigned contexts);
/* laz_ic_init: fresh models, as at the start of a chunk. Returns 0 or -1 (out of memory). */
int laz_ic_init(laz_ic *ic);
void laz_ic_free(laz_ic *ic);

#define LAZ_AC_MIN_LENGTH 0x01000000u /* renormalise below 2^24 */
#define LAZ_DM_SHIFT 15               /* symbol model distribution bits */
#define LAZ_BM_SHIFT 13               /* bit model probability bits */
#define LAZ_TABLE_BITS 8              /* decoder table: 2^8 buckets of the 15-bit distribution */

/* Internal to laz_arith.c, called from the inline decoder below. */
void laz__model_update(laz_model *m);
void laz__bitmodel_update(laz_bitmodel *m);

/* The decoding functions below are forced inline: an item decoder copies its coder into a
 * local laz_dec, so that value, length and the byte pointer stay in registers across all the
 * symbols of a point, and writes it back once (see laz_v2.c / laz_v3.c). */
#define LAZ_INLINE static inline __attribute__((always_inline))

/* The functions that decode whole items (and inline everything above) are compiled twice on
 * x86-64: for x86-64-v3 (BMI2's one-cycle variable shifts and LZCNT in the renormalisation)
 * and for the baseline; the loader picks one for the CPU at hand. About 4 % on autzen_trim. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define LAZ_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define LAZ_CLONES
#endif

/* laz_renorm: after a symbol, shifts in bytes until length >= 2^24. The number of bytes is
 * clz(length) / 8 (length is never 0: every symbol keeps a nonzero share of the interval), read
 * as one big-endian word while 4 bytes remain; the last bytes of the stream go one at a time,
 * past the end as zeros with overrun set. */
LAZ_INLINE void laz_renorm(laz_dec *d)
{
    if (__builtin_expect(d->end - d->p >= 4, 1)) {
        /* branch-free: 0 to 3 bytes, whether or not length fell below 2^24 */
        unsigned sh = ((unsigned)__builtin_clz(d->length) >> 3) << 3;
        const uint8_t *q = d->p;
        uint32_t w = (uint32_t)q[0] << 24 | (uint32_t)q[1] << 16 | (uint32_t)q[2] << 8 | q[3];
        d->value = (d->value << sh) | (uint32_t)((uint64_t)w >> (32 - sh));
        d->length <<= sh;
        d->p += sh >> 3;
    } else {
        while (d->length < LAZ_AC_MIN_LENGTH) {
            uint32_t b = 0;
            if (d->p < d->end) b = *d->p++;
            else d->overrun = 1;
            d->value = (d->value << 8) | b;
            d->length <<= 8;
        }
    }
}

/* laz__symbol_done: the interval and the model after decoding sym. */
LAZ_INLINE uint32_t laz__symbol_done(laz_dec *d, laz_model *m, uint32_t sym, uint32_t x,
                                     uint32_t y)
{
    d->value -= x;
    d->length = y - x;
    laz_renorm(d);
    ++m->count[sym];
    if (--m->until == 0) laz__model_update(m);
    return sym;
}

/* laz_decode_symbol_tab: the next symbol of m, a model with a decoder table (over 4 symbols;
 * the item decoders call it where the model size says so, sparing the test). The symbol is
 * the one whose range [dist[s], dist[s+1]) holds value / (length >> 15): the table gives the
 * candidates of that quotient's bucket, a binary search the rest. */
#define LAZ_DECODE_TAB(tbl)                                                                \
    uint32_t y = d->length;                                                                  \
    uint32_t dv = d->value / (d->length >>= LAZ_DM_SHIFT);                                   \
    /* value < length always (laz_dec_init), so dv < 2^15 + 64 and t <= LAZ_TABLE_SIZE */    \
    uint32_t t = dv >> (LAZ_DM_SHIFT - LAZ_TABLE_BITS);                                      \
    uint32_t sym = m->tbl[t], n = m->tbl[t + 1] + 1u;                                    \
    while (n > sym + 1) {                                                                    \
        uint32_t k = (sym + n) >> 1;                                                         \
        if (m->dist[k] > dv) n = k;                                                          \
        else sym = k;                                                                        \
    }                                                                                        \
    uint32_t x = m->dist[sym] * d->length;                                                   \
    /* dist has a spare entry at n, so this load is in bounds for the last symbol too */     \
    uint32_t yn = m->dist[sym + 1] * d->length;                                              \
    return laz__symbol_done(d, m, sym, x, sym != m->last ? yn : y)

/* Tables of bytes for models up to 256 symbols (all but one): half the cache lines of u16
 * entries; the table load is on the decoder's serial chain. */
LAZ_INLINE uint32_t laz_decode_symbol_tab(laz_dec *d, laz_model *m)
{
    LAZ_DECODE_TAB(table);
}
/* laz_decode_symbol_tab16: the same for a model over 256 symbols. */
LAZ_INLINE uint32_t laz_decode_symbol_tab16(laz_dec *d, laz_model *m)
{
    LAZ_DECODE_TAB(table16);
}
/* laz_decode_symbol: the next symbol of any model (4 symbols or fewer: a binary search with
 * multiplications only, as LASzip). */
LAZ_INLINE uint32_t laz_decode_symbol(laz_dec *d, laz_model *m)
{
    if (m->table) return laz_decode_symbol_tab(d, m);
    if (m->table16) return laz_decode_symbol_tab16(d, m);
    uint32_t y = d->length, x = 0, sym = 0, n = m->n, k = n >> 1;
    d->length >>= LAZ_DM_SHIFT;
    do {
        uint32_t z = d->length * m->dist[k];
        if (z > d->value) {
            n = k;
            y = z;
        } else {
            sym = k;
            x = z;
        }
    } while ((k = (sym + n) >> 1) != sym);
    return laz__symbol_done(d, m, sym, x, y);
}

/* laz_decode_bit: the next bit of model m. */
LAZ_INLINE uint32_t laz_decode_bit(laz_dec *d, laz_bitmodel *m)
{
    uint32_t x = m->bit0_prob * (d->length >> LAZ_BM_SHIFT);
    uint32_t sym = d->value >= x, one = -sym; /* masks, not a branch: bits are coin tosses */
    d->value -= x & one;
    d->length = (x & ~one) | ((d->length - x) & one);
    m->bit0_count += sym ^ 1u;
    laz_renorm(d);
    if (--m->until == 0) laz__bitmodel_update(m);
    return sym;
}

/* laz_read_bits: 1 .. 32 raw bits (more than 19 as 16 low bits, then the rest). */
LAZ_INLINE uint32_t laz__read_raw(laz_dec *d, unsigned bits)
{
    uint32_t sym = d->value / (d->length >>= bits);
    d->value -= d->length * sym;
    laz_renorm(d);
    return sym;
}
LAZ_INLINE uint32_t laz_read_bits(laz_dec *d, unsigned bits)
{
    if (bits > 19) {
        uint32_t lower = laz__read_raw(d, 16) & 0xFFFFu;
        uint32_t upper = laz__read_raw(d, bits - 16);
        return (upper << 16) | lower;
    }
    return laz__read_raw(d, bits);
}
/* laz_read_int: 32 raw bits. */
LAZ_INLINE uint32_t laz_read_int(laz_dec *d)
{
    uint32_t lower = laz__read_raw(d, 16) & 0xFFFFu;
    uint32_t upper = laz__read_raw(d, 16) & 0xFFFFu;
    return (upper << 16) | lower;
}

/* laz_ic_decompress: pred plus the decoded correction, wrapped into the corrector's range. */
LAZ_INLINE int32_t laz_ic_decompress(laz_ic *ic, laz_dec *d, int32_t pred, unsigned context)
{
    unsigned k = laz_decode_symbol_tab(d, &ic->mbits[context]); /* 17 or 33 symbols */
    ic->k = k;
    uint32_t c;
    if (k == 0) {
        c = laz_decode_bit(d, &ic->corr0);
    } else if (k < 32) {
        c = laz_decode_symbol_tab(d, &ic->corr[k]); /* every corr model has a table */
        if (k > ic->bits_high) {
            unsigned k1 = k - ic->bits_high;
            c = (c << k1) | laz_read_bits(d, k1);
        }
        /* c in [0, 2^k): the upper half maps to [2^(k-1)+1, 2^k], the lower to negatives
         * (a select, not a branch: the sign of a correction is a coin toss) */
        c += c >= (1u << (k - 1)) ? 1u : 1u - (1u << k);
    } else {
        c = (uint32_t)ic->corr_min;
    }
    uint32_t real = (uint32_t)pred + c;
    if (ic->corr_range) {
        if ((int32_t)real < 0) real += ic->corr_range;
        else if (real >= ic->corr_range) real -= ic->corr_range;
    }
    return (int32_t)real;
}

/* The arithmetic of the item decoders, as LASzip defines it. */
static inline uint8_t laz_u8_fold(int32_t n)
{
    return (uint8_t)(n < 0 ? n + 256 : n > 255 ? n - 256 : n);
}
static inline int32_t laz_u8_clamp(int32_t n) { return n < 0 ? 0 : n > 255 ? 255 : n; }

/* StreamingMedian5: the median of the last five values, kept with a high/low insertion flag. */
typedef struct laz_median5 {
    int32_t v[5];
    int high;
} laz_median5;

static inline void laz_median5_init(laz_median5 *m)
{
    for (int i = 0; i < 5; i++) m->v[i] = 0;
    m->high = 1;
}
/* laz_median5_add: the high flag says which end leaves: the largest value after a value below
 * the median, the smallest after one above it. Written as a merge with min/max, no branches
 * (the insertion point is data-dependent and mispredicts); same values as the branchy form. */
static inline void laz_median5_add(laz_median5 *m, int32_t x)
{
    int32_t *v = m->v, t = x;
    int hi = m->high;
    const int32_t *keep = v + !hi; /* v[0..3] or v[1..4]: an offset, not a branch */
    /* x < v[2] (high) or x <= v[2] (low), as one 64-bit compare: no branch */
    m->high = (int64_t)x < (int64_t)v[2] + !hi;
    int32_t k0 = keep[0], k1 = keep[1], k2 = keep[2], k3 = keep[3];
    /* written out: a loop here was left rolled, its exit a mispredicted branch */
    int32_t lo = k0 < t ? k0 : t;
    t = k0 < t ? t : k0;
    v[0] = lo;
    lo = k1 < t ? k1 : t;
    t = k1 < t ? t : k1;
    v[1] = lo;
    lo = k2 < t ? k2 : t;
    t = k2 < t ? t : k2;
    v[2] = lo;
    lo = k3 < t ? k3 : t;
    t = k3 < t ? t : k3;
    v[3] = lo;
    v[4] = t;
}
static inline int32_t laz_median5_get(const laz_median5 *m) { return m->v[2]; }
