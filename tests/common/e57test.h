/* e57test.h — a small E57 (ASTM E2807) writer for the tests and the benchmark, written from the
 * format description and apart from the reader (server/io/e57_*.c): synthetic files with any
 * prototype (integers of any width, scaled integers, single and double floats, the normals
 * extension), several scans with poses, invalid states, many data packets whose fields advance
 * at different paces (records cut across packets), index and empty packets.
 *
 * The file is written as it is generated, a data packet at a time, through a page writer that
 * appends each page's CRC-32C (computed bit by bit here), so a multi-million-point file needs no
 * more memory than a few packets. Values come from a callback per record. */
#pragma once
#include <stddef.h>
#include <stdint.h>

enum { E57W_INT, E57W_SCALED, E57W_F32, E57W_F64 };

typedef struct e57w_field {
    const char *name;        /* element name, with its prefix: "cartesianX", "nor:normalX" */
    int kind;                /* E57W_* */
    int64_t min, max;        /* E57W_INT, E57W_SCALED: raw bounds */
    double scale, offset;    /* E57W_SCALED (scale 0: 1) */
    int no_bounds;           /* E57W_INT: write no minimum/maximum (the int64 range) */
} e57w_field;

/* The value of field f of record i: ints[f] for integer fields (the raw integer, before any
 * scale), dbls[f] for float fields. */
typedef void (*e57w_gen)(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls);

typedef struct e57w_scan {
    uint32_t nfields;
    const e57w_field *fields;
    uint64_t records;
    int pose;                /* 1: write <pose> */
    int pose_no_rotation;    /* with pose: only the translation */
    double quat[4];          /* w x y z */
    double trans[3];
    const char *extra_xml;   /* put inside the scan's element (limits, ...); NULL: none */
    /* packets: field f takes per_packet + f * stagger records per data packet (0: as many as
     * fit a 64 KiB packet for the slowest field) */
    uint32_t per_packet, stagger;
    int empty_packet;        /* an empty packet after the first data packet */
    int index_packet;        /* an index packet after the data packets */
} e57w_scan;

typedef struct e57w_opts {
    uint32_t page;           /* page size (0: 1024) */
    const char *root_extra;  /* put inside <e57Root> (images2D, ...); NULL: none */
} e57w_opts;

/* e57w_write: writes the file path. Returns 0, or -1 (with a message on stderr). */
int e57w_write(const char *path, const e57w_scan *scans, uint32_t nscans, const e57w_opts *o,
               e57w_gen gen, void *ctx);

/* e57w_crc32c: CRC-32C of n bytes, bit by bit. */
uint32_t e57w_crc32c(const uint8_t *p, size_t n);

/* e57w_fix_crcs: recomputes every page checksum of the file image d (n bytes, pages of page
 * bytes), after a test changed its bytes. */
void e57w_fix_crcs(uint8_t *d, size_t n, uint32_t page);

/* e57w_phys: the physical offset of logical offset l (pages of page bytes). */
uint64_t e57w_phys(uint64_t l, uint32_t page);
