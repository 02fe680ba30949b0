/* morton.h — Morton (Z-order) codes over a cloud's bounding cube and the radix sort that puts a
 * cloud into that order.
 *
 * A code interleaves 21 bits per axis (63 bits, x in bit 0, y in bit 1, z in bit 2, ...), so the
 * points of every octree cell at every level 0..21 are consecutive once sorted. prep.c uses the
 * order for batches and cache locality; knn_grid.c uses the cells for its neighbour search. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

enum { PREP_MORTON_BITS = 21 }; /* bits per axis; level L cells hold codes sharing the top 3L bits */

/* The cube the codes are taken over: cell indices at the finest level are
 * floor((p - origin) * inv_cell), clamped to [0, 2^21 - 1]. */
typedef struct prep_morton_frame {
    double origin[3];  /* the cube's lowest corner (local coordinates) */
    double side;       /* the cube's edge length (> 0) */
    double inv_cell;   /* 2^21 / side */
} prep_morton_frame;

/* prep_morton_frame_of: the bounding cube of the n points pos (3 floats each), slightly enlarged
 * so every point lies strictly inside. n may be 0 (a unit cube at the origin). */
void prep_morton_frame_of(const float *pos, size_t n, prep_morton_frame *f);

/* prep_morton_encode: the 63-bit code of the finest-level cell indices (each < 2^21). */
uint64_t prep_morton_encode(uint32_t x, uint32_t y, uint32_t z);

/* prep_morton_decode: the inverse of prep_morton_encode for the low 3 * bits bits of code. */
void prep_morton_decode(uint64_t code, uint32_t *x, uint32_t *y, uint32_t *z);

/* prep_morton_code: the code of one point in frame f. */
uint64_t prep_morton_code(const prep_morton_frame *f, const float p[3]);

/* prep_morton_sort: computes the codes of the n points and sorts them with a stable radix sort
 * (prep_radix_sort64). On return codes[i] is the i-th smallest code and perm[i] the index of its point in pos
 * (ties keep input order, so the result is deterministic). codes and perm hold n entries each.
 * Returns 0 or SD_ENOMEM (the sort needs 12 n bytes of temporary memory). */
int prep_morton_sort(const float *pos, size_t n, const prep_morton_frame *f, uint64_t *codes,
                     uint32_t *perm, sd_err *err);

/* prep_radix_sort64: sorts the n keys codes ascending with a stable radix sort (one MSD pass on
 * the 11 highest bits the keys differ in, then LSD passes of 8 bits inside each bucket,
 * skipping digits all keys share), moving perm[i] along with codes[i]. Returns 0 (also when
 * already sorted: then nothing moves) or SD_ENOMEM (12 n bytes of temporary memory). */
int prep_radix_sort64(uint64_t *codes, uint32_t *perm, size_t n, sd_err *err);
