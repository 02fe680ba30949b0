/* las_header.c — the LAS public header (shared by the LAS and LAZ readers) and the conversion
 * of point records into the raw cloud. See las_header.h. */
#include "las_header.h"

#include <math.h>
#include <string.h>

#define LAS_HEADER_MIN 227u /* LAS 1.0-1.2 public header; 1.3 adds 8 bytes, 1.4 adds 148 */

const pc__las_format pc__las_formats[11] = {
    {20, 0}, {28, 0}, {26, 20}, {34, 28}, {57, 0}, {63, 28},
    {30, 0}, {36, 30}, {38, 30}, {59, 0}, {67, 30},
};

/* Checks the public header of a file of size bytes and fills h. Returns 0 or a negative code
 * whose message names the offending field's byte offset. */
int pc__las_header(const char *path, const uint8_t *d, size_t size, las_header *h, sd_err *err)
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
    /* Bits 6 and 7 mark LASzip compression (LAZ); the point records follow a chunk table. */
    h->compressed = (fmt & 0xC0) != 0;
    fmt &= 0x3F;
    if (fmt > 10)
        return sd_errf(err, SD_EUNSUP, "%s: point data format %u at offset 104 is not supported "
                       "(0 to 10)", path, fmt);
    h->format = fmt;
    if (h->rec_len < pc__las_formats[fmt].len)
        return sd_errf(err, SD_EFORMAT, "%s: point record length %u at offset 105 is shorter "
                       "than the %u bytes of point format %u", path, h->rec_len,
                       pc__las_formats[fmt].len, fmt);
    h->count = rd32(d + 107);
    if (h->count == 0 && h->minor == 4) h->count = rd64(d + 247);
    h->nvlr = rd32(d + 100);
    if (h->minor == 4) {
        h->evlr_off = rd64(d + 235);
        h->nevlr = rd32(d + 243);
    }
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
    if (h->compressed) return 0; /* the LAZ reader bounds the count by its chunk table */
    /* Every record must be in the file before anything is allocated for it. */
    uint64_t avail = (uint64_t)size - h->data_off;
    if (h->count > avail / h->rec_len)
        return sd_errf(err, SD_ETRUNC, "%s: the header declares %llu points of %u bytes from "
                       "offset %u, but the file has only %zu bytes (room for %llu points)", path,
                       (unsigned long long)h->count, h->rec_len, h->data_off, size,
                       (unsigned long long)(avail / h->rec_len));
    return 0;
}


void pc__las_convert(const las_header *h, const uint8_t *rec, size_t n, pc_raw *raw, size_t at,
                     int wide, uint16_t *rgb16)
{
    unsigned rgb = pc__las_formats[h->format].rgb;
    int new_layout = h->format >= 6;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = rec + i * h->rec_len;
        size_t j = at + i;
        double *xyz = raw->xyz + 3 * j;
        for (int k = 0; k < 3; k++) xyz[k] = rdi32(p + 4 * k) * h->scale[k] + h->offset[k];
        raw->intensity[j] = rd16(p + 12);
        raw->cls[j] = new_layout ? p[16] : (uint8_t)(p[15] & 31);
        if (!rgb) continue;
        if (rgb16) {
            for (int k = 0; k < 3; k++) rgb16[3 * j + k] = rd16(p + rgb + 2 * k);
            continue;
        }
        uint8_t *c = raw->rgba + 4 * j;
        for (int k = 0; k < 3; k++) {
            unsigned v = rd16(p + rgb + 2 * k);
            c[k] = (uint8_t)(wide ? (v + 128) / 257 : v);
        }
        c[3] = 255;
    }
}

int pc__las_rgb16_wide(const uint16_t *rgb16, size_t n)
{
    unsigned cmax = 0;
    for (size_t i = 0; i < 3 * n; i++)
        if (rgb16[i] > cmax) cmax = rgb16[i];
    return cmax > 255;
}

void pc__las_rgb16_range(const uint16_t *rgb16, size_t lo, size_t hi, int wide, pc_raw *raw)
{
    for (size_t i = lo; i < hi; i++) {
        uint8_t *c = raw->rgba + 4 * i;
        for (int k = 0; k < 3; k++) {
            unsigned v = rgb16[3 * i + k];
            c[k] = (uint8_t)(wide ? (v + 128) / 257 : v);
        }
        c[3] = 255;
    }
}

void pc__las_rgb16(const uint16_t *rgb16, size_t n, pc_raw *raw)
{
    pc__las_rgb16_range(rgb16, 0, n, pc__las_rgb16_wide(rgb16, n), raw);
}
