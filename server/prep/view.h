/* view.h — a prepared cloud's default view (protocol/framing.h's sp_view), which INFO carries
 * and the daemon's frame without a camera uses: the up rule from the file's format, the
 * sensor's orientation where the file gives it, and the box the view frames.
 *
 * The framed box is the cloud's bounds without its farthest outliers: per axis the
 * VIEW_TRIM-th and (1 - VIEW_TRIM)-th quantiles of up to VIEW_SAMPLE points spread evenly over
 * the cloud (for a LOD cloud the points of its top levels, a uniform sample of the whole),
 * widened by half the gap to the real bounds' ends when that gap is small (so a clean cloud
 * keeps its own box), never beyond the bounds. A few stray returns far above a terrain (birds,
 * noise) then no longer shrink the terrain to a strip in the first view. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "framing.h"

#define VIEW_TRIM 0.001
enum { VIEW_SAMPLE = 65536 };

/* view_rule: the up rule (SP_UP_*) of a format string as the readers write it: "LAS ...",
 * "LAZ ...", "COPC ...", "E57 ..." are z up; "PCD ..." the sensor's orientation; anything else
 * the guess rule. */
int view_rule(const char *format);

/* view_box: the framed box of n positions pos (3 floats each, local coordinates: file = local +
 * offset) within the bounds bmin..bmax (file coordinates), into vmin..vmax. */
void view_box(const float *pos, uint64_t n, const double offset[3], const double bmin[3],
              const double bmax[3], double vmin[3], double vmax[3]);

/* view_make: the default view of a cloud of format fmt, bounds bmin..bmax and framed box
 * vmin..vmax; q (w, x, y, z) the sensor's rotation when has_q (PCD VIEWPOINT), else NULL. */
void view_make(const char *fmt, const double bmin[3], const double bmax[3], const double vmin[3],
               const double vmax[3], const double *q, sp_view *v);

struct pc_prepared;
struct lod_cloud;
/* view_of_prepared, view_of_lod: the default view of a prepared cloud (its positions sampled
 * for the framed box) and of a LOD cloud (the points of its top nodes, breadth first). */
void view_of_prepared(const struct pc_prepared *p, sp_view *v);
void view_of_lod(const struct lod_cloud *c, sp_view *v);
