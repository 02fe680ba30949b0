/* laz_items.h — the two chunk layouts behind laz_chunk.h: pointwise version-2 items (laz_v2.c)
 * and layered version-3 items (laz_v3.c). Internal to the LAZ reader. */
#pragma once
#include "laz_arith.h"
#include "laz_chunk.h"

typedef struct laz_v2 laz_v2;
laz_v2 *laz__v2_create(const laz_item *items, unsigned nitems);
void laz__v2_free(laz_v2 *s);
int laz__v2_begin(laz_v2 *s, const uint8_t *p, const uint8_t *end, uint8_t *first,
                  const char **what);
int laz__v2_next(laz_v2 *s, size_t npts, uint8_t *out, const char **what);

typedef struct laz_v3 laz_v3;
laz_v3 *laz__v3_create(const laz_item *items, unsigned nitems);
void laz__v3_free(laz_v3 *s);
int laz__v3_begin(laz_v3 *s, const uint8_t *p, const uint8_t *end, size_t npts, uint8_t *first,
                  const char **what);
int laz__v3_next(laz_v3 *s, size_t npts, uint8_t *out, const char **what);

/* Return-number context tables of LASzip (number of returns n, return number r). */
extern const uint8_t laz__return_map8[8][8];
extern const uint8_t laz__return_map16[16][16];

/* laz__rgb_models_init: fresh models of the RGB coder (used: 128 symbols, diff[6]: 256). */
int laz__rgb_models_init(laz_model *used, laz_model *diff);
/* laz__rgb_decode: one colour (3 x u16) into c, coded against last (RGB12 v2 = RGB14 v3). */
void laz__rgb_decode(laz_dec *d, laz_model *used, laz_model *diff, const uint16_t *last,
                     uint16_t *c);
