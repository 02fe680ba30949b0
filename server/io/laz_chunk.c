/* laz_chunk.c — picks the chunk layout for an item list and checks the list (laz_chunk.h). */
#include "laz_chunk.h"

#include "laz_items.h"

#include <stdlib.h>

struct laz_chunk_dec {
    laz_v2 *v2; /* exactly one of the two */
    laz_v3 *v3;
};

int laz_items_check(const laz_item *items, unsigned nitems, unsigned compressor,
                    const char **why)
{
    if (nitems == 0 || nitems > LAZ_MAX_ITEMS) {
        *why = "an item count outside 1..8";
        return -1;
    }
    for (unsigned i = 0; i < nitems; i++) {
        const laz_item *it = &items[i];
        if (it->type == LAZ_ITEM_WAVEPACKET13 || it->type == LAZ_ITEM_WAVEPACKET14) {
            *why = "waveform packets (point formats 4, 5, 9, 10) are not supported";
            return -1;
        }
        if (compressor == 2) {
            int ok = (it->type == LAZ_ITEM_POINT10 && it->size == 20 && i == 0) ||
                     (it->type == LAZ_ITEM_GPSTIME11 && it->size == 8) ||
                     (it->type == LAZ_ITEM_RGB12 && it->size == 6) ||
                     (it->type == LAZ_ITEM_BYTE && it->size > 0);
            if (!ok || it->version != 2) {
                *why = "an item other than POINT10/GPSTIME11/RGB12/BYTE version 2 in a "
                       "pointwise-chunked file (only version 2 items are supported)";
                return -1;
            }
        } else if (compressor == 3) {
            int ok = (it->type == LAZ_ITEM_POINT14 && it->size == 30 && i == 0) ||
                     (it->type == LAZ_ITEM_RGB14 && it->size == 6) ||
                     (it->type == LAZ_ITEM_RGBNIR14 && it->size == 8) ||
                     (it->type == LAZ_ITEM_BYTE14 && it->size > 0);
            if (!ok || it->version != 3) {
                *why = "an item other than POINT14/RGB14/RGBNIR14/BYTE14 version 3 in a "
                       "layered-chunked file (version 4, LASzip's variant with its own context "
                       "switch rule, is not supported: no test file)";
                return -1;
            }
        } else {
            *why = "a compressor other than 2 (pointwise chunked) or 3 (layered chunked)";
            return -1;
        }
    }
    return 0;
}

laz_chunk_dec *laz_chunk_dec_create(const laz_item *items, unsigned nitems)
{
    laz_chunk_dec *cd = calloc(1, sizeof *cd);
    if (!cd) return NULL;
    if (items[0].type == LAZ_ITEM_POINT14) cd->v3 = laz__v3_create(items, nitems);
    else cd->v2 = laz__v2_create(items, nitems);
    if (!cd->v2 && !cd->v3) {
        free(cd);
        return NULL;
    }
    return cd;
}

void laz_chunk_dec_free(laz_chunk_dec *cd)
{
    if (!cd) return;
    laz__v2_free(cd->v2);
    laz__v3_free(cd->v3);
    free(cd);
}

int laz_chunk_begin(laz_chunk_dec *cd, const uint8_t *p, const uint8_t *end, size_t npts,
                    uint8_t *first, const char **what)
{
    return cd->v3 ? laz__v3_begin(cd->v3, p, end, npts, first, what)
                  : laz__v2_begin(cd->v2, p, end, first, what);
}

int laz_chunk_next(laz_chunk_dec *cd, size_t npts, uint8_t *out, const char **what)
{
    return cd->v3 ? laz__v3_next(cd->v3, npts, out, what) : laz__v2_next(cd->v2, npts, out, what);
}
