/* partition.h — spatial parts of a prepared cloud for sort-last rendering (splatd --mpi): each
 * of N ranks keeps about 1/N of the points and of their screen footprint in one box and renders
 * only those.
 *
 * The units are octree cells: the cloud's Morton cube (morton.h) refined until no cell holds
 * more than max(1, n / (PC_PART_CELL_DIV N)) points (or a cell is a finest-level cell); the
 * non-empty leaves are the units and every unit goes whole to one part. The parts are the
 * leaves of a kd tree over the cube: a region destined for k parts is cut by an axis-aligned
 * plane into two regions for floor(k/2) and ceil(k/2) parts, and only planes that cross no unit
 * are candidates (planes on the octree's cell grid), so every part is a box, a union of whole
 * cells, and the parts are disjoint and tile the cube (the order a back-to-front composite of
 * the ranks' images needs: a kd tree's boxes are always depth-sortable).
 *
 * What is balanced: the points (upload, memory, vertex work) and the screen footprint. The
 * footprint depends on the view; its view-independent proxy is the sum of the points' splat
 * areas, pi r^2 with r the prep's radius (a part of few large splats covers as much screen and
 * costs as much fill as one of many small ones). Each cut is the candidate plane, over the three
 * axes, that minimises the larger of the two imbalances it leaves, max(points, footprint), each
 * as max/mean of the two sides' per-part shares against the split floor(k/2) : ceil(k/2).
 * Everything is computed in a fixed order from the positions and radii alone, so every rank
 * gets the same result. */
#pragma once
#include <stdint.h>

#include "prepared.h"
#include "sd_err.h"

enum { PC_PART_MAX = 4096 };
enum { PC_PART_CELL_DIV = 64 }; /* units hold at most n / (64 N) points */
enum { PC_PART_MIN_LEVEL = 6 }; /* and are cells of level 6 or deeper (edge <= 1/64 cube) */

/* A part's region: the half-open box [lo, hi) in local coordinates (pos's), and the same box in
 * finest-level cells of the cloud's Morton frame (prep_morton_frame_of(pos, n)): a point whose
 * cell indices c satisfy cell_lo <= c < cell_hi on every axis belongs to it. The N boxes tile the
 * frame's cube. */
typedef struct pc_part_box {
    double lo[3], hi[3];
    uint32_t cell_lo[3], cell_hi[3];
} pc_part_box;

/* pc_partition: part[i] in [0, nparts) for each of the n points of pos (3n floats) with splat
 * radii radius (n floats, >= 0; NULL: every point weighs the same, only points are balanced);
 * box, when not NULL, receives the nparts regions. nparts in 1..PC_PART_MAX, n < 2^32.
 * A part may be empty only when the cloud has fewer units than parts. Temporary memory: 8
 * bytes a point, 16 more when pos is not in the Morton order of its own cube (a prepared
 * cloud is: prep.c sorts it so), and 32 bytes a unit. Returns 0 or SD_EINVAL / SD_ENOMEM. */
int pc_partition(const float *pos, const float *radius, uint64_t n, int nparts, uint16_t *part,
                 pc_part_box *box, sd_err *err);

/* pc_partition_median: the earlier partition, kept to compare against (tests, bench): recursive
 * cuts at the median of the longest axis of each set's bounding box, points only, ordered by
 * coordinate then index; not on a cell grid (points on a cut plane may go either way). */
int pc_partition_median(const float *pos, uint64_t n, int nparts, uint16_t *part, sd_err *err);

/* pc_partition_balance: each part's share of the points and of the footprint proxy (sum of
 * pi r^2; radius NULL: of the points) in pts[p], fp[p] (nparts entries each), and the
 * imbalances max/mean of both (1 = perfect) in *pts_imb, *fp_imb. */
void pc_partition_balance(const float *radius, uint64_t n, const uint16_t *part, int nparts,
                          double *pts, double *fp, double *pts_imb, double *fp_imb);

/* pc_prepared_subset: dst = the points i of src with part[i] == which, in their order, with
 * every section copied into a new heap block and batches of PC_BATCH_POINTS re-cut. The
 * summary (offset, bounds, sigma, F percentiles, radius median, format, k) is src's: the view's
 * near and far planes and the height field's range are the whole cloud's, so each part renders
 * exactly as its points would within the whole. Returns 0 or SD_ENOMEM (dst zeroed). */
int pc_prepared_subset(const pc_prepared *src, const uint16_t *part, int which,
                       pc_prepared *dst, sd_err *err);
