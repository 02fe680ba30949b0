/* laz_chunk.h — decoding one LAZ chunk into uncompressed LAS point records.
 *
 * A chunk starts with its first point stored raw; the rest is arithmetic-coded. Two layouts:
 *   - pointwise (LASzip compressor 2, items POINT10/GPSTIME11/RGB12/BYTE version 2, point
 *     formats 0-5): one coded stream, each point's items decoded in the record's order;
 *   - layered (compressor 3, items POINT14/RGB14/RGBNIR14/BYTE14 version 3, formats 6-10):
 *     after the raw point a u32 point count and one u32 byte size per layer, then the layers,
 *     each its own coded stream, so a field can be decoded without the others.
 * A decoder object holds the models of one item list; one per thread, reused across chunks. */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* LASzip item types (the laszip VLR lists them in record order). */
enum {
    LAZ_ITEM_BYTE = 0,
    LAZ_ITEM_POINT10 = 6,
    LAZ_ITEM_GPSTIME11 = 7,
    LAZ_ITEM_RGB12 = 8,
    LAZ_ITEM_WAVEPACKET13 = 9,
    LAZ_ITEM_POINT14 = 10,
    LAZ_ITEM_RGB14 = 11,
    LAZ_ITEM_RGBNIR14 = 12,
    LAZ_ITEM_WAVEPACKET14 = 13,
    LAZ_ITEM_BYTE14 = 14,
};

typedef struct laz_item {
    uint16_t type, size, version;
} laz_item;

#define LAZ_MAX_ITEMS 8

/* Chunk decode results besides 0. */
enum {
    LAZ_CHUNK_NOMEM = -1,
    LAZ_CHUNK_SHORT = -2,    /* the chunk's bytes end before its points do */
    LAZ_CHUNK_COUNT = -3,    /* a layered chunk stores a point count other than expected */
    LAZ_CHUNK_LAYERS = -4,   /* layered chunk: the layer sizes exceed the chunk's bytes */
};

typedef struct laz_chunk_dec laz_chunk_dec;

/* laz_chunk_dec_create: a decoder for items (checked by the caller: laz_items_check).
 * Returns NULL when out of memory. */
laz_chunk_dec *laz_chunk_dec_create(const laz_item *items, unsigned nitems);
void laz_chunk_dec_free(laz_chunk_dec *cd);

/* laz_chunk_begin: starts the chunk of npts >= 1 points in [p, end): writes its first point
 * (stored raw) to first, one record of rec_len bytes (the sum of the item sizes), and sets up
 * the models. laz_chunk_next: decodes the next npts points into out. Both return 0 or a
 * LAZ_CHUNK_* code; on failure *what says which part (a layer name or "points") ran short.
 * Decoding in steps keeps what a reader allocates proportional to the points it really got. */
int laz_chunk_begin(laz_chunk_dec *cd, const uint8_t *p, const uint8_t *end, size_t npts,
                    uint8_t *first, const char **what);
int laz_chunk_next(laz_chunk_dec *cd, size_t npts, uint8_t *out, const char **what);

/* laz_items_check: 0 when this decoder handles the item list (pointwise v2 or layered v3 items
 * in a valid order); otherwise -1 with *why naming the first item it cannot handle. */
int laz_items_check(const laz_item *items, unsigned nitems, unsigned compressor,
                    const char **why);
