/* laz_arith.c — the arithmetic decoder, its models and the integer decompressor (laz_arith.h). */
#include "laz_arith.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#define AC_MAX_LENGTH 0xFFFFFFFFu
#define BM_SHIFT LAZ_BM_SHIFT
#define BM_MAX_COUNT (1u << BM_SHIFT)
#define DM_MAX_COUNT (1u << LAZ_DM_SHIFT)

/* Decoder tables. LASzip gives models over 16 symbols a table of n/8 to n/4 entries; here
 * every model over TABLE_MIN symbols has 2^LAZ_TABLE_BITS. The table only narrows the search
 * for the symbol (the symbol is the one whose cumulative range holds value / length, whatever
 * the table), and a finer table leaves fewer candidates: about 15 % faster on autzen_trim.
 * One size for all makes the bucket shift a constant. */
#define TABLE_MIN 4
#define TABLE_SIZE (1u << LAZ_TABLE_BITS)

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
    if (v == AC_MAX_LENGTH) {
        d->overrun = 1;
        v = AC_MAX_LENGTH - 1;
    }
    d->value = v;
}

/* ---- bit model ---- */

void laz_bitmodel_init(laz_bitmodel *m)
{
    m->bit0_count = 1;
    m->bit_count = 2;
    m->bit0_prob = 1u << (BM_SHIFT - 1);
    m->cycle = m->until = 4;
}

void laz__bitmodel_update(laz_bitmodel *m)
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

/* ---- symbol model ---- */

/* FILL_TABLE: dist from the counts, and the decoder table of entries of type T (u8 or u16).
 * table[j] = the last symbol whose range starts below bucket j (a lower bound of the symbol
 * of any value in bucket j). Symbol k - 1 fills buckets s+1 .. w: the first 16 / sizeof(T)
 * with one unconditional 16-byte store (most runs are that short; an exit branch per run
 * mispredicts), the rest as many at a time. Stores past w are overwritten by the next symbols
 * or the final fill; the block has spare entries. */
#define FILL_TABLE(T, tab, splat)                                                            \
    do {                                                                                     \
        const uint32_t per = 16 / sizeof(T);                                                 \
        uint32_t s = 0;                                                                      \
        T *t = (tab);                                                                        \
        for (uint32_t k = 0; k < m->n; k++) {                                                \
            m->dist[k] = (uint16_t)((scale * sum) >> (31 - LAZ_DM_SHIFT));                   \
            sum += m->count[k];                                                              \
            uint32_t w = m->dist[k] >> (LAZ_DM_SHIFT - LAZ_TABLE_BITS);                      \
            uint64_t a = (uint64_t)(T)(k - 1) * (splat), all[2] = {a, a};                    \
            memcpy(t + s + 1, all, sizeof all);                                              \
            for (uint32_t j = s + 1 + per; j <= w; j += per) memcpy(t + j, all, sizeof all); \
            s = w;                                                                           \
        }                                                                                    \
        t[0] = 0;                                                                            \
        for (uint32_t j = s + 1; j <= TABLE_SIZE + 1; j++) t[j] = (T)(m->n - 1);             \
    } while (0)

void laz__model_update(laz_model *m)
{
    if ((m->total += m->cycle) > DM_MAX_COUNT) {
        m->total = 0;
        for (uint32_t k = 0; k < m->n; k++) m->total += (m->count[k] = (m->count[k] + 1) >> 1);
    }
    uint32_t scale = 0x80000000u / m->total, sum = 0;
    if (m->table) {
        FILL_TABLE(uint8_t, m->table, 0x0101010101010101ull);
    } else if (m->table16) {
        FILL_TABLE(uint16_t, m->table16, 0x0001000100010001ull);
    } else {
        for (uint32_t k = 0; k < m->n; k++) {
            m->dist[k] = (uint16_t)((scale * sum) >> (31 - LAZ_DM_SHIFT));
            sum += m->count[k];
        }
    }
    m->cycle = (5 * m->cycle) >> 2;
    uint32_t max_cycle = (m->n + 6) << 3;
    if (m->cycle > max_cycle) m->cycle = max_cycle;
    m->until = m->cycle;
}

/* Fresh models (every count 1, then the first update) of n <= 256 symbols with a decoder
 * table, built once per n and copied: every chunk starts its models fresh, pointwise LAZ up to
 * 768 lazily made 256-symbol ones, and the integer decompressors dozens of 2..256-symbol ones,
 * and building each (counts, distribution, table) was most of the decoding time of a small or
 * noisy chunk. Made at their first use, kept for the process (reachable from fresh[]). */
