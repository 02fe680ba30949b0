/* laz_v3.c — layered LAZ chunks (LAS 1.4 point formats 6-8): the version-3 items POINT14,
 * RGB14, RGBNIR14 and BYTE14.
 *
 * POINT14 splits its fields over nine layers, each its own coded stream: returns and x/y,
 * z, classification, flags, intensity, scan angle, user data, point source, GPS time. A layer
 * of zero bytes means the field keeps the chunk's first value. Every model exists once per
 * scanner channel (four contexts); a context is set up from the previous point when the
 * channel first switches to it within a chunk. The returns/xy layer decides everything else:
 * a 7-bit change mask (context: first/last return and whether the time changed last point)
 * says whether channel, return counts, scan angle, time and point source changed. The other
 * items follow the channel POINT14 decoded for the same point. */
#include "laz_arith.h"
#include "laz_gps.h"
#include "laz_items.h"

#include <stdlib.h>
#include <string.h>

const uint8_t laz__return_map16[16][16] = {
    {0, 1, 2, 3, 4, 5, 3, 4, 4, 5, 5, 5, 5, 5, 5, 5}, {1, 0, 1, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3},
    {2, 1, 2, 4, 4, 4, 4, 4, 4, 4, 4, 3, 3, 3, 3, 3}, {3, 3, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4},
    {4, 3, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4}, {5, 3, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4},
    {3, 3, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4}, {4, 3, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4},
    {4, 3, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4}, {5, 3, 4, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4},
    {5, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4}, {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 4, 4, 4},
    {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 4, 4}, {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 4},
    {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5}, {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5},
};

/* the return level |n - r|, capped at 7 (LASzip's 8-context level table) */
static inline unsigned level8(unsigned n, unsigned r)
{
    unsigned v = n > r ? n - r : r - n;
    return v > 7 ? 7 : v;
}

static inline uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static inline void put16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}
static inline uint32_t get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static inline void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* The fields of a format 6 record (30 bytes) that the coder works on. */
typedef struct p14 {
    int32_t x, y, z;
    uint16_t intensity, psid;
    int16_t scan_angle;
    uint8_t ret, nret, cflags, channel, sdir, edge, cls, ud;
    uint64_t gps;
    int gps_change;
} p14;

static void p14_unpack(p14 *q, const uint8_t *r)
{
    q->x = (int32_t)get32(r);
    q->y = (int32_t)get32(r + 4);
    q->z = (int32_t)get32(r + 8);
    q->intensity = get16(r + 12);
    q->ret = r[14] & 15;
    q->nret = r[14] >> 4;
    q->cflags = r[15] & 15;
    q->channel = (r[15] >> 4) & 3;
    q->sdir = (r[15] >> 6) & 1;
    q->edge = r[15] >> 7;
    q->cls = r[16];
    q->ud = r[17];
    q->scan_angle = (int16_t)get16(r + 18);
    q->psid = get16(r + 20);
    memcpy(&q->gps, r + 22, 8);
    q->gps_change = 0;
}

/* inline: a default-target function is not inlined into the x86-64-v3 clones by itself */
static inline __attribute__((always_inline)) void p14_pack(const p14 *q, uint8_t *r)
{
    put32(r, (uint32_t)q->x);
    put32(r + 4, (uint32_t)q->y);
    put32(r + 8, (uint32_t)q->z);
    put16(r + 12, q->intensity);
    r[14] = (uint8_t)(q->ret | q->nret << 4);
    r[15] = (uint8_t)(q->cflags | q->channel << 4 | q->sdir << 6 | q->edge << 7);
    r[16] = q->cls;
    r[17] = q->ud;
    put16(r + 18, (uint16_t)q->scan_angle);
    put16(r + 20, q->psid);
    memcpy(r + 22, &q->gps, 8);
}

/* ---- POINT14: one context per scanner channel ---- */

