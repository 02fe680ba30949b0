/* laz_gps.c — the GPS time coder of LAZ (laz_gps.h). */
#include "laz_gps.h"

#include <string.h>

#define MULTI 500
#define MULTI_MINUS (-10)
/* version 2: 511 "unchanged", 512 "full", 513-515 "switch"; version 3: 511 "full", 512-514 */
#define V2_UNCHANGED (MULTI - MULTI_MINUS + 1)

int laz_gps_create(laz_gps *g, int v3)
{
    memset(g, 0, sizeof *g);
    g->v3 = v3;
    return laz_ic_create(&g->ic, 32, 9);
}

void laz_gps_free(laz_gps *g)
{
    laz_model_free(&g->multi);
    laz_model_free(&g->zdiff);
    laz_ic_free(&g->ic);
}

int laz_gps_begin(laz_gps *g, uint64_t first)
{
    unsigned total = MULTI - MULTI_MINUS + (g->v3 ? 5 : 6);
    if (laz_model_init(&g->multi, total) || laz_model_init(&g->zdiff, g->v3 ? 5 : 6) ||
        laz_ic_init(&g->ic))
        return -1;
    g->last = g->next = 0;
    for (int i = 0; i < 4; i++) g->diff[i] = g->extreme[i] = 0, g->t[i] = 0;
    g->t[0] = first;
    return 0;
}

/* The multiplied prediction wraps like LASzip's 32-bit product. */
static inline int32_t mul32(int32_t a, int32_t b) { return (int32_t)((uint32_t)a * (uint32_t)b); }

/* extreme: after more than three differences far from the prediction, adopt the latest. */
static inline __attribute__((always_inline)) void extreme(laz_gps *g, int32_t diff)
{
    if (++g->extreme[g->last] > 3) {
        g->diff[g->last] = diff;
        g->extreme[g->last] = 0;
    }
}

/* full: a new sequence whose time is coded whole (high 32 bits predicted, low raw). */
static inline __attribute__((always_inline)) void full(laz_gps *g, laz_dec *d)
{
    g->next = (g->next + 1) & 3;
    uint64_t hi = (uint32_t)laz_ic_decompress(&g->ic, d, (int32_t)(g->t[g->last] >> 32), 8);
    g->t[g->next] = (hi << 32) | laz_read_int(d);
    g->last = g->next;
    g->diff[g->last] = 0;
    g->extreme[g->last] = 0;
}

LAZ_CLONES uint64_t laz_gps_read(laz_gps *g, laz_dec *dp)
{
    laz_dec dd = *dp, *d = &dd;
    /* v = the version-2 symbol; version 3 codes v - 1 (it has no "unchanged" 0 / 511) */
    const uint32_t sh = g->v3 ? 1 : 0, code_full = MULTI - MULTI_MINUS + 2 - sh;
    /* a sequence switch re-reads with the new sequence (LASzip recurses); at most a few */
    for (int guard = 0; guard < 64; guard++) {
        unsigned L = g->last;
        if (g->diff[L] == 0) {
            uint32_t v = laz_decode_symbol_tab(d, &g->zdiff) + sh;
            if (v == 1) {
                g->diff[L] = laz_ic_decompress(&g->ic, d, 0, 0);
                g->t[L] += (uint64_t)(int64_t)g->diff[L];
                g->extreme[L] = 0;
            } else if (v == 2) {
                full(g, d);
            } else if (v > 2) {
                g->last = (L + v - 2) & 3;
                continue;
            }
            break;
        }
        uint32_t m = laz_decode_symbol_tab16(d, &g->multi); /* over 256 symbols */
        if (m == 1) {
            g->t[L] += (uint64_t)(int64_t)laz_ic_decompress(&g->ic, d, g->diff[L], 1);
            g->extreme[L] = 0;
        } else if (m < code_full && !(sh == 0 && m == V2_UNCHANGED)) {
            int32_t diff;
            if (m == 0) {
                diff = laz_ic_decompress(&g->ic, d, 0, 7);
                extreme(g, diff);
            } else if (m < MULTI) {
                diff = laz_ic_decompress(&g->ic, d, mul32((int32_t)m, g->diff[L]),
                                         m < 10 ? 2 : 3);
            } else if (m == MULTI) {
                diff = laz_ic_decompress(&g->ic, d, mul32(MULTI, g->diff[L]), 4);
                extreme(g, diff);
            } else {
                int32_t mm = MULTI - (int32_t)m;
                if (mm > MULTI_MINUS) {
                    diff = laz_ic_decompress(&g->ic, d, mul32(mm, g->diff[L]), 5);
                } else {
                    diff = laz_ic_decompress(&g->ic, d, mul32(MULTI_MINUS, g->diff[L]), 6);
                    extreme(g, diff);
                }
            }
            g->t[L] += (uint64_t)(int64_t)diff;
        } else if (m == code_full) {
            full(g, d);
        } else if (m > code_full) {
            g->last = (L + m - code_full) & 3;
            continue;
        }
        break;
    }
    *dp = dd;
    return g->t[g->last];
}
