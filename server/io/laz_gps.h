/* laz_gps.h — LASzip's GPS time coder, shared by GPSTIME11 v2 (laz_v2.c) and the time layer of
 * POINT14 v3 (laz_v3.c).
 *
 * The time is predicted as the last time plus a multiple of the last difference: a symbol says
 * which multiple (1 to 499, 500, or -1 to -10 relative), "code the difference fresh", "full
 * 64-bit time follows" or "switch to sequence k" of four remembered time sequences (for
 * interleaved flight lines). Version 3 dropped version 2's "unchanged" symbols (the point's
 * change mask says that), so its symbols sit one lower. */
#pragma once
#include <stdint.h>

#include "laz_arith.h"

typedef struct laz_gps {
    int v3;                /* symbol numbering of version 3 */
    laz_model multi, zdiff;
    laz_ic ic;             /* 32 bits, 9 contexts */
    unsigned last, next;
    uint64_t t[4];         /* the four sequences' last times (bit patterns of doubles) */
    int32_t diff[4], extreme[4];
} laz_gps;

/* laz_gps_create: returns 0 or -1 (out of memory). */
int laz_gps_create(laz_gps *g, int v3);
void laz_gps_free(laz_gps *g);
/* laz_gps_begin: fresh models, sequence 0 starting at first. Returns 0 or -1. */
int laz_gps_begin(laz_gps *g, uint64_t first);
/* laz_gps_read: decodes the next time; returns its bit pattern. */
uint64_t laz_gps_read(laz_gps *g, laz_dec *d);