typedef struct ctx14 {
    int unused;
    p14 last;
    laz_model changed[8], channel, rgps_same, nret[16], rnum[16];
    uint8_t nret_on[16], rnum_on[16];
    laz_ic dx, dy, z, intensity, scan, psid;
    laz_gps gps;
    laz_median5 mx[12], my[12];
    int32_t last_z[8];
    uint16_t last_int[8];
    laz_model cls[64], flags[64], ud[64];
    uint8_t cls_on[64], flags_on[64], ud_on[64];
} ctx14;

enum { L_XY, L_Z, L_CLS, L_FLAGS, L_INT, L_SCAN, L_UD, L_PSID, L_GPS, L_P14 };
static const char *const layer_names[L_P14] = {
    "returns/xy", "z", "classification", "flags", "intensity", "scan angle", "user data",
    "point source", "gps time"};

typedef struct pt14 {
    ctx14 c[4];
    int created[4];
    unsigned cur;
    laz_dec d[L_P14];
    int on[L_P14]; /* the layer has bytes in this chunk */
} pt14;

static int ctx_create(ctx14 *c)
{
    memset(c, 0, sizeof *c);
    if (laz_ic_create(&c->dx, 32, 2) || laz_ic_create(&c->dy, 32, 22) ||
        laz_ic_create(&c->z, 32, 20) || laz_ic_create(&c->intensity, 16, 4) ||
        laz_ic_create(&c->scan, 16, 2) || laz_ic_create(&c->psid, 16, 1) ||
        laz_gps_create(&c->gps, 1))
        return -1;
    return 0;
}

static void ctx_free(ctx14 *c)
{
    for (int i = 0; i < 8; i++) laz_model_free(&c->changed[i]);
    laz_model_free(&c->channel);
    laz_model_free(&c->rgps_same);
    for (int i = 0; i < 16; i++) {
        laz_model_free(&c->nret[i]);
        laz_model_free(&c->rnum[i]);
    }
    for (int i = 0; i < 64; i++) {
        laz_model_free(&c->cls[i]);
        laz_model_free(&c->flags[i]);
        laz_model_free(&c->ud[i]);
    }
    laz_gps_free(&c->gps);
    laz_ic *ics[] = {&c->dx, &c->dy, &c->z, &c->intensity, &c->scan, &c->psid};
    for (size_t i = 0; i < sizeof ics / sizeof ics[0]; i++) laz_ic_free(ics[i]);
}

/* ctx_start: fresh models for context c, its predictions seeded from the point from. */
static int ctx_start(ctx14 *c, const p14 *from)
{
    for (int i = 0; i < 8; i++)
        if (laz_model_init(&c->changed[i], 128)) return -1;
    if (laz_model_init(&c->channel, 3) || laz_model_init(&c->rgps_same, 13) ||
        laz_gps_begin(&c->gps, from->gps))
        return -1;
    laz_ic *ics[] = {&c->dx, &c->dy, &c->z, &c->intensity, &c->scan, &c->psid};
    for (size_t i = 0; i < sizeof ics / sizeof ics[0]; i++)
        if (laz_ic_init(ics[i])) return -1;
    memset(c->nret_on, 0, sizeof c->nret_on);
    memset(c->rnum_on, 0, sizeof c->rnum_on);
    memset(c->cls_on, 0, sizeof c->cls_on);
    memset(c->flags_on, 0, sizeof c->flags_on);
    memset(c->ud_on, 0, sizeof c->ud_on);
    for (int i = 0; i < 12; i++) {
        laz_median5_init(&c->mx[i]);
        laz_median5_init(&c->my[i]);
    }
    for (int i = 0; i < 8; i++) {
        c->last_z[i] = from->z;
        c->last_int[i] = from->intensity;
    }
    c->last = *from;
    c->last.gps_change = 0;
    c->unused = 0;
    return 0;
}

static laz_model *lazy(laz_model *m, uint8_t *on, uint32_t n)
{
    if (!*on) {
        if (laz_model_init(m, n)) return NULL;
        *on = 1;
    }
    return m;
}

