/* prepared.h — a preprocessed cloud: the layout the renderer uploads and cache.c stores.
 *
 * Points are in Morton (Z-order) order and grouped into batches of consecutive points with
 * bounding boxes (frustum culling now, level of detail later). Every array lives in one block,
 * each section 64-byte aligned, in the order below; that block is written to the cache file
 * verbatim and mmapped back, so a cached load copies nothing. Arrays are read-only once built. */
#pragma once
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "cloud.h"

typedef struct pc_batch {
    uint32_t first, count;   /* points [first, first + count) */
    float bmin[3], bmax[3];  /* bounds of those points (local, re-centred coordinates) */
} pc_batch;                  /* 32 bytes, stored verbatim */

enum { PC_BATCH_POINTS = 4096 }; /* target points per batch */

typedef struct pc_prep_stats {
    double t_knn_build, t_knn_query, t_normals, t_radius, t_field, t_reorder; /* seconds */
} pc_prep_stats;

typedef struct pc_prepared {
    uint64_t n;
    uint32_t attrs;          /* PC_ATTR_*: always NORMAL | RADIUS | F, plus what the file had */
    uint32_t k;              /* neighbours used */
    /* sections (NULL when absent); their order in the block is prepared.c's */
    float *pos;              /* 3n, local coordinates (file coordinates - offset) */
    PC_ATTR_ARRAYS           /* cloud.h's table: normal (3n, unit) and radius (n, eq. 20 as
                                DESIGN.md interprets it) always; rgba (4n), intensity, cls,
                                scalar (n) when attrs says so */
    float *F;                /* n, uncertainty eq. 21 normalised to [0,1] */
    pc_batch *batches;       /* nbatches */
    uint64_t nbatches;
    /* summary */
    double offset[3], bmin[3], bmax[3]; /* file coordinates */
    float sigma;             /* median nearest-neighbour distance */
    float F_raw_p99;         /* the 99th percentile of raw F used to normalise */
    float F_pct[5];          /* normalised F at the 1st, 25th, 50th, 75th, 99th percentiles */
    float radius_median;
    uint64_t n_dropped;
    char format[64];
    char scalar_name[32];
    int has_sensor_q;        /* the file gave the sensor's rotation (PCD VIEWPOINT) */
    double sensor_q[4];      /* that rotation, w x y z: the default view looks as the sensor */
    pc_prep_stats stats;
    /* storage: exactly one of heap or map is set */
    void *block;             /* the arrays' block (inside heap or map) */
    uint64_t block_len;
    void *heap;
    void *map;               /* a cache file's guarded mapping (file), or NULL */
    size_t map_len;
    struct cf_map *file;     /* cachefile.h: owns map; says whether the file changed */
} pc_prepared;

/* The summary values both cache kinds store (cache.c, lod_file.c), copied between their header
 * meta and the loaded cloud by PC_SUMMARY_COPY: any two structs with these fields. */
typedef struct pc_summary {
    double offset[3], bmin[3], bmax[3];
    float sigma, F_raw_p99, F_pct[5], radius_median;
    uint64_t n_dropped;
    char format[64];
    double sensor_q[4];      /* the sensor's rotation, w x y z (view.h), when has_sensor_q */
    uint64_t has_sensor_q;
} pc_summary;
#define PC_SUMMARY_COPY(dst, src)                                     \
    do {                                                              \
        memcpy((dst)->offset, (src)->offset, sizeof (dst)->offset);   \
        memcpy((dst)->bmin, (src)->bmin, sizeof (dst)->bmin);         \
        memcpy((dst)->bmax, (src)->bmax, sizeof (dst)->bmax);         \
        (dst)->sigma = (src)->sigma;                                  \
        (dst)->F_raw_p99 = (src)->F_raw_p99;                          \
        memcpy((dst)->F_pct, (src)->F_pct, sizeof (dst)->F_pct);      \
        (dst)->radius_median = (src)->radius_median;                  \
        (dst)->n_dropped = (src)->n_dropped;                          \
        memcpy((dst)->format, (src)->format, sizeof (dst)->format);   \
        (dst)->format[sizeof (dst)->format - 1] = 0;                  \
        memcpy((dst)->sensor_q, (src)->sensor_q, sizeof (dst)->sensor_q); \
        (dst)->has_sensor_q = (src)->has_sensor_q != 0;               \
    } while (0)

/* pc_prepared_block_len: bytes of the array block for n points, attrs and nbatches. */
uint64_t pc_prepared_block_len(uint64_t n, uint32_t attrs, uint64_t nbatches);

/* pc_prepared_bind: points every section pointer of p into block (p->n, p->attrs and
 * p->nbatches must be set). */
void pc_prepared_bind(pc_prepared *p, void *block);

/* pc_prepared_alloc: allocates a zeroed heap block for p->n, p->attrs, p->nbatches and binds it.
 * Returns 0 or SD_ENOMEM. */
int pc_prepared_alloc(pc_prepared *p, sd_err *err);

/* pc_prepared_make_batches: cuts p's n points into p->nbatches batches of `per` consecutive
 * points (the last one shorter; nbatches must be ceil(n / per)) and sets each batch's bounds
 * from pos. */
void pc_prepared_make_batches(pc_prepared *p, uint32_t per);

/* pc_prepared_check: 0 when every read of p's arrays so far saw what was loaded; SD_ESTALE with
 * err naming the cache file when p is mapped from a cache file that became shorter under the
 * reader (those reads gave zeros: what was made of them must be thrown away). Call it after
 * reading p's arrays (an upload). */
int pc_prepared_check(const pc_prepared *p, sd_err *err);

/* pc_prepared_free: releases the heap block or the mapping; safe to call twice. */
void pc_prepared_free(pc_prepared *p);
