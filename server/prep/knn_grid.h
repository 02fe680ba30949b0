/* knn_grid.h — internal interface between knn.c and knn_grid.c (the Morton-cell search). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "knn.h"

typedef struct prep__grid prep__grid;
typedef struct prep__grid_scratch prep__grid_scratch;

/* prep__grid_build: sorts (a copy of the order of) the n points by Morton code and splits the
 * octree into leaves of at most leaf_size points. frame and codes: see prep_knn_opts (NULL:
 * the points' bounding cube; codes computed here). simd: prep_knn_opts.simd. Returns 0 or
 * SD_ENOMEM. */
int prep__grid_build(const float *pos, size_t n, int leaf_size, const prep_morton_frame *frame,
                     const uint64_t *codes, int simd, prep__grid **out, sd_err *err);
void prep__grid_free(prep__grid *g);

prep__grid_scratch *prep__grid_scratch_new(void);
void prep__grid_scratch_free(prep__grid_scratch *s);
void prep__grid_counters(const prep__grid_scratch *s, prep_knn_counters *c);

/* prep__grid_query: see prep_knn_query. */
int prep__grid_query(const prep__grid *g, const uint32_t *qidx, size_t first, size_t nq, int k,
                     uint32_t *idx, float *d2, prep__grid_scratch *s, sd_err *err);

/* prep__knn_sort_pairs: sorts m (d2, idx) pairs ascending by d2, then idx (insertion sort:
 * m is small and the input is often nearly sorted). */
void prep__knn_sort_pairs(float *d2, uint32_t *idx, int m);
