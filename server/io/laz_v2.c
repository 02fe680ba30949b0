/* laz_v2.c — pointwise LAZ chunks: the version-2 items POINT10 (the 20 bytes every format 0-5
 * record starts with), GPSTIME11, RGB12 and BYTE (extra bytes), all on one coded stream.
 *
 * POINT10 predicts x and y from the median of the last five differences in the same return
 * context (16 contexts from return number r and number of returns n), z from the last z at the
 * same return level |n - r|, and codes the other fields only when a 6-bit change mask says they
 * changed. GPSTIME11 codes the time difference as a multiple of the last difference, keeping
 * four sequences to jump between. RGB12 codes each colour byte against the previous point's,
 * green and blue predicted from red's change. BYTE codes each extra byte against its last. */
#include "laz_arith.h"
#include "laz_gps.h"
#include "laz_items.h"

#include <stdlib.h>
#include <string.h>

const uint8_t laz__return_map8[8][8] = {
    {15, 14, 13, 12, 11, 10, 9, 8},  {14, 0, 1, 3, 6, 10, 10, 9},
    {13, 1, 2, 4, 7, 11, 11, 10},    {12, 3, 4, 5, 8, 12, 12, 11},
    {11, 6, 7, 8, 9, 13, 13, 12},    {10, 10, 11, 12, 13, 14, 14, 13},
    {9, 10, 11, 12, 13, 14, 15, 14}, {8, 9, 10, 11, 12, 13, 14, 15},
};

