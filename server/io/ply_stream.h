/* ply_stream.h — where the vertices of a PLY file lie when they can be read in blocks (the LOD
 * build's input stream; prep/lod_src.c): a binary little-endian file whose first element is
 * the vertex element, of fixed-size records. The header is parsed, the vertex properties
 * chosen and the whole file's elements checked by pc_read_ply's own code (io_ply.c), so a file
 * streamed from this plan is one pc_read_ply reads, with the same coordinates and colours. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

/* The plan of a streamable PLY file. Fields x y z r g b a, in that order. */
typedef struct pc_ply_stream {
    uint64_t data_off;      /* the first vertex record */
    uint64_t count;         /* vertex records */
    size_t rec;             /* bytes a record */
    int off[7];             /* the field's byte offset in a record, -1: absent (the colours are
                               all absent unless r, g and b are present) */
    int type[7];            /* its value type: 1 int8, 2 uint8, 3 int16, 4 uint16, 5 int32,
                               6 uint32, 7 float32, 8 float64 */
    double cscale[7];       /* colours: factor to 0..255 before rounding (pc_read_ply's) */
    char format[64];        /* pc_read_ply's format string */
} pc_ply_stream;

/* pc_ply_stream_plan: 1 with *sp filled when path is such a file and pc_read_ply would read it
 * (header, x y z present, every element inside the file); 0 when pc_read_ply reads it another
 * way (ascii, big-endian, the vertices not first or holding lists); the negative SD_E* code and
 * message pc_read_ply gives for a file it refuses. */
int pc_ply_stream_plan(const char *path, pc_ply_stream *sp, sd_err *err);
