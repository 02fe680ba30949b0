/* laz.h — a LAZ file (LASzip-compressed LAS 1.0-1.4) in memory: its header, the laszip VLR
 * (compressor, chunk size, item list), the chunk table, and the decoding of one chunk.
 *
 * Layout: the LAS header and VLRs as in LAS; at the offset to point data an i64 with the
 * offset of the chunk table (-1: the writer could not seek back, the offset is then the last
 * 8 bytes of the file); the chunks; the chunk table: u32 version 0, u32 chunk count, then
 * arithmetic-coded per chunk its point count (variable chunk size only) and its byte size,
 * each predicted from the previous chunk's. The first chunk starts right after the i64.
 *
 * Every count is checked against the bytes that hold it before anything is allocated for it:
 * the chunk count against the bytes between the first chunk and the table, each chunk's
 * points against its bytes at the coder's densest (laz_open), and chunk decoding grows its
 * output only as points really decode (laz_read_span). Errors name the file and the chunk. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "las_header.h"
#include "laz_chunk.h"
#include "sd_err.h"

typedef struct laz_file {
    const char *path;
    const uint8_t *data;     /* the whole file, not owned */
    size_t size;
    las_header h;
    unsigned compressor;     /* 2 pointwise chunked, 3 layered chunked */
    uint32_t chunk_size;     /* points per chunk, or UINT32_MAX: variable (in the table) */
    laz_item items[LAZ_MAX_ITEMS];
    unsigned nitems;
    size_t nchunks;
    uint64_t *chunk_start;   /* nchunks + 1 byte offsets; the last is the chunk table's */
    uint64_t *chunk_first;   /* nchunks + 1 point indices; the last is the point count */
    const uint8_t *copc_info; /* the 160-byte COPC info VLR payload, NULL when not COPC */
} laz_file;

/* laz_open: parses the file in [data, data+size) named path (kept for messages). Returns 0;
 * SD_EEMPTY (no points); SD_EUNSUP (waveform formats 4, 5, 9, 10; other compressors or item
 * versions; an uncompressed file); SD_EFORMAT/SD_ETRUNC with the offending offset or chunk;
 * SD_ENOMEM. lf is zeroed on failure. */
int laz_open(laz_file *lf, const char *path, const uint8_t *data, size_t size, sd_err *err);
void laz_close(laz_file *lf);

/* laz_read_span: decodes npts points coded from byte off, bytes long (a chunk: chunk i of the
 * table, or a COPC node), into *buf (records of h.rec_len bytes; grown with realloc, *cap its
 * size in bytes). label names the chunk in errors ("chunk 3", "node 2-1-0-1"). Returns 0 or
 * a negative code; *buf stays the caller's to free either way. */
int laz_read_span(const laz_file *lf, laz_chunk_dec *cd, uint64_t off, uint64_t bytes,
                  uint64_t npts, const char *label, uint8_t **buf, size_t *cap, sd_err *err);

/* laz_read_chunk: laz_read_span on chunk i of the chunk table. */
int laz_read_chunk(const laz_file *lf, laz_chunk_dec *cd, size_t i, uint8_t **buf, size_t *cap,
                   sd_err *err);

/* The densest the coder can be: each point costs at least one symbol of a model whose least
 * likely symbol keeps a count of 1 in 2^15, about 0.003 bits, so a byte holds at most ~2900
 * points. A chunk claiming more points per byte than this is malformed. */
#define LAZ_MAX_POINTS_PER_BYTE 4096u
