/* las_stream.h — the point records of an uncompressed LAS file read in blocks with pread, so
 * memory does not grow with the file (the LOD build's input stream; prep/lod_src.c).
 *
 * The conversion is pc_read_las's (las_header.h): coordinate = X * scale + offset; colours are
 * handed out as the file's 16-bit values, and the caller scales them to 8 bits by the same rule
 * (down only when some value of the file needs more than 8 bits), which needs the whole file's
 * maximum: a first pass over the blocks gives it. A file that shrinks under a read gives an
 * error naming the byte, never a SIGBUS (nothing is mapped). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct pc_las_stream pc_las_stream;

/* pc_las_stream_open: 1 and *out when path is an uncompressed LAS file (header checked as
 * pc_read_las checks it: every declared record lies in the file), 0 when it is not a LAS file or
 * is LAZ (the caller reads it another way), negative SD_E* with a message on a bad header or an
 * I/O error. */
int pc_las_stream_open(const char *path, pc_las_stream **out, sd_err *err);
void pc_las_stream_close(pc_las_stream *s);

uint64_t pc_las_stream_count(const pc_las_stream *s);   /* point records */
int pc_las_stream_has_rgb(const pc_las_stream *s);       /* formats 2, 3, 5, 7, 8, 10 */
const char *pc_las_stream_format(const pc_las_stream *s); /* "LAS 1.2 format 2", as pc_read_las */

/* pc_las_stream_read: records [first, first + m) as coordinates (3 doubles each) and, when
 * rgb16 is not NULL and the format has colours, their 16-bit colours (3 each). m is at most
 * PC_LAS_STREAM_BLOCK. Returns 0 or a negative SD_E*. */
enum { PC_LAS_STREAM_BLOCK = 1 << 16 };
int pc_las_stream_read(pc_las_stream *s, uint64_t first, size_t m, double *xyz, uint16_t *rgb16,
                       sd_err *err);
