/* pcd_stream.h — the points of a PCD file read a window at a time, so memory does not grow with
 * the file (the LOD build's input stream; prep/lod_src.c). The same header checks and value
 * conversions as pc_read_pcd (io_pcd.c): the same points, the same errors.
 *
 * binary bodies are decoded a window of records at a time from the mapped file, ascii bodies a
 * window of lines at a time (the reader resumed where the window ended), and the pages already
 * read are given back. A binary_compressed body is one LZF stream of field-major values (every
 * x, then every y, ...): no window of points can be decoded without all of it, so it is
 * decompressed whole once (its size checked against the header as pc_read_pcd checks it) and
 * windows are decoded from that buffer: that form is not bounded in memory.
 *
 * Colours from separate red/green/blue fields are scaled by what the whole file holds (16-bit
 * when some value is over 255), so they come out only once a whole pass has been read. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct pc_pcd_stream pc_pcd_stream;

/* pc_pcd_stream_open: 1 and *out when path has the extension pcd (pc_load's rule) and its header
 * checks out; 0 for another extension; a negative SD_E* with pc_read_pcd's message otherwise. */
int pc_pcd_stream_open(const char *path, pc_pcd_stream **out, sd_err *err);
void pc_pcd_stream_close(pc_pcd_stream *s);

void pc_pcd_stream_rewind(pc_pcd_stream *s);

/* pc_pcd_stream_next: up to max next points as coordinates (3 doubles each) and, when rgba is
 * not NULL, colours as pc_read_pcd makes them (RGBA8; white when the file has none); rgba from
 * separate colour fields needs a whole pass read before (else SD_EINVAL). Returns the count, 0
 * at the end, or a negative SD_E* naming the file and the line or offset. */
int64_t pc_pcd_stream_next(pc_pcd_stream *s, double *xyz, uint8_t *rgba, size_t max,
                           sd_err *err);

uint64_t pc_pcd_stream_count(const pc_pcd_stream *s);    /* points the header declares */
const char *pc_pcd_stream_format(const pc_pcd_stream *s); /* "PCD 0.7 binary", as pc_read_pcd */
int pc_pcd_stream_has_rgb(const pc_pcd_stream *s);
/* pc_pcd_stream_viewpoint: 1 and the sensor's position (file coordinates) and rotation (w x y
 * z) when the header gives a pose other than PCL's identity default, as pc_read_pcd. */
int pc_pcd_stream_viewpoint(const pc_pcd_stream *s, double xyz[3], double q[4]);
