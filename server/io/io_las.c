/* io_las.c — the LAS reader (ASPRS LAS 1.0 to 1.4, uncompressed, point data formats 0 to 10).
 *
 * The public header is read by las_header.c. A file whose format byte marks LASzip compression
 * goes to the LAZ reader whatever its extension.
 * Each point record starts with X Y Z as int32 (coordinate = X * scale + offset) and a u16
 * intensity. Formats 0-5 keep the class in the low 5 bits of byte 15; formats 6-10 in all of
 * byte 16. RGB (3 x u16) follows the GPS time in formats 2, 3, 5 and sits at byte 30 in 7, 8
 * and 10. Records may be longer than their format needs (extra bytes); they are skipped. */
#include "cloud.h"
#include "io_text.h"
#include "las_header.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* What the guarded part of pc_read_las works on (it allocates nothing but raw's arrays). */
typedef struct las_job {
    const char *path;
    const pc__file *f;
    pc_raw *raw;
    sd_err *err;
    int is_laz;
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
    int rc = pc__las_header(path, file.data, file.size, &h, err);
    if (rc) return rc;
    if (h.compressed) {
        j->is_laz = 1; /* read by the LAZ reader once this guard is left */
        return 0;
    }
    unsigned rgb = pc__las_formats[h.format].rgb;
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
    pc__las_convert(&h, rec, n, raw, 0, wide, NULL);
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
    if (!rc && j.is_laz) return pc_read_laz(path, raw, err);
    return rc;
}