typedef struct fresh_model {
    uint32_t total, cycle, until;
    size_t bytes;                   /* of block: counts, distribution and table */
    _Alignas(64) uint8_t block[];
} fresh_model;
static fresh_model *fresh[257];
static pthread_mutex_t fresh_lock = PTHREAD_MUTEX_INITIALIZER;
static int model_build(laz_model *m, uint32_t n, int tab);

/* block_bytes: the block of a model of n <= 256 symbols with a table (model_build's layout). */
static size_t block_bytes(uint32_t n)
{
    return sizeof(uint32_t) * n + sizeof(uint16_t) * (n + 1) + TABLE_SIZE + 17;
}

/* fresh_get: the fresh model of n symbols (1 <= n <= 256, with a table), or NULL when out of
 * memory. */
static const fresh_model *fresh_get(uint32_t n)
{
    pthread_mutex_lock(&fresh_lock);
    fresh_model *f = fresh[n];
    laz_model m = {0};
    if (!f && model_build(&m, n, 1) == 0 && (f = malloc(sizeof *f + block_bytes(n)))) {
        f->bytes = block_bytes(n);
        memcpy(f->block, m.count, f->bytes);
        f->total = m.total, f->cycle = m.cycle, f->until = m.until;
        fresh[n] = f;
    }
    laz_model_free(&m);
    pthread_mutex_unlock(&fresh_lock);
    return f;
}

/* model_init: laz_model_init, with a decoder table whatever n when tab is set. */
static int model_init(laz_model *m, uint32_t n, int tab)
{
    const fresh_model *f = n >= 1 && n <= 256 && (n > TABLE_MIN || tab) &&
                           (!m->count || m->n == n) ? fresh_get(n) : NULL;
    if (!f) return model_build(m, n, tab);
    if (!m->count) {
        void *blk = NULL;
        if (posix_memalign(&blk, 64, f->bytes)) return -1;
        m->count = blk;
        m->dist = (uint16_t *)(m->count + n);
        m->table = (uint8_t *)(m->dist + n + 1);
        m->table16 = NULL;
        m->n = n;
        m->last = n - 1;
    }
    memcpy(m->count, f->block, f->bytes);
    m->total = f->total, m->cycle = f->cycle, m->until = f->until;
    return 0;
}

/* model_build: a model of n symbols, counts 1 and distribution computed (a decoder table
 * whatever n when tab is set); m's block is allocated at its first use. */
static int model_build(laz_model *m, uint32_t n, int tab)
{
    if (!m->count) {
        uint32_t tsize = 0;
        if (n > TABLE_MIN || tab) tsize = TABLE_SIZE;
        /* one block: n counts (u32), n + 1 distribution values (u16, < 2^15) and the table
         * (bytes up to 256 symbols, else u16; 16 spare entries for the 16-byte stores) */
        size_t tbytes = tsize ? (tsize + 17) * (n > 256 ? 2 : 1) : 0;
        /* cache-line aligned: where a model's block falls changed the decode speed by up to
         * 9 % (the table, dist and count lines of the hot models) */
        void *blk = NULL;
        if (posix_memalign(&blk, 64, sizeof(uint32_t) * (size_t)n +
                                         sizeof(uint16_t) * ((size_t)n + 1) + tbytes))
            return -1;
        m->count = blk;
        m->dist = (uint16_t *)(m->count + n);
        m->dist[n] = 0;        /* read, never used, by the decoder's branch-free last-symbol case */
        m->table = tsize && n <= 256 ? (uint8_t *)(m->dist + n + 1) : NULL;
        m->table16 = tsize && n > 256 ? m->dist + n + 1 : NULL;
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

int laz_model_init(laz_model *m, uint32_t n) { return model_init(m, n, 0); }

void laz_model_free(laz_model *m)
{
    free(m->count);
    m->count = NULL;
    m->dist = m->table16 = NULL;
    m->table = NULL;
}

/* ---- integer decompressor ---- */

int laz_ic_create(laz_ic *ic, unsigned bits, unsigned contexts)
{
    *ic = (laz_ic){0};
    if (bits && bits < 4) return -1; /* its bit-count models would have no decoder table */
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
    /* every correction model has a table, the 2- and 4-symbol ones too: one decoding path
     * for every k, no branch on the model's size (k is data, the branch mispredicted) */
    for (unsigned i = 1; i <= ic->corr_bits; i++)
        if (model_init(&ic->corr[i], 1u << (i <= ic->bits_high ? i : ic->bits_high), 1))
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
