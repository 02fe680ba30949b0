/* io_las.c — the LAS reader (ASPRS LAS 1.0 to 1.4, uncompressed, point data formats 0 to 10).
 *
 * The public header (little-endian, offsets in bytes):
 *     0 "LASF"                      24 version major, 25 minor
 *    94 header size (u16)           96 offset to point data (u32)
 *   104 point data format (u8; bits 6 and 7 set mark LAZ compression)
 *   105 point data record length (u16)
 *   107 legacy point count (u32)   131 x y z scale (3 doubles)   155 x y z offset (3 doubles)
 *   179 max x, min x, max y, min y, max z, min z (doubles)
 *   247 (1.4) point count (u64), used when the legacy count is 0
 * Each point record starts with X Y Z as int32 (coordinate = X * scale + offset) and a u16
 * intensity. Formats 0-5 keep the class in the low 5 bits of byte 15; formats 6-10 in all of
 * byte 16. RGB (3 x u16) follows the GPS time in formats 2, 3, 5 and sits at byte 30 in 7, 8
 * and 10. Records may be longer than their format needs (extra bytes); they are skipped. */
#include "cloud.h"
#include "io_text.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "io_las.c reads little-endian LAS fields with memcpy; add byte swapping for this host"
#endif

#define LAS_HEADER_MIN 227u /* LAS 1.0-1.2 public header; 1.3 adds 8 bytes, 1.4 adds 148 */

/* Minimum record length and RGB offset (0: none) of each point data format. */
static const struct { uint16_t len, rgb; } las_formats[11] = {
    {20, 0}, {28, 0}, {26, 20}, {34, 28}, {57, 0}, {63, 28},
    {30, 0}, {36, 30}, {38, 30}, {59, 0}, {67, 30},
};

static uint16_t rd16(const uint8_t *p) { uint16_t v; memcpy(&v, p, 2); return v; }
static uint32_t rd32(const uint8_t *p) { uint32_t v; memcpy(&v, p, 4); return v; }
static uint64_t rd64(const uint8_t *p) { uint64_t v; memcpy(&v, p, 8); return v; }
static int32_t rdi32(const uint8_t *p) { int32_t v; memcpy(&v, p, 4); return v; }
static double rdf64(const uint8_t *p) { double v; memcpy(&v, p, 8); return v; }

/* What the reader takes from the header. */
typedef struct las_header {
    unsigned minor, format;
    uint32_t header_size, data_off, rec_len;
    uint64_t count;
    double scale[3], offset[3];
} las_header;

/* Checks the public header of a file of size bytes and fills h. Returns 0 or a negative code
 * whose message names the offending field's byte offset. */
static int parse_header(const char *path, const uint8_t *d, size_t size, las_header *h,
                        sd_err *err)
{
    if (size < 4)
        return sd_errf(err, SD_ETRUNC, "%s: the file ends at offset %zu, before the 4-byte "
                       "'LASF' magic", path, size);
    if (memcmp(d, "LASF", 4) != 0) {
        char got[5] = {0};
        for (size_t i = 0; i < 4; i++)
            got[i] = (d[i] >= 32 && d[i] < 127) ? (char)d[i] : '?';
        return sd_errf(err, SD_EFORMAT, "%s: not a LAS file: the magic at offset 0 is '%s', not "
                       "'LASF'", path, got);
    }
    if (size < LAS_HEADER_MIN)
        return sd_errf(err, SD_ETRUNC, "%s: the LAS header is cut off at offset %zu (it needs "
                       "%u bytes)", path, size, LAS_HEADER_MIN);
    unsigned major = d[24];
    h->minor = d[25];
    if (major != 1 || h->minor > 4)
        return sd_errf(err, SD_EUNSUP, "%s: LAS version %u.%u (offset 24) is not supported (1.0 "
                       "to 1.4)", path, major, h->minor);
    h->header_size = rd16(d + 94);
    h->data_off = rd32(d + 96);
    unsigned fmt = d[104];
    h->rec_len = rd16(d + 105);
    uint32_t need = h->minor == 4 ? 375 : h->minor == 3 ? 235 : LAS_HEADER_MIN;
    if (h->header_size < need)
        return sd_errf(err, SD_EFORMAT, "%s: header size %u at offset 94 is below the %u bytes "
                       "of a LAS 1.%u header", path, h->header_size, need, h->minor);
    if (h->header_size > h->data_off)
        return sd_errf(err, SD_EFORMAT, "%s: header size %u at offset 94 exceeds the offset to "
                       "point data %u (offset 96)", path, h->header_size, h->data_off);
    if (h->header_size > size)
        return sd_errf(err, SD_ETRUNC, "%s: the %u-byte LAS header (size at offset 94) is cut "
                       "off at offset %zu", path, h->header_size, size);
    if (h->data_off > size)
        return sd_errf(err, SD_ETRUNC, "%s: the offset to point data %u (offset 96) is past the "
                       "end of the file (%zu bytes)", path, h->data_off, size);
    if (fmt & 0xC0)
        return sd_errf(err, SD_EUNSUP, "%s: point data format byte 0x%02x at offset 104 has the "
                       "compression bits set: compressed LAZ not supported (decompress it with "
                       "laszip first)", path, fmt);
    if (fmt > 10)
        return sd_errf(err, SD_EUNSUP, "%s: point data format %u at offset 104 is not supported "
                       "(0 to 10)", path, fmt);
    h->format = fmt;
    if (h->rec_len < las_formats[fmt].len)
        return sd_errf(err, SD_EFORMAT, "%s: point record length %u at offset 105 is shorter "
                       "than the %u bytes of point format %u", path, h->rec_len,
                       las_formats[fmt].len, fmt);
    h->count = rd32(d + 107);
    if (h->count == 0 && h->minor == 4) h->count = rd64(d + 247);
    for (int k = 0; k < 3; k++) {
        h->scale[k] = rdf64(d + 131 + 8 * k);
        h->offset[k] = rdf64(d + 155 + 8 * k);
        if (!isfinite(h->scale[k]) || h->scale[k] == 0 || !isfinite(h->offset[k]))
            return sd_errf(err, SD_EFORMAT, "%s: %c scale %g (offset %d) or offset %g (offset "
                           "%d) is zero or not finite", path, "xyz"[k], h->scale[k], 131 + 8 * k,
                           h->offset[k], 155 + 8 * k);
    }
    if (h->count == 0)
        return sd_errf(err, SD_EEMPTY, "%s: the header declares 0 points (offset %d)", path,
                       h->minor == 4 ? 247 : 107);
    /* Every record must be in the file before anything is allocated for it. */
    uint64_t avail = (uint64_t)size - h->data_off;
    if (h->count > avail / h->rec_len)
        return sd_errf(err, SD_ETRUNC, "%s: the header declares %llu points of %u bytes from "
                       "offset %u, but the file has only %zu bytes (room for %llu points)", path,
                       (unsigned long long)h->count, h->rec_len, h->data_off, size,
                       (unsigned long long)(avail / h->rec_len));
    return 0;
}