LAZ_CLONES static int pt14_read(pt14 *s, uint8_t *rec)
{
    ctx14 *c = &s->c[s->cur];
    p14 *L = &c->last;
    laz_dec dd = s->d[L_XY], *dxy = &dd; /* the coder in registers for the point's fields */
    unsigned lpr = (L->ret == 1) + (L->ret >= L->nret ? 2u : 0u) + (L->gps_change ? 4u : 0u);
    uint32_t changed = laz_decode_symbol_tab(dxy, &c->changed[lpr]);
    if (changed & 64) {
        unsigned ch = (s->cur + laz_decode_symbol(dxy, &c->channel) + 1) % 4;
        if (s->c[ch].unused && ctx_start(&s->c[ch], L)) goto nomem;
        s->cur = ch;
        c = &s->c[ch];
        L = &c->last;
        L->channel = (uint8_t)ch;
    }
    int psc = !!(changed & 32), gpsc = !!(changed & 16), sac = !!(changed & 8);
    unsigned last_n = L->nret, last_r = L->ret, n, r;
    if (changed & 4) {
        laz_model *m = lazy(&c->nret[last_n], &c->nret_on[last_n], 16);
        if (!m) goto nomem;
        n = laz_decode_symbol_tab(dxy, m);
        L->nret = (uint8_t)n;
    } else {
        n = last_n;
    }
    switch (changed & 3) {
    case 0: r = last_r; break;
    case 1: r = (last_r + 1) % 16; break;
    case 2: r = (last_r + 15) % 16; break;
    default:
        if (gpsc) {
            laz_model *m = lazy(&c->rnum[last_r], &c->rnum_on[last_r], 16);
            if (!m) goto nomem;
            r = laz_decode_symbol_tab(dxy, m);
        } else {
            r = (last_r + laz_decode_symbol_tab(dxy, &c->rgps_same) + 2) % 16;
        }
        break;
    }
    L->ret = (uint8_t)r;
    unsigned m = laz__return_map16[n][r], lv = level8(n, r);
    unsigned cpr = (r == 1) + (r >= n ? 2u : 0u);
    unsigned idx = (m << 1) | (unsigned)gpsc, one = n == 1;

    /* The layers are separate streams: the fields that need only the return counts decode
     * between x and y, so that their serial chains sit next to the x/y chain in the
     * instruction stream and overlap with it (z waits for x's and y's bit counts). */
    if (s->on[L_CLS]) {
        unsigned ccc = ((L->cls & 0x1Fu) << 1) + (cpr == 3);
        laz_model *md = lazy(&c->cls[ccc], &c->cls_on[ccc], 256);
        if (!md) goto nomem;
        L->cls = (uint8_t)laz_decode_symbol_tab(&s->d[L_CLS], md);
    }
    if (s->on[L_FLAGS]) {
        unsigned lf = (unsigned)L->edge << 5 | (unsigned)L->sdir << 4 | L->cflags;
        laz_model *md = lazy(&c->flags[lf], &c->flags_on[lf], 64);
        if (!md) goto nomem;
        uint32_t f = laz_decode_symbol_tab(&s->d[L_FLAGS], md);
        L->edge = (f >> 5) & 1;
        L->sdir = (f >> 4) & 1;
        L->cflags = f & 15;
    }
    int32_t diff = laz_ic_decompress(&c->dx, dxy, laz_median5_get(&c->mx[idx]), one);
    L->x = (int32_t)((uint32_t)L->x + (uint32_t)diff);
    laz_median5_add(&c->mx[idx], diff);
    unsigned kb = c->dx.k;
    if (s->on[L_INT]) {
        unsigned k = (cpr << 1) | (unsigned)gpsc;
        L->intensity = (uint16_t)laz_ic_decompress(&c->intensity, &s->d[L_INT], c->last_int[k],
                                                   cpr);
        c->last_int[k] = L->intensity;
    }
    if (s->on[L_UD]) {
        unsigned k = L->ud / 4u;
        laz_model *md = lazy(&c->ud[k], &c->ud_on[k], 256);
        if (!md) goto nomem;
        L->ud = (uint8_t)laz_decode_symbol_tab(&s->d[L_UD], md);
    }
    diff = laz_ic_decompress(&c->dy, dxy, laz_median5_get(&c->my[idx]),
                             one + (kb < 20 ? (kb & ~1u) : 20));
    L->y = (int32_t)((uint32_t)L->y + (uint32_t)diff);
    laz_median5_add(&c->my[idx], diff);
    s->d[L_XY] = dd;

    if (s->on[L_Z]) {
        kb = (c->dx.k + c->dy.k) / 2;
        L->z = laz_ic_decompress(&c->z, &s->d[L_Z], c->last_z[lv],
                                 one + (kb < 18 ? (kb & ~1u) : 18));
        c->last_z[lv] = L->z;
    }
    if (s->on[L_SCAN] && sac)
        L->scan_angle = (int16_t)(uint16_t)laz_ic_decompress(&c->scan, &s->d[L_SCAN],
                                                              L->scan_angle, (unsigned)gpsc);
    if (s->on[L_PSID] && psc)
        L->psid = (uint16_t)laz_ic_decompress(&c->psid, &s->d[L_PSID], L->psid, 0);
    if (s->on[L_GPS] && gpsc) {
        L->gps = laz_gps_read(&c->gps, &s->d[L_GPS]);
    }
    p14_pack(L, rec);
    L->gps_change = gpsc;
    return 0;
nomem:
    s->d[L_XY] = dd;
    return -1;
}