static inline uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static inline void put16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}
static inline int32_t get32(const uint8_t *p)
{
    return (int32_t)((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
                     (uint32_t)p[3] << 24);
}
static inline void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* ---- POINT10 ---- */

typedef struct p10 {
    laz_model changed, scan[2];
    laz_ic ic_int, ic_psid, ic_dx, ic_dy, ic_z;
    laz_model bitbyte[256], cls[256], ud[256]; /* created when first needed */
    uint8_t bitbyte_on[256], cls_on[256], ud_on[256];
    laz_median5 mx[16], my[16];
    uint16_t last_int[16];
    int32_t last_h[8];
    uint8_t last[20];
} p10;

static int p10_create(p10 *s)
{
    memset(s, 0, sizeof *s);
    if (laz_ic_create(&s->ic_int, 16, 4) || laz_ic_create(&s->ic_psid, 16, 1) ||
        laz_ic_create(&s->ic_dx, 32, 2) || laz_ic_create(&s->ic_dy, 32, 22) ||
        laz_ic_create(&s->ic_z, 32, 20))
        return -1;
    return 0;
}

static void p10_free(p10 *s)
{
    laz_model_free(&s->changed);
    laz_model_free(&s->scan[0]);
    laz_model_free(&s->scan[1]);
    laz_ic_free(&s->ic_int);
    laz_ic_free(&s->ic_psid);
    laz_ic_free(&s->ic_dx);
    laz_ic_free(&s->ic_dy);
    laz_ic_free(&s->ic_z);
    for (int i = 0; i < 256; i++) {
        laz_model_free(&s->bitbyte[i]);
        laz_model_free(&s->cls[i]);
        laz_model_free(&s->ud[i]);
    }
}

static int p10_begin(p10 *s, const uint8_t *item)
{
    for (int i = 0; i < 16; i++) {
        laz_median5_init(&s->mx[i]);
        laz_median5_init(&s->my[i]);
        s->last_int[i] = 0;
        s->last_h[i / 2] = 0;
    }
    if (laz_model_init(&s->changed, 64) || laz_model_init(&s->scan[0], 256) ||
        laz_model_init(&s->scan[1], 256) || laz_ic_init(&s->ic_int) ||
        laz_ic_init(&s->ic_psid) || laz_ic_init(&s->ic_dx) || laz_ic_init(&s->ic_dy) ||
        laz_ic_init(&s->ic_z))
        return -1;
    memset(s->bitbyte_on, 0, sizeof s->bitbyte_on);
    memset(s->cls_on, 0, sizeof s->cls_on);
    memset(s->ud_on, 0, sizeof s->ud_on);
    memcpy(s->last, item, 20);
    s->last[12] = s->last[13] = 0; /* the intensity prediction starts from zero */
    return 0;
}

/* lazy: the model of a 256-symbol context, fresh at its first use in a chunk. */
static laz_model *lazy(laz_model *m, uint8_t *on)
{
    if (!*on) {
        if (laz_model_init(m, 256)) return NULL;
        *on = 1;
    }
    return m;
}

LAZ_CLONES static int p10_read(p10 *s, laz_dec *dp, uint8_t *item)
{
    laz_dec dd = *dp, *d = &dd; /* the coder in registers for the whole point */
    uint8_t *l = s->last;
    uint32_t changed = laz_decode_symbol_tab(d, &s->changed);
    unsigned r, n, m, lv;
    if (changed) {
        if (changed & 32) {
            laz_model *md = lazy(&s->bitbyte[l[14]], &s->bitbyte_on[l[14]]);
            if (!md) goto nomem;
            l[14] = (uint8_t)laz_decode_symbol_tab(d, md);
        }
        r = l[14] & 7;
        n = (l[14] >> 3) & 7;
        m = laz__return_map8[n][r];
        lv = n > r ? n - r : r - n;
        if (changed & 16) {
            uint16_t v = (uint16_t)laz_ic_decompress(&s->ic_int, d, s->last_int[m], m < 3 ? m : 3);
            s->last_int[m] = v;
            put16(l + 12, v);
        } else {
            put16(l + 12, s->last_int[m]);
        }
        if (changed & 8) {
            laz_model *md = lazy(&s->cls[l[15]], &s->cls_on[l[15]]);
            if (!md) goto nomem;
            l[15] = (uint8_t)laz_decode_symbol_tab(d, md);
        }
        if (changed & 4) {
            uint32_t v = laz_decode_symbol_tab(d, &s->scan[(l[14] >> 6) & 1]);
            l[16] = laz_u8_fold((int32_t)v + l[16]);
        }
        if (changed & 2) {
            laz_model *md = lazy(&s->ud[l[17]], &s->ud_on[l[17]]);
            if (!md) goto nomem;
            l[17] = (uint8_t)laz_decode_symbol_tab(d, md);
        }
        if (changed & 1)
            put16(l + 18, (uint16_t)laz_ic_decompress(&s->ic_psid, d, get16(l + 18), 0));
    } else {
        r = l[14] & 7;
        n = (l[14] >> 3) & 7;
        m = laz__return_map8[n][r];
        lv = n > r ? n - r : r - n;
    }
    unsigned one = n == 1;
    int32_t diff = laz_ic_decompress(&s->ic_dx, d, laz_median5_get(&s->mx[m]), one);
    put32(l, (uint32_t)get32(l) + (uint32_t)diff);
    laz_median5_add(&s->mx[m], diff);

    unsigned kb = s->ic_dx.k;
    diff = laz_ic_decompress(&s->ic_dy, d, laz_median5_get(&s->my[m]),
                             one + (kb < 20 ? (kb & ~1u) : 20));
    put32(l + 4, (uint32_t)get32(l + 4) + (uint32_t)diff);
    laz_median5_add(&s->my[m], diff);

    kb = (s->ic_dx.k + s->ic_dy.k) / 2;
    int32_t z = laz_ic_decompress(&s->ic_z, d, s->last_h[lv], one + (kb < 18 ? (kb & ~1u) : 18));
    put32(l + 8, (uint32_t)z);
    s->last_h[lv] = z;
    memcpy(item, l, 20);
    *dp = dd;
    return 0;
nomem:
    *dp = dd;
    return -1;
}

/* ---- RGB12 (also the RGB layer of RGB14 / RGBNIR14) ---- */

typedef struct rgb {
    laz_model used, diff[6];
    uint16_t last[3];
} rgb;

int laz__rgb_models_init(laz_model *used, laz_model *diff)
{
    if (laz_model_init(used, 128)) return -1;
    for (int i = 0; i < 6; i++)
        if (laz_model_init(&diff[i], 256)) return -1;
    return 0;
}

LAZ_CLONES void laz__rgb_decode(laz_dec *dp, laz_model *used, laz_model *dm, const uint16_t *last,
                     uint16_t *c)
{
    laz_dec dd = *dp, *d = &dd;
    uint32_t sym = laz_decode_symbol_tab(d, used);
    int32_t lo0 = last[0] & 0xFF, hi0 = last[0] >> 8;
    c[0] = (sym & 1) ? laz_u8_fold((int32_t)laz_decode_symbol_tab(d, &dm[0]) + lo0) : (uint16_t)lo0;
    c[0] |= (uint16_t)(((sym & 2) ? laz_u8_fold((int32_t)laz_decode_symbol_tab(d, &dm[1]) + hi0)
                                   : hi0) << 8);
    if (sym & 64) {
        int32_t diff = (c[0] & 0xFF) - lo0;
        int32_t lo1 = last[1] & 0xFF, lo2 = last[2] & 0xFF;
        c[1] = (sym & 4) ? laz_u8_fold((int32_t)laz_decode_symbol_tab(d, &dm[2]) +
                                       laz_u8_clamp(diff + lo1))
                         : (uint16_t)lo1;
        if (sym & 16) {
            int32_t corr = (int32_t)laz_decode_symbol_tab(d, &dm[4]);
            diff = (diff + ((c[1] & 0xFF) - lo1)) / 2;
            c[2] = laz_u8_fold(corr + laz_u8_clamp(diff + lo2));
        } else {
            c[2] = (uint16_t)lo2;
        }
        diff = (c[0] >> 8) - hi0;
        int32_t hi1 = last[1] >> 8, hi2 = last[2] >> 8;
        if (sym & 8) {
            int32_t corr = (int32_t)laz_decode_symbol_tab(d, &dm[3]);
            c[1] |= (uint16_t)(laz_u8_fold(corr + laz_u8_clamp(diff + hi1)) << 8);
        } else {
            c[1] |= (uint16_t)(hi1 << 8);
        }
        if (sym & 32) {
            int32_t corr = (int32_t)laz_decode_symbol_tab(d, &dm[5]);
            diff = (diff + ((c[1] >> 8) - hi1)) / 2;
            c[2] |= (uint16_t)(laz_u8_fold(corr + laz_u8_clamp(diff + hi2)) << 8);
        } else {
            c[2] |= (uint16_t)(hi2 << 8);
        }
    } else {
        c[1] = c[2] = c[0];
    }
    *dp = dd;
}

/* ---- the item list ---- */

typedef struct item_state {
    laz_item it;
    size_t off;          /* byte offset in the record */
    p10 *pt;
    laz_gps *g;
    rgb *c;
    laz_model *bytes;    /* BYTE: one model per byte */
    uint8_t *last_bytes;
} item_state;

struct laz_v2 {
    laz_dec d;
    unsigned n;
    size_t rec_len;
    item_state is[LAZ_MAX_ITEMS];
};

void laz__v2_free(laz_v2 *s)
{
    if (!s) return;
    for (unsigned i = 0; i < s->n; i++) {
        item_state *x = &s->is[i];
        if (x->pt) p10_free(x->pt);
        free(x->pt);
        if (x->g) laz_gps_free(x->g);
        free(x->g);
        if (x->c) {
            laz_model_free(&x->c->used);
            for (int k = 0; k < 6; k++) laz_model_free(&x->c->diff[k]);
        }
        free(x->c);
        if (x->bytes)
            for (unsigned k = 0; k < x->it.size; k++) laz_model_free(&x->bytes[k]);
        free(x->bytes);
        free(x->last_bytes);
    }
    free(s);
}

laz_v2 *laz__v2_create(const laz_item *items, unsigned nitems)
{
    laz_v2 *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->n = nitems;
    for (unsigned i = 0; i < nitems; i++) {
        item_state *x = &s->is[i];
        x->it = items[i];
        x->off = s->rec_len;
        s->rec_len += items[i].size;
        int bad = 0;
        switch (items[i].type) {
        case LAZ_ITEM_POINT10:
            x->pt = malloc(sizeof *x->pt);
            bad = !x->pt || p10_create(x->pt);
            break;
        case LAZ_ITEM_GPSTIME11:
            x->g = calloc(1, sizeof *x->g);
            bad = !x->g || laz_gps_create(x->g, 0);
            break;
        case LAZ_ITEM_RGB12:
            x->c = calloc(1, sizeof *x->c);
            bad = !x->c;
            break;
        default: /* BYTE */
            x->bytes = calloc(items[i].size, sizeof *x->bytes);
            x->last_bytes = malloc(items[i].size);
            bad = !x->bytes || !x->last_bytes;
            break;
        }
        if (bad) {
            s->n = i + 1;
            laz__v2_free(s);
            return NULL;
        }
    }
    return s;
}

int laz__v2_begin(laz_v2 *s, const uint8_t *p, const uint8_t *end, uint8_t *first,
                  const char **what)
{
    *what = "points";
    if ((size_t)(end - p) < s->rec_len) return LAZ_CHUNK_SHORT;
    memcpy(first, p, s->rec_len);
    p += s->rec_len;
    laz_dec_init(&s->d, p, end);
    for (unsigned i = 0; i < s->n; i++) {
        item_state *x = &s->is[i];
        const uint8_t *item = first + x->off;
        int rc = 0;
        if (x->pt) rc = p10_begin(x->pt, item);
        else if (x->g) {
            uint64_t t;
            memcpy(&t, item, 8);
            rc = laz_gps_begin(x->g, t);
        }
        else if (x->c) {
            rc = laz__rgb_models_init(&x->c->used, x->c->diff);
            for (int k = 0; k < 3; k++) x->c->last[k] = get16(item + 2 * k);
        } else {
            for (unsigned k = 0; k < x->it.size && !rc; k++)
                rc = laz_model_init(&x->bytes[k], 256);
            memcpy(x->last_bytes, item, x->it.size);
        }
        if (rc) return LAZ_CHUNK_NOMEM;
    }
    return 0;
}

LAZ_CLONES int laz__v2_next(laz_v2 *s, size_t npts, uint8_t *out, const char **what)
{
    laz_dec *d = &s->d;
    *what = "points";
    for (size_t j = 0; j < npts; j++) {
        uint8_t *rec = out + j * s->rec_len;
        for (unsigned i = 0; i < s->n; i++) {
            item_state *x = &s->is[i];
            uint8_t *item = rec + x->off;
            if (x->pt) {
                if (p10_read(x->pt, d, item)) return LAZ_CHUNK_NOMEM;
            } else if (x->g) {
                uint64_t t = laz_gps_read(x->g, d);
                memcpy(item, &t, 8);
            } else if (x->c) {
                uint16_t c[3];
                laz__rgb_decode(d, &x->c->used, x->c->diff, x->c->last, c);
                for (int k = 0; k < 3; k++) {
                    put16(item + 2 * k, c[k]);
                    x->c->last[k] = c[k];
                }
            } else {
                for (unsigned k = 0; k < x->it.size; k++) {
                    uint32_t v = laz_decode_symbol_tab(d, &x->bytes[k]);
                    item[k] = x->last_bytes[k] = laz_u8_fold((int32_t)v + x->last_bytes[k]);
                }
            }
        }
        if (d->overrun) return LAZ_CHUNK_SHORT;
    }
    return 0;
}