/* What the guarded part of pc_read_las works on (it allocates nothing but raw's arrays). */
typedef struct las_job {
    const char *path;
    const pc__file *f;
    pc_raw *raw;
    sd_err *err;
} las_job;

/* las_parse: the header and the point records of the file mapped in j->f, into j->raw. */
static int las_parse(void *arg)
{
    las_job *j = arg;
    const char *path = j->path;
    const pc__file *fp = j->f;
    pc__file file = *fp;
    pc_raw *raw = j->raw;
    sd_err *err = j->err;
    las_header h = {0};
    int rc = parse_header(path, file.data, file.size, &h, err);
    if (rc) return rc;
    unsigned rgb = las_formats[h.format].rgb;
    raw->attrs = PC_ATTR_INTENSITY | PC_ATTR_CLASS | (rgb ? PC_ATTR_RGB : 0);
    rc = pc_raw_reserve(raw, (size_t)h.count, err);
    if (rc) return rc;

    const uint8_t *rec = file.data + h.data_off;
    size_t n = (size_t)h.count;
    /* LAS colours are 16-bit, but many writers store 8-bit values in them (autzen_trim.las
     * holds 0-236): scale down only when some value needs more than 8 bits. */
    unsigned cmax = 0;
    if (rgb)
        for (size_t i = 0; i < n; i++) {
            const uint8_t *c = rec + i * h.rec_len + rgb;
            for (int k = 0; k < 3; k++) {
                unsigned v = rd16(c + 2 * k);
                if (v > cmax) cmax = v;
            }
        }
    int wide = cmax > 255;
    int new_layout = h.format >= 6;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = rec + i * h.rec_len;
        double *xyz = raw->xyz + 3 * i;
        for (int k = 0; k < 3; k++) xyz[k] = rdi32(p + 4 * k) * h.scale[k] + h.offset[k];
        raw->intensity[i] = rd16(p + 12);
        raw->cls[i] = new_layout ? p[16] : (uint8_t)(p[15] & 31);
        if (rgb) {
            uint8_t *c = raw->rgba + 4 * i;
            for (int k = 0; k < 3; k++) {
                unsigned v = rd16(p + rgb + 2 * k);
                c[k] = (uint8_t)(wide ? (v + 128) / 257 : v);
            }
            c[3] = 255;
        }
    }
    raw->n = n;
    snprintf(raw->format, sizeof raw->format, "LAS 1.%u format %u", h.minor, h.format);
    return 0;
}

int pc_read_las(const char *path, pc_raw *raw, sd_err *err)
{
    pc__file file;
    int rc = pc__file_open(path, &file, err);
    if (rc) return rc;
    las_job j = {.path = path, .f = &file, .raw = raw, .err = err};
    rc = pc__guarded(&file, path, las_parse, &j, err);
    pc__file_close(&file);
    return rc;
}