/* ---- RGB14 / RGBNIR14 / BYTE14: per-channel contexts following POINT14's channel ---- */

typedef struct ctxx {
    int unused, made;
    laz_model used, diff[6], nused, ndiff[2];
    laz_model *bytes;      /* BYTE14: one model per byte */
    uint8_t last[8];       /* RGB(NIR): 3 or 4 x u16 little-endian; BYTE14 uses lastb */
    uint8_t *lastb;
} ctxx;

typedef struct itemx {
    laz_item it;
    size_t off;
    ctxx c[4];
    unsigned cur;
    unsigned nlayers;      /* RGB14 1, RGBNIR14 2, BYTE14 size */
    laz_dec *d;            /* nlayers decoders */
    int *on;
} itemx;

struct laz_v3 {
    size_t npts;           /* the chunk's point count */
    unsigned n;
    size_t rec_len;
    pt14 *pt;
    itemx x[LAZ_MAX_ITEMS]; /* x[0] unused: the POINT14 item */
};

static int ctxx_start(itemx *x, ctxx *c, const uint8_t *from)
{
    if (!c->made && x->it.type == LAZ_ITEM_BYTE14) {
        c->bytes = calloc(x->it.size, sizeof *c->bytes);
        c->lastb = malloc(x->it.size);
        if (!c->bytes || !c->lastb) return -1;
    }
    c->made = 1;
    if (x->it.type == LAZ_ITEM_BYTE14) {
        for (unsigned k = 0; k < x->it.size; k++)
            if (laz_model_init(&c->bytes[k], 256)) return -1;
        memcpy(c->lastb, from, x->it.size);
    } else {
        if (laz__rgb_models_init(&c->used, c->diff)) return -1;
        if (x->it.type == LAZ_ITEM_RGBNIR14 &&
            (laz_model_init(&c->nused, 4) || laz_model_init(&c->ndiff[0], 256) ||
             laz_model_init(&c->ndiff[1], 256)))
            return -1;
        memcpy(c->last, from, x->it.type == LAZ_ITEM_RGBNIR14 ? 8 : 6);
    }
    c->unused = 0;
    return 0;
}

static void ctxx_free(itemx *x, ctxx *c)
{
    laz_model_free(&c->used);
    for (int i = 0; i < 6; i++) laz_model_free(&c->diff[i]);
    laz_model_free(&c->nused);
    laz_model_free(&c->ndiff[0]);
    laz_model_free(&c->ndiff[1]);
    if (c->bytes)
        for (unsigned k = 0; k < x->it.size; k++) laz_model_free(&c->bytes[k]);
    free(c->bytes);
    free(c->lastb);
}

