/* lod_src.h — the input of the LOD build, read as a stream of points in file order.
 *
 * Binary little-endian PLY whose first element is the vertex element with scalar properties
 * (what scanners' exports and gen_cloud write) and uncompressed LAS (io/las_stream.h) are
 * streamed with pread in blocks, LAZ and COPC (io/laz_stream.h) a round of chunks at a time,
 * decoded in parallel, XYZ/PTS text (io/xyz_stream.h), PCD (io/pcd_stream.h; a
 * binary_compressed body is decompressed whole first) and E57 (io/e57_stream.h: scan by scan,
 * packets read as the records need them) a window of rows at a time: memory does not grow with
 * the file. Any other file (ascii or big-endian PLY, PLY whose first element is
 * not the vertices) is read whole by pc_load (io/) and handed out from memory; that path is in
 * core, and says so in lod_src_info.streamed.
 *
 * Positions come out as prepared.h has them: float(x - offset), offset the double centre of
 * the bounding box of the finite points (pc_finalize's rule), non-finite points skipped, so
 * point i of the stream is point i of pc_load's cloud. Colours as RGBA8 (r in the low byte,
 * alpha 255), white when the file has none. Normals, radii and other attributes of the file
 * are not read: the LOD build computes normals and radii itself. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct lod_src lod_src;

/* lod_src_open: opens path and runs the bounds pass (one read of the file); the stream then
 * starts at the first point. */
int lod_src_open(const char *path, lod_src **out, sd_err *err);
void lod_src_close(lod_src *s);

/* Summary after the bounds pass. */
typedef struct lod_src_info {
    uint64_t n, n_dropped;      /* finite points, points dropped */
    double offset[3], bmin[3], bmax[3];
    uint32_t attrs;             /* PC_ATTR_RGB when the file has colours */
    int has_viewpoint;
    double viewpoint[3];        /* file coordinates */
    double viewpoint_q[4];      /* the sensor's rotation, w x y z */
    char format[64];
    int streamed;               /* 1: read in blocks; 0: read whole (another format) */
} lod_src_info;
void lod_src_get_info(const lod_src *s, lod_src_info *info);

/* lod_src_rewind: starts the stream again at the first point. */
int lod_src_rewind(lod_src *s, sd_err *err);

/* lod_src_next: up to max next points: local positions (3 floats each) and colours. Returns the
 * count (0 at the end) or a negative SD_E*. */
int64_t lod_src_next(lod_src *s, float *pos, uint32_t *rgba, size_t max, sd_err *err);
