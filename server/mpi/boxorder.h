/* boxorder.h — the visibility order of the ranks' parts for ordered (non-commutative)
 * compositing: soft and olt under splatd --mpi composite the ranks' images with "over", front
 * to back.
 *
 * Each rank's part is the set of points pc_partition gave it; its box is their bounding box.
 * The parts come from axis-aligned cuts applied recursively (a binary space partition), so the
 * boxes can be split again by axis-aligned planes: bo_order finds, for a set of boxes, a plane
 * x_a = c with every box wholly on one side (touching it allowed: points on a cut), and orders
 * the side that holds the eye first, recursively. That is exact for the points: no point of a
 * farther part lies in front of a point of a nearer one along any ray from the eye. (A splat or
 * disc reaching across a cut is what the order cannot fix: compose.h's "over" puts it wholly in
 * front of or behind the other part.) Boxes that no plane separates (not a partition by cuts)
 * fall back to the order of their nearest distance to the eye, and bo_order says so. */
#pragma once
#include <stdint.h>

typedef struct bo_box {
    float lo[3], hi[3];        /* lo > hi on an axis: empty (no point); ordered last */
} bo_box;

/* bo_boxes: box[p] = the bounding box of the points i with part[i] == p, for nparts parts of
 * the n points of pos (3n floats, local coordinates). */
void bo_boxes(const float *pos, uint64_t n, const uint16_t *part, int nparts,
              bo_box *box);

/* bo_order: order[0..n) = the parts front to back as seen from eye (local coordinates).
 * scratch: n ints. Returns 1 when every step found a separating plane (the order is exact for
 * the points), 0 when it fell back to distances somewhere. */
int bo_order(const bo_box *box, int n, const double eye[3], int *order, int *scratch);
