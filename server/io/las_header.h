/* las_header.h — the LAS public header, shared by the LAS reader (io_las.c) and the LAZ reader
 * (io_laz.c), and the conversion of LAS point records into the raw cloud.
 *
 * The public header (little-endian, offsets in bytes):
 *     0 "LASF"                      24 version major, 25 minor
 *    94 header size (u16)           96 offset to point data (u32)   100 number of VLRs (u32)
 *   104 point data format (u8; bits 6 and 7 set mark LAZ compression)
 *   105 point data record length (u16)
 *   107 legacy point count (u32)   131 x y z scale (3 doubles)   155 x y z offset (3 doubles)
 *   235 (1.4) start of the first extended VLR (u64), 243 their number (u32)
 *   247 (1.4) point count (u64), used when the legacy count is 0
 * Internal to the pc_ module. */
#pragma once
#include <stdint.h>
#include <string.h>

#include "cloud.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the LAS readers read little-endian fields with memcpy; add byte swapping for this host"
#endif

/* Minimum record length and RGB offset (0: none) of each point data format. */
typedef struct pc__las_format {
    uint16_t len, rgb;
} pc__las_format;
extern const pc__las_format pc__las_formats[11];

/* What the readers take from the header. */
typedef struct las_header {
    unsigned minor, format;  /* format without the compression bits */
    int compressed;          /* bits 6/7 of the format byte: LAZ */
    uint32_t header_size, data_off, rec_len, nvlr, nevlr;
    uint64_t count, evlr_off;
    double scale[3], offset[3];
} las_header;

static inline uint16_t rd16(const uint8_t *p) { uint16_t v; memcpy(&v, p, 2); return v; }
static inline uint32_t rd32(const uint8_t *p) { uint32_t v; memcpy(&v, p, 4); return v; }
static inline uint64_t rd64(const uint8_t *p) { uint64_t v; memcpy(&v, p, 8); return v; }
static inline int32_t rdi32(const uint8_t *p) { int32_t v; memcpy(&v, p, 4); return v; }
static inline double rdf64(const uint8_t *p) { double v; memcpy(&v, p, 8); return v; }

/* pc__las_header: checks the public header of a file of size bytes and fills h. Returns 0 or
 * a negative code whose message names the offending field's byte offset. For an uncompressed
 * file every declared record must lie in the file; a compressed one is bounded later by its
 * chunk table. A count of 0 gives SD_EEMPTY. */
int pc__las_header(const char *path, const uint8_t *d, size_t size, las_header *h, sd_err *err);

/* pc__las_convert: n records of h's format at rec into raw's points at .. at+n (xyz, intensity,
 * class, colour). Colours go to rgb16 (3 per point, indexed like raw) when it is not NULL,
 * else into raw->rgba, divided down from 16 bits when wide. */
void pc__las_convert(const las_header *h, const uint8_t *rec, size_t n, pc_raw *raw, size_t at,
                     int wide, uint16_t *rgb16);

/* pc__las_rgb16: raw->rgba of the n points from their 16-bit colours, scaled down only when
 * some value needs more than 8 bits (many writers store 8-bit values in the 16-bit fields). */
void pc__las_rgb16(const uint16_t *rgb16, size_t n, pc_raw *raw);
/* pc__las_rgb16 in parts (a threaded reader): whether any of n colours needs more than 8 bits,
 * and raw->rgba of points lo .. hi-1 from rgb16, divided down when wide. */
int pc__las_rgb16_wide(const uint16_t *rgb16, size_t n);
void pc__las_rgb16_range(const uint16_t *rgb16, size_t lo, size_t hi, int wide, pc_raw *raw);

