/* copc.h — Cloud Optimized Point Clouds: the COPC info VLR, the hierarchy pages and the
 * decoding of one octree node, read lazily (a page or a node only when asked for).
 *
 * A COPC file is a LAZ 1.4 file (point formats 6-8, variable chunks) whose first VLR is
 * "copc"/1, 160 bytes: centre x y z, half size, spacing (doubles), root hierarchy page offset
 * and size (u64), GPS time min and max (doubles), 11 reserved u64. The hierarchy lives in an
 * extended VLR "copc"/1000; each page is a list of 32-byte entries: the node's key (level, x,
 * y, z as i32), then u64 offset, i32 byte size, i32 point count. A count of -1 makes the entry
 * a link to a child page (offset and size of the page); 0 is a node without points; otherwise
 * offset/size hold a LAZ chunk of that many points. Nodes are chunks of the chunk table too,
 * so the whole file decodes as plain LAZ. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "laz.h"

typedef struct copc_info {
    double center[3], halfsize, spacing;
    uint64_t root_off, root_size;
    double gps_min, gps_max;
} copc_info;

typedef struct copc_entry {
    int32_t level, x, y, z;
    uint64_t off;
    int32_t bytes, count;    /* count -1: off/bytes is a child hierarchy page */
} copc_entry;

/* copc_info_read: the info VLR of lf (laz_open found it). Returns 0, or SD_EFORMAT when lf is
 * not COPC or the root page lies outside the file. */
int copc_info_read(const laz_file *lf, copc_info *out, sd_err *err);

/* copc_page_read: the entries of the hierarchy page at off, size bytes, into *out (malloc'd,
 * *n entries; at most size / 32, and size must lie in the file). Checks each entry: a child
 * page or a node chunk inside the file, a level and key that fit the octree (0 <= x, y, z <
 * 2^level), counts of -1 or more. Returns 0 or SD_EFORMAT naming the page and the entry. */
int copc_page_read(const laz_file *lf, uint64_t off, uint64_t size, copc_entry **out, size_t *n,
                   sd_err *err);

/* copc_node_read: decodes node e's points into *buf (records, grown; see laz_read_span).
 * cd is a chunk decoder for lf's items. */
int copc_node_read(const laz_file *lf, laz_chunk_dec *cd, const copc_entry *e, uint8_t **buf,
                   size_t *cap, sd_err *err);

/* copc_visit: walks the hierarchy from the root page, depth first, page by page, calling fn
 * for every node entry (count >= 0) of level max_level or less; a linked page whose node lies
 * deeper than max_level is not read at all (pass INT32_MAX for the whole tree). fn returns
 * nonzero to stop (copc_visit returns that value). At most size / 32 pages are read, so a page
 * that links back to an ancestor ends with an error instead of a loop. Returns 0, fn's stop
 * value, or a negative code. */
int copc_visit(const laz_file *lf, int32_t max_level, int (*fn)(void *ctx, const copc_entry *e),
               void *ctx, sd_err *err);
