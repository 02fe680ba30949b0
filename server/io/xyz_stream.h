/* xyz_stream.h — the rows of an XYZ/PTS text file (.xyz, .pts, .txt) read a window at a time,
 * so memory does not grow with the file (the LOD build's input stream; prep/lod_src.c). The
 * same parser as pc_read_xyz (io_xyz.c), resumed where the last window ended: the same rows,
 * the same errors with the same line numbers.
 *
 * Colours: pc_read_xyz scales them by what the whole file holds (16-bit when some value is over
 * 255, 0..1 floats when all are within [0, 1] with a fraction), so they come out only once a
 * whole pass has been read; the caller's first pass (bounds) asks for positions alone. The file
 * is mapped and parsed under a SIGBUS guard (a file that shrinks is an error, not a crash), and
 * the pages of the windows already read are given back. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct pc_xyz_stream pc_xyz_stream;

/* pc_xyz_stream_open: 1 and *out when path has an XYZ/PTS extension (pc_load's rule), 0 when it
 * has another, a negative SD_E* with a message when it cannot be opened. Nothing is parsed yet. */
int pc_xyz_stream_open(const char *path, pc_xyz_stream **out, sd_err *err);
void pc_xyz_stream_close(pc_xyz_stream *s);

/* pc_xyz_stream_rewind: the next read starts at the first line again. */
void pc_xyz_stream_rewind(pc_xyz_stream *s);

/* pc_xyz_stream_next: up to max next rows as coordinates (3 doubles each) and, when rgba is not
 * NULL, colours as pc_read_xyz makes them (RGBA8, alpha 255; white when the file has none);
 * rgba needs a whole pass read before (else SD_EINVAL). Returns the count, 0 at the end (and
 * then the file's layout, format and colour scale are final), or a negative SD_E* naming the
 * file and the line. */
int64_t pc_xyz_stream_next(pc_xyz_stream *s, double *xyz, uint8_t *rgba, size_t max,
                           sd_err *err);

/* After a whole pass: the format pc_read_xyz names, and whether the rows carry colours. */
const char *pc_xyz_stream_format(const pc_xyz_stream *s);
int pc_xyz_stream_has_rgb(const pc_xyz_stream *s);
