/* laz_arith.c — the arithmetic decoder, its models and the integer decompressor (laz_arith.h). */
#include "laz_arith.h"

#include <stdlib.h>

#define AC_MAX_LENGTH 0xFFFFFFFFu
#define BM_SHIFT 13               /* bit model probability bits */
#define BM_MAX_COUNT (1u << BM_SHIFT)
#define DM_MAX_COUNT (1u << LAZ_DM_SHIFT)

static inline uint32_t next_byte(laz_dec *d)
{
    if (d->p < d->end) return *d->p++;
    d->overrun = 1;
    return 0;
}

void laz_dec_init(laz_dec *d, const uint8_t *p, const uint8_t *end)
{
    d->p = p;
    d->end = end;
    d->overrun = 0;
    d->length = AC_MAX_LENGTH;
    uint32_t v = 0;
    for (int i = 0; i < 4; i++) v = (v << 8) | next_byte(d);
    d->value = v;
}

void laz__renorm(laz_dec *d)
{
    do {
        d->value = (d->value << 8) | next_byte(d);
        d->length <<= 8;
    } while (d->length < LAZ_AC_MIN_LENGTH);
}

/* ---- bit model ---- */

void laz_bitmodel_init(laz_bitmodel *m)
{
    m->bit0_count = 1;
    m->bit_count = 2;
    m->bit0_prob = 1u << (BM_SHIFT - 1);
    m->cycle = m->until = 4;
}

static void bitmodel_update(laz_bitmodel *m)
{
    if ((m->bit_count += m->cycle) > BM_MAX_COUNT) {
        m->bit_count = (m->bit_count + 1) >> 1;
        m->bit0_count = (m->bit0_count + 1) >> 1;
        if (m->bit0_count == m->bit_count) ++m->bit_count;
    }
    uint32_t scale = 0x80000000u / m->bit_count;
    m->bit0_prob = (m->bit0_count * scale) >> (31 - BM_SHIFT);
    m->cycle = (5 * m->cycle) >> 2;
    if (m->cycle > 64) m->cycle = 64;
    m->until = m->cycle;
}

uint32_t laz_decode_bit(laz_dec *d, laz_bitmodel *m)
{
    uint32_t x = m->bit0_prob * (d->length >> BM_SHIFT);
    uint32_t sym = d->value >= x;
    if (!sym) {
        d->length = x;
        ++m->bit0_count;
    } else {
        d->value -= x;
        d->length -= x;
    }
    if (d->length < LAZ_AC_MIN_LENGTH) laz__renorm(d);
    if (--m->until == 0) bitmodel_update(m);
    return sym;
}

/* ---- symbol model ---- */

void laz__model_update(laz_model *m)
{
    if ((m->total += m->cycle) > DM_MAX_COUNT) {
        m->total = 0;
        for (uint32_t k = 0; k < m->n; k++) m->total += (m->count[k] = (m->count[k] + 1) >> 1);
    }
    uint32_t scale = 0x80000000u / m->total, sum = 0;
    if (!m->table) {
        for (uint32_t k = 0; k < m->n; k++) {
            m->dist[k] = (scale * sum) >> (31 - LAZ_DM_SHIFT);
            sum += m->count[k];
        }
    } else {
        uint32_t s = 0;
        for (uint32_t k = 0; k < m->n; k++) {
            m->dist[k] = (scale * sum) >> (31 - LAZ_DM_SHIFT);
            sum += m->count[k];
            uint32_t w = m->dist[k] >> m->table_shift;
            while (s < w) m->table[++s] = k - 1;
        }
        m->table[0] = 0;
        while (s <= m->table_size) m->table[++s] = m->n - 1;
    }
    m->cycle = (5 * m->cycle) >> 2;
    uint32_t max_cycle = (m->n + 6) << 3;
    if (m->cycle > max_cycle) m->cycle = max_cycle;
    m->until = m->cycle;
}

int laz_model_init(laz_model *m, uint32_t n)
{
    if (!m->dist) {
        uint32_t tbits = 0, tsize = 0;
        if (n > 16) {
            tbits = 3;
            while (n > (1u << (tbits + 2))) ++tbits;
            tsize = 1u << tbits;
        }
        m->dist = malloc(sizeof(uint32_t) * (2 * (size_t)n + (tsize ? tsize + 2 : 0)));
        if (!m->dist) return -1;
        m->count = m->dist + n;
        m->table = tsize ? m->dist + 2 * n : NULL;
        m->table_size = tsize;
        m->table_shift = tsize ? LAZ_DM_SHIFT - tbits : 0;
        m->n = n;
        m->last = n - 1;
    }
    for (uint32_t k = 0; k < n; k++) m->count[k] = 1;
    m->total = 0;
    m->cycle = n;
    laz__model_update(m);
    m->cycle = m->until = (n + 6) >> 1;
    return 0;
}

