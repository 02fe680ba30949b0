/* partition.h — spatial parts of a prepared cloud for sort-last rendering (splatd --mpi): each
 * of N ranks keeps about 1/N of the points in a compact region and renders only those.
 *
 * The split is recursive: a set of points destined for k parts is cut at the median of the
 * longest axis of its bounding box into two sets for floor(k/2) and ceil(k/2) parts, holding
 * the points in the same proportion; points are ordered along the axis by coordinate, then by
 * index, so the result is deterministic and the same on every rank. (The level-of-detail
 * octree, when there is one, would hand out its nodes instead; this needs only positions.) */
#pragma once
#include <stdint.h>

#include "prepared.h"
#include "sd_err.h"

enum { PC_PART_MAX = 4096 };

/* pc_partition: part[i] in [0, nparts) for each of the n points of pos (3n floats). nparts in
 * 1..PC_PART_MAX. Returns 0 or SD_EINVAL / SD_ENOMEM. */
int pc_partition(const float *pos, uint64_t n, int nparts, uint16_t *part, sd_err *err);

/* pc_prepared_subset: dst = the points i of src with part[i] == which, in their order, with
 * every section copied into a new heap block and batches of PC_BATCH_POINTS re-cut. The
 * summary (offset, bounds, sigma, F percentiles, radius median, format, k) is src's: the view's
 * near and far planes and the height field's range are the whole cloud's, so each part renders
 * exactly as its points would within the whole. Returns 0 or SD_ENOMEM (dst zeroed). */
int pc_prepared_subset(const pc_prepared *src, const uint16_t *part, int which,
                       pc_prepared *dst, sd_err *err);