LAZ_CLONES static int itemx_read(itemx *x, unsigned context, uint8_t *item)
{
    /* As LASzip: the previous context's last item stands in for one point when switching to
     * a context already used in this chunk. */
    ctxx *c = &x->c[x->cur];
    uint8_t *last = x->it.type == LAZ_ITEM_BYTE14 ? c->lastb : c->last;
    if (x->cur != context) {
        x->cur = context;
        if (x->c[context].unused) {
            if (ctxx_start(x, &x->c[context], last)) return -1;
            last = x->it.type == LAZ_ITEM_BYTE14 ? x->c[context].lastb : x->c[context].last;
        }
    }
    c = &x->c[x->cur];
    if (x->it.type == LAZ_ITEM_BYTE14) {
        for (unsigned k = 0; k < x->it.size; k++) {
            if (x->on[k]) {
                uint32_t v = laz_decode_symbol_tab(&x->d[k], &c->bytes[k]);
                item[k] = last[k] = laz_u8_fold((int32_t)v + last[k]);
            } else {
                item[k] = last[k];
            }
        }
        return 0;
    }
    if (x->on[0]) {
        uint16_t lc[3], col[3];
        for (int k = 0; k < 3; k++) lc[k] = get16(last + 2 * k);
        laz__rgb_decode(&x->d[0], &c->used, c->diff, lc, col);
        for (int k = 0; k < 3; k++) put16(item + 2 * k, col[k]);
        memcpy(last, item, 6);
    } else {
        memcpy(item, last, 6);
    }
    if (x->it.type == LAZ_ITEM_RGBNIR14) {
        if (x->on[1]) {
            laz_dec *d = &x->d[1];
            uint32_t sym = laz_decode_symbol(d, &c->nused);
            uint32_t lo = last[6], hi = last[7];
            if (sym & 1) lo = laz_u8_fold((int32_t)laz_decode_symbol_tab(d, &c->ndiff[0]) + (int32_t)lo);
            if (sym & 2) hi = laz_u8_fold((int32_t)laz_decode_symbol_tab(d, &c->ndiff[1]) + (int32_t)hi);
            item[6] = last[6] = (uint8_t)lo;
            item[7] = last[7] = (uint8_t)hi;
        } else {
            item[6] = last[6];
            item[7] = last[7];
        }
    }
    return 0;
}

void laz__v3_free(laz_v3 *s)
{
    if (!s) return;
    if (s->pt)
        for (int i = 0; i < 4; i++)
            if (s->pt->created[i]) ctx_free(&s->pt->c[i]);
    free(s->pt);
    for (unsigned i = 1; i < s->n; i++) {
        for (int k = 0; k < 4; k++) ctxx_free(&s->x[i], &s->x[i].c[k]);
        free(s->x[i].d);
        free(s->x[i].on);
    }
    free(s);
}

laz_v3 *laz__v3_create(const laz_item *items, unsigned nitems)
{
    laz_v3 *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->n = nitems;
    s->pt = calloc(1, sizeof *s->pt);
    if (!s->pt) goto fail;
    for (int i = 0; i < 4; i++) {
        s->pt->created[i] = 1;
        if (ctx_create(&s->pt->c[i])) goto fail;
    }
    s->rec_len = items[0].size;
    for (unsigned i = 1; i < nitems; i++) {
        itemx *x = &s->x[i];
        x->it = items[i];
        x->off = s->rec_len;
        s->rec_len += items[i].size;
        x->nlayers = items[i].type == LAZ_ITEM_RGB14 ? 1 : items[i].type == LAZ_ITEM_RGBNIR14
                                                               ? 2 : items[i].size;
        x->d = calloc(x->nlayers, sizeof *x->d);
        x->on = calloc(x->nlayers, sizeof *x->on);
        if (!x->d || !x->on) goto fail;
    }
    return s;
fail:
    laz__v3_free(s);
    return NULL;
}

