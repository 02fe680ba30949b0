/* io_e57.c — the E57 reader (ASTM E2807): every scan of the file into one raw cloud, through
 * the point stream of e57_stream.h (pose applied, invalid points dropped, colours and
 * intensities normalised by their limits, the scan index when there are several scans).
 * The arrays are reserved for what the file can hold (pc_e57_stream_bound), never for what
 * the XML merely claims, and filled a batch at a time. */
#include "cloud.h"
#include "e57_stream.h"

#include <stdio.h>
#include <string.h>

enum { STEP = 1 << 16 };

int pc_read_e57(const char *path, pc_raw *raw, sd_err *err)
{
    pc_e57_stream *s;
    int rc = pc_e57_stream_open(path, &s, err);
    if (rc == 0)
        return sd_errf(err, SD_EFORMAT,
                       "%s: not an E57 file: it does not start with the "
                       "signature 'ASTM-E57'",
                       path);
    if (rc < 0) return rc;
    raw->attrs = pc_e57_stream_attrs(s);
    snprintf(raw->format, sizeof raw->format, "%s", pc_e57_stream_format(s));
    uint64_t bound = pc_e57_stream_bound(s);
    rc = bound > SIZE_MAX / 64 ? sd_errf(err, SD_ELIMIT,
                                         "%s: %llu points is over this "
                                         "machine's limit",
                                         path, (unsigned long long)bound)
                               : pc_raw_reserve(raw, (size_t)bound, err);
    while (rc == 0) {
        size_t room = raw->cap - raw->n;
        if (room == 0) break; /* the bound is reached: the stream has no more */
        size_t n = raw->n;
        pc_e57_points o = {
            .xyz = raw->xyz + 3 * n,
            .rgba = raw->rgba ? raw->rgba + 4 * n : NULL,
            .intensity = raw->intensity ? raw->intensity + n : NULL,
            .normal = raw->normal ? raw->normal + 3 * n : NULL,
            .scan = raw->scan ? raw->scan + n : NULL,
        };
        int64_t m = pc_e57_stream_next(s, &o, room < STEP ? room : STEP, err);
        if (m < 0) rc = (int)m;
        if (m <= 0) break;
        raw->n += (size_t)m;
    }
    if (rc == 0 && raw->n == 0) {
        uint32_t ns = pc_e57_stream_scans(s);
        uint64_t nr = pc_e57_stream_records(s);
        rc = sd_errf(err, SD_EEMPTY, "%s: no points: %u scan%s, %llu records in all%s", path, ns,
                     ns == 1 ? "" : "s", (unsigned long long)nr,
                     nr ? ", every one of them invalid" : "");
    }
    pc_e57_stream_close(s);
    return rc;
}
