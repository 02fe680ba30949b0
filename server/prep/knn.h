/* knn.h — exact k nearest neighbours of the points of a cloud, among the cloud's own points.
 *
 * Two interchangeable methods behind one interface:
 *  - PREP_KNN_GRID (default): the octree cells implied by Morton order (knn_grid.c). Points are
 *    sorted by Morton code; each query scans a 3x3x3 block of cells around it by brute force
 *    and grows the block until the k-th distance is below the distance to the block's faces,
 *    so the result is exact. Queries issued in Morton order share their candidate blocks and
 *    predict each other's cell size; that is what makes it fast (prep queries in Morton order:
 *    ~2x less CPU than FLANN). In an arbitrary query order every query gathers its own block
 *    and FLANN is the faster choice (1M points: 13.8 against 9.1 CPU seconds).
 *  - PREP_KNN_FLANN: FLANN's single kd-tree (C API, FLANN_INDEX_KDTREE_SINGLE, unlimited
 *    checks: exact), the reference the grid is tested against.
 * Both return, for each query point, its k nearest OTHER points (the query itself is excluded by
 * index; duplicates of it at distance 0 are neighbours), sorted by (squared distance, index), so
 * both methods give identical lists except where distinct points tie at the k-th distance. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "morton.h"
#include "sd_err.h"

typedef enum prep_knn_method {
    PREP_KNN_GRID = 0,  /* Morton-cell search (default, fastest) */
    PREP_KNN_FLANN = 1, /* FLANN KDTREE_SINGLE, exact */
} prep_knn_method;

typedef struct prep_knn_opts {
    prep_knn_method method; /* default PREP_KNN_GRID */
    int leaf_size;          /* default: grid 32 points per leaf cell, FLANN leaf_max_size 10 */
    int flann_cores;        /* default 1: FLANN's own OpenMP threads per query call. prep runs
                               its own threads with 1 each instead: measured faster (1M points,
                               2 cores: 3.1 s against 5.3 s with cores = 2, bench_prep.sh) */
    /* Grid only, both optional. frame: the Morton cube to index in (default: the points' own
     * bounding cube); it must contain every point. codes: the points' codes in that frame
     * (prep_morton_code), read until prep_knn_free; when they are non-decreasing the points are
     * taken as already in Morton order and neither coded nor sorted again (a prepared cloud, or
     * a region of one loaded in order: queries then run in the index's own order). Results do
     * not depend on either. */
    const prep_morton_frame *frame;
    const uint64_t *codes;
    /* Grid only: the widest vector path the search may use (PREP_KNN_SIMD_*; 0 = the best the
     * CPU has). Every path gives the same bits; tests pin each one to compare them. */
    int simd;
} prep_knn_opts;

enum {
    PREP_KNN_SIMD_BEST = 0,
    PREP_KNN_SIMD_PORTABLE = 1, /* GCC vector extensions (target clones), scalar packing */
    PREP_KNN_SIMD_AVX2 = 2,     /* + AVX2 packing */
    PREP_KNN_SIMD_AVX512 = 3,   /* + AVX-512 distances, packing (vcompress) and ranking */
};

typedef struct prep_knn prep_knn;                 /* an index over one point set */
typedef struct prep_knn_scratch prep_knn_scratch; /* query memory, one per thread */

/* prep_knn_build: indexes the n points pos (3 floats each; must stay valid and unchanged until
 * prep_knn_free). n must be below 2^32 - 1. opts may be NULL (defaults). Returns 0 and *out, or
 * SD_ENOMEM / SD_EINVAL / SD_ELIMIT with err filled. */
int prep_knn_build(const float *pos, size_t n, const prep_knn_opts *opts, prep_knn **out,
                   sd_err *err);

/* prep_knn_free: releases an index; NULL is fine. */
void prep_knn_free(prep_knn *kn);

/* prep_knn_scratch_new: per-thread query memory (NULL when out of memory). */
prep_knn_scratch *prep_knn_scratch_new(void);
void prep_knn_scratch_free(prep_knn_scratch *s);

/* prep_knn_query: for the nq query points with dataset indices qidx[0..nq) (or first + i when
 * qidx is NULL) writes their k nearest other points to idx[i * k + j], ascending, and the
 * squared distances to d2[i * k + j] (d2 may be NULL). 1 <= k <= n - 1. Safe to call from
 * several threads at once on one index, each with its own scratch. Returns 0 or SD_ENOMEM. */
int prep_knn_query(const prep_knn *kn, const uint32_t *qidx, size_t first, size_t nq, int k,
                   uint32_t *idx, float *d2, prep_knn_scratch *s, sd_err *err);

/* prep_knn_method_name: "grid" or "flann". */
const char *prep_knn_method_name(prep_knn_method m);

/* prep_knn_scratch_counters: the grid search's work (diagnostics for the bench); zeros for
 * FLANN. Counts accumulate in the scratch over its lifetime. */
typedef struct prep_knn_counters {
    uint64_t queries;    /* queries answered */
    uint64_t widened;    /* blocks that were not enough and had to grow */
    uint64_t dense;      /* queries that started below a too-big leaf block */
    uint64_t candidates; /* points whose distance was computed, summed */
    uint64_t filtered;   /* keys sorted after the radius filter, summed */
    uint64_t gathers;    /* candidate blocks gathered (not found in the scratch's cache) */
} prep_knn_counters;
void prep_knn_scratch_counters(const prep_knn_scratch *s, prep_knn_counters *c);
