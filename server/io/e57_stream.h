/* e57_stream.h — the points of an E57 file (ASTM E2807), scan after scan, a batch of records
 * at a time: pc_read_e57 (io_e57.c) reads a whole file through it and the LOD build
 * (prep/lod_src.c) streams it. Memory per open stream: the XML tree's scan list, one
 * compressed vector reader (a packet buffer per field read, a few cached packets) and one
 * batch of decoded records, whatever the scans' sizes.
 *
 * Every /data3D scan becomes points in the file's world frame:
 *   - cartesianX/Y/Z, else sphericalRange/Azimuth/Elevation (x = r cos(el) cos(az),
 *     y = r cos(el) sin(az), z = r sin(el)); both present: cartesian;
 *   - the invalid state of the coordinates used (cartesianInvalidState or
 *     sphericalInvalidState): 0 is a point; 1 (only a direction is meaningful: the range or
 *     magnitude is not) and 2 (no meaningful value) are both dropped, as neither gives a
 *     position;
 *   - the scan's pose applied: world = R p + t (R from the rotation quaternion);
 *   - colours mapped from the scan's colour limits to 0-255 (RGBA8, alpha 255; white when the
 *     scan has none or isColorInvalid is set);
 *   - intensities mapped from the intensity limits to [0, 1] (kept as they are when no finite
 *     limits are known; 0 when the scan has none or isIntensityInvalid is set);
 *   - normals of the surface normals extension (nor:normalX/Y/Z) rotated by R and normalised;
 *   - the scan's index in /data3D.
 * rowIndex, columnIndex, timeStamp and the other fields are never read; images2D are skipped.
 * Non-finite coordinates are handed out (pc_finalize and lod_src drop them). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct pc_e57_stream pc_e57_stream;

/* pc_e57_signature: 1 when the file path starts with "ASTM-E57" (E57's signature). */
int pc_e57_signature(const char *path);

/* pc_e57_stream_open: 1 and *out when path has the extension e57 (any case) or starts with the
 * signature "ASTM-E57", and its header, XML, scans and every compressed vector's section
 * header check out (no two scans' sections overlapping); 0 when it is neither (another format); a negative SD_E* naming the file
 * and the offset or XML line otherwise (SD_EEMPTY: no /data3D scan). */
int pc_e57_stream_open(const char *path, pc_e57_stream **out, sd_err *err);
void pc_e57_stream_close(pc_e57_stream *s);
void pc_e57_stream_rewind(pc_e57_stream *s);

/* Where pc_e57_stream_next writes; any pointer may be NULL (not wanted). */
typedef struct pc_e57_points {
    double *xyz;       /* 3 per point */
    uint8_t *rgba;     /* 4 per point */
    float *intensity;  /* 1 per point */
    float *normal;     /* 3 per point */
    uint16_t *scan;    /* 1 per point */
} pc_e57_points;

/* pc_e57_stream_next: up to max next valid points. Returns the count, 0 at the end, or a
 * negative SD_E* naming the file, the scan and the record or physical offset. */
int64_t pc_e57_stream_next(pc_e57_stream *s, const pc_e57_points *out, size_t max,
                           sd_err *err);

/* pc_e57_stream_attrs: the PC_ATTR_* bits the points carry: RGB when some scan has colours,
 * INTENSITY when some scan has intensities, NORMAL when every scan with records has normals,
 * SCAN when the file has more than one scan. */
uint32_t pc_e57_stream_attrs(const pc_e57_stream *s);
/* pc_e57_stream_bound: the most points the file can give: the sum over scans of the smaller of
 * recordCount and what the compressed vector's bytes can hold at the bits a record takes. */
uint64_t pc_e57_stream_bound(const pc_e57_stream *s);
uint32_t pc_e57_stream_scans(const pc_e57_stream *s);
uint64_t pc_e57_stream_records(const pc_e57_stream *s);  /* recordCount over all scans */
const char *pc_e57_stream_format(const pc_e57_stream *s); /* "E57 1.0, 2 scans" */
/* pc_e57_stream_pages_checked: pages whose checksum was computed so far (tests). */
uint64_t pc_e57_stream_pages_checked(const pc_e57_stream *s);