static uint32_t rd32(const uint8_t *p) { return get32(p); }

int laz__v3_begin(laz_v3 *s, const uint8_t *p, const uint8_t *end, size_t npts, uint8_t *out,
                  const char **what)
{
    *what = "points";
    size_t nsizes = L_P14;
    for (unsigned i = 1; i < s->n; i++) nsizes += s->x[i].nlayers;
    if ((size_t)(end - p) < s->rec_len + 4 + 4 * nsizes) return LAZ_CHUNK_SHORT;
    memcpy(out, p, s->rec_len);
    p += s->rec_len;
    if (rd32(p) != npts) return LAZ_CHUNK_COUNT;
    p += 4;
    /* the layer sizes, then the layers in the same order */
    const uint8_t *sz = p;
    p += 4 * nsizes;
    pt14 *pt = s->pt;
    for (int l = 0; l < L_P14; l++) {
        uint32_t b = rd32(sz + 4 * l);
        if (b > (size_t)(end - p)) {
            *what = layer_names[l];
            return LAZ_CHUNK_LAYERS;
        }
        pt->on[l] = b > 0;
        if (b) laz_dec_init(&pt->d[l], p, p + b);
        p += b;
    }
    sz += 4 * L_P14;
    for (unsigned i = 1; i < s->n; i++) {
        itemx *x = &s->x[i];
        for (unsigned l = 0; l < x->nlayers; l++, sz += 4) {
            uint32_t b = rd32(sz);
            if (b > (size_t)(end - p)) {
                *what = x->it.type == LAZ_ITEM_BYTE14 ? "extra bytes" : "rgb/nir";
                return LAZ_CHUNK_LAYERS;
            }
            x->on[l] = b > 0;
            if (b) laz_dec_init(&x->d[l], p, p + b);
            p += b;
        }
    }
    /* start every item's context from the raw first point */
    p14 first;
    p14_unpack(&first, out);
    for (int c = 0; c < 4; c++) pt->c[c].unused = 1;
    pt->cur = first.channel;
    if (ctx_start(&pt->c[pt->cur], &first)) return LAZ_CHUNK_NOMEM;
    for (unsigned i = 1; i < s->n; i++) {
        itemx *x = &s->x[i];
        for (int c = 0; c < 4; c++) x->c[c].unused = 1;
        x->cur = pt->cur;
        if (ctxx_start(x, &x->c[x->cur], out + x->off)) return LAZ_CHUNK_NOMEM;
    }
    s->npts = npts;
    return 0;
}

LAZ_CLONES int laz__v3_next(laz_v3 *s, size_t npts, uint8_t *out, const char **what)
{
    pt14 *pt = s->pt;
    *what = "points";
    if (s->npts > 1 && !pt->on[L_XY]) {
        *what = layer_names[L_XY];
        return LAZ_CHUNK_SHORT;
    }
    for (size_t j = 0; j < npts; j++) {
        uint8_t *rec = out + j * s->rec_len;
        if (pt14_read(pt, rec)) return LAZ_CHUNK_NOMEM;
        for (unsigned i = 1; i < s->n; i++)
            if (itemx_read(&s->x[i], pt->cur, rec + s->x[i].off)) return LAZ_CHUNK_NOMEM;
    }
    for (int l = 0; l < L_P14; l++)
        if (pt->on[l] && pt->d[l].overrun) {
            *what = layer_names[l];
            return LAZ_CHUNK_SHORT;
        }
    for (unsigned i = 1; i < s->n; i++)
        for (unsigned l = 0; l < s->x[i].nlayers; l++)
            if (s->x[i].on[l] && s->x[i].d[l].overrun) {
                *what = s->x[i].it.type == LAZ_ITEM_BYTE14 ? "extra bytes" : "rgb/nir";
                return LAZ_CHUNK_SHORT;
            }
    return 0;
}
