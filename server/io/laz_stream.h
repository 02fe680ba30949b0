/* laz_stream.h — the points of a LAZ (or COPC) file decoded a few chunks at a time, so memory
 * does not grow with the file (the LOD build's input stream; prep/lod_src.c). The LAZ sibling
 * of las_stream.h, with the same conversion as pc_read_laz: coordinate = X * scale + offset,
 * colours handed out as the file's 16-bit values for the caller to scale by pc_read_las's rule
 * (which needs the whole file's maximum: a first pass gives it).
 *
 * The file is mapped read-only and read under a SIGBUS guard (a file that shrinks mid-read is
 * an error naming it, never a crash). Each read decodes a round of `threads` consecutive chunks
 * in parallel, each thread into its own buffers grown only by what really decoded (never by the
 * chunk table's claim); the pages of a decoded round are given back (madvise), so the resident
 * size is a round's points plus the decoder's models, whatever the file's size. Reads in file
 * order decode every chunk once; a read before the held round (a rewind) decodes again from the
 * chunk that holds its first point. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

typedef struct pc_laz_stream pc_laz_stream;

/* pc_laz_stream_open: 1 and *out when path is a LAZ file (a LAS header with the compression
 * bits) whose laszip VLR and chunk table parse; 0 when it is not LAZ (an uncompressed LAS or
 * another format: the caller reads it another way); a negative SD_E* with a message naming the
 * file on a malformed header or table, an unsupported point format, or an I/O error. threads:
 * chunks decoded at once (0: the online CPUs). */
int pc_laz_stream_open(const char *path, int threads, pc_laz_stream **out, sd_err *err);
void pc_laz_stream_close(pc_laz_stream *s);

uint64_t pc_laz_stream_count(const pc_laz_stream *s);   /* points, per the chunk table */
int pc_laz_stream_has_rgb(const pc_laz_stream *s);       /* formats 2, 3, 5, 7, 8, 10 */
const char *pc_laz_stream_format(const pc_laz_stream *s); /* "LAZ 1.2 format 3", as pc_read_laz */

/* pc_laz_stream_read: points [first, first + m) as coordinates (3 doubles each) and, when rgb16
 * is not NULL and the format has colours, their 16-bit colours (3 each); first + m at most the
 * count. Returns 0 or a negative SD_E* naming the file and the chunk. */
int pc_laz_stream_read(pc_laz_stream *s, uint64_t first, size_t m, double *xyz, uint16_t *rgb16,
                       sd_err *err);