void laz_model_free(laz_model *m)
{
    free(m->dist);
    m->dist = m->count = m->table = NULL;
}

/* ---- raw bits ---- */

static uint32_t read_short(laz_dec *d)
{
    uint32_t sym = d->value / (d->length >>= 16);
    d->value -= d->length * sym;
    if (d->length < LAZ_AC_MIN_LENGTH) laz__renorm(d);
    return sym & 0xFFFFu;
}

uint32_t laz_read_bits(laz_dec *d, unsigned bits)
{
    if (bits > 19) {
        uint32_t lower = read_short(d);
        uint32_t upper = laz_read_bits(d, bits - 16);
        return (upper << 16) | lower;
    }
    uint32_t sym = d->value / (d->length >>= bits);
    d->value -= d->length * sym;
    if (d->length < LAZ_AC_MIN_LENGTH) laz__renorm(d);
    return sym;
}

uint32_t laz_read_int(laz_dec *d)
{
    uint32_t lower = read_short(d);
    uint32_t upper = read_short(d);
    return (upper << 16) | lower;
}

/* ---- integer decompressor ---- */

int laz_ic_create(laz_ic *ic, unsigned bits, unsigned contexts)
{
    *ic = (laz_ic){0};
    ic->contexts = contexts;
    ic->bits_high = 8;
    if (bits && bits < 32) {
        ic->corr_bits = bits;
        ic->corr_range = 1u << bits;
        ic->corr_min = -(int32_t)(ic->corr_range / 2);
    } else {
        ic->corr_bits = 32;
        ic->corr_range = 0;
        ic->corr_min = INT32_MIN;
    }
    ic->mbits = calloc(contexts, sizeof *ic->mbits);
    ic->corr = calloc(ic->corr_bits + 1, sizeof *ic->corr);
    if (!ic->mbits || !ic->corr) {
        laz_ic_free(ic);
        return -1;
    }
    return 0;
}

int laz_ic_init(laz_ic *ic)
{
    for (unsigned c = 0; c < ic->contexts; c++)
        if (laz_model_init(&ic->mbits[c], ic->corr_bits + 1)) return -1;
    laz_bitmodel_init(&ic->corr0);
    for (unsigned i = 1; i <= ic->corr_bits; i++)
        if (laz_model_init(&ic->corr[i], 1u << (i <= ic->bits_high ? i : ic->bits_high)))
            return -1;
    ic->k = 0;
    return 0;
}

void laz_ic_free(laz_ic *ic)
{
    if (ic->mbits)
        for (unsigned c = 0; c < ic->contexts; c++) laz_model_free(&ic->mbits[c]);
    if (ic->corr)
        for (unsigned i = 0; i <= ic->corr_bits; i++) laz_model_free(&ic->corr[i]);
    free(ic->mbits);
    free(ic->corr);
    ic->mbits = NULL;
    ic->corr = NULL;
}

int32_t laz_ic_decompress(laz_ic *ic, laz_dec *d, int32_t pred, unsigned context)
{
    unsigned k = laz_decode_symbol(d, &ic->mbits[context]);
    ic->k = k;
    uint32_t c;
    if (k == 0) {
        c = laz_decode_bit(d, &ic->corr0);
    } else if (k < 32) {
        if (k <= ic->bits_high) {
            c = laz_decode_symbol(d, &ic->corr[k]);
        } else {
            unsigned k1 = k - ic->bits_high;
            c = laz_decode_symbol(d, &ic->corr[k]);
            c = (c << k1) | laz_read_bits(d, k1);
        }
        /* c in [0, 2^k): the upper half maps to [2^(k-1)+1, 2^k], the lower to negatives */
        if (c >= (1u << (k - 1))) c += 1;
        else c -= (1u << k) - 1;
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

void laz_median5_add(laz_median5 *m, int32_t x)
{
    int32_t *v = m->v;
    if (m->high) {
        if (x < v[2]) {
            v[4] = v[3];
            v[3] = v[2];
            if (x < v[0]) {
                v[2] = v[1];
                v[1] = v[0];
                v[0] = x;
            } else if (x < v[1]) {
                v[2] = v[1];
                v[1] = x;
            } else {
                v[2] = x;
            }
        } else {
            if (x < v[3]) {
                v[4] = v[3];
                v[3] = x;
            } else {
                v[4] = x;
            }
            m->high = 0;
        }
    } else {
        if (v[2] < x) {
            v[0] = v[1];
            v[1] = v[2];
            if (v[4] < x) {
                v[2] = v[3];
                v[3] = v[4];
                v[4] = x;
            } else if (v[3] < x) {
                v[2] = v[3];
                v[3] = x;
            } else {
                v[2] = x;
            }
        } else {
            if (v[1] < x) {
                v[0] = v[1];
                v[1] = x;
            } else {
                v[0] = x;
            }
            m->high = 1;
        }
    }
}
