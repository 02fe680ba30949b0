/* laz.c — the LAZ file structure: laszip VLR, chunk table, chunk decoding (laz.h). */
#include "laz.h"

#include "laz_arith.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define VLR_HEADER 54u
#define LASZIP_RECORD 22204u
#define COPC_INFO_SIZE 160u

/* name16: 1 when the 16-byte NUL-padded user id at p is exactly s. */
static int name16(const uint8_t *p, const char *s)
{
    size_t n = strlen(s);
    if (memcmp(p, s, n) != 0) return 0;
    for (size_t i = n; i < 16; i++)
        if (p[i] != 0) return 0;
    return 1;
}

/* find_vlrs: the laszip VLR (required) and the COPC info VLR (optional) among the VLRs between
 * the header and the point data. */
static int find_vlrs(laz_file *lf, const uint8_t **laszip, uint16_t *laszip_len, sd_err *err)
{
    const las_header *h = &lf->h;
    uint64_t off = h->header_size;
    *laszip = NULL;
    for (uint32_t i = 0; i < h->nvlr; i++) {
        if (off + VLR_HEADER > h->data_off)
            return sd_errf(err, SD_EFORMAT, "%s: VLR %u of %u at offset %llu runs past the point "
                           "data at offset %u", lf->path, i, h->nvlr, (unsigned long long)off,
                           h->data_off);
        const uint8_t *v = lf->data + off;
        uint16_t rid = rd16(v + 18), len = rd16(v + 20);
        if (off + VLR_HEADER + len > h->data_off)
            return sd_errf(err, SD_EFORMAT, "%s: VLR %u at offset %llu declares %u bytes, past "
                           "the point data at offset %u", lf->path, i, (unsigned long long)off,
                           len, h->data_off);
        if (name16(v + 2, "laszip encoded") && rid == LASZIP_RECORD) {
            *laszip = v + VLR_HEADER;
            *laszip_len = len;
        } else if (name16(v + 2, "copc") && rid == 1 && len >= COPC_INFO_SIZE) {
            lf->copc_info = v + VLR_HEADER;
        }
        off += VLR_HEADER + len;
    }
    if (!*laszip)
        return sd_errf(err, SD_EFORMAT, "%s: the point format byte (offset 104) marks LAZ "
                       "compression but none of the %u VLRs is the 'laszip encoded' record "
                       "%u", lf->path, h->nvlr, LASZIP_RECORD);
    return 0;
}

static int parse_laszip(laz_file *lf, const uint8_t *v, uint16_t len, sd_err *err)
{
    if (len < 34)
        return sd_errf(err, SD_EFORMAT, "%s: the laszip VLR holds %u bytes, fewer than its "
                       "34-byte fixed part", lf->path, len);
    lf->compressor = rd16(v);
    unsigned coder = rd16(v + 2);
    lf->chunk_size = rd32(v + 12);
    unsigned nitems = rd16(v + 32);
    if (coder != 0)
        return sd_errf(err, SD_EUNSUP, "%s: laszip coder %u is not supported (only 0, "
                       "arithmetic)", lf->path, coder);
    if (lf->compressor == 1)
        return sd_errf(err, SD_EUNSUP, "%s: unchunked LAZ (laszip compressor 1, written by "
                       "LASzip before 2.0) is not supported; recompress it with a current "
                       "laszip", lf->path);
    if (nitems == 0 || nitems > LAZ_MAX_ITEMS || 34u + 6u * nitems > len)
        return sd_errf(err, SD_EFORMAT, "%s: the laszip VLR lists %u items (1 to %d in %u "
                       "bytes)", lf->path, nitems, LAZ_MAX_ITEMS, len);
    lf->nitems = nitems;
    unsigned sum = 0;
    for (unsigned i = 0; i < nitems; i++) {
        const uint8_t *it = v + 34 + 6 * i;
        lf->items[i] = (laz_item){rd16(it), rd16(it + 2), rd16(it + 4)};
        sum += lf->items[i].size;
    }
    const char *why = NULL;
    if (laz_items_check(lf->items, nitems, lf->compressor, &why))
        return sd_errf(err, SD_EUNSUP, "%s: laszip VLR (compressor %u): %s", lf->path,
                       lf->compressor, why);
    if (sum != lf->h.rec_len)
        return sd_errf(err, SD_EFORMAT, "%s: the laszip items add up to %u bytes per point, "
                       "the header's record length (offset 105) is %u", lf->path, sum,
                       lf->h.rec_len);
    if (lf->chunk_size == 0)
        return sd_errf(err, SD_EFORMAT, "%s: the laszip VLR gives a chunk size of 0 points",
                       lf->path);
    return 0;
}

/* read_chunk_table: fills chunk_start / chunk_first from the table (see laz.h). */
static int read_chunk_table(laz_file *lf, sd_err *err)
{
    const las_header *h = &lf->h;
    const char *path = lf->path;
    uint64_t first = (uint64_t)h->data_off + 8;
    if (first > lf->size)
        return sd_errf(err, SD_ETRUNC, "%s: the file ends at %zu, before the 8-byte chunk "
                       "table offset at the point data (offset %u)", path, lf->size,
                       h->data_off);
    uint64_t table = rd64(lf->data + h->data_off);
    if (table == UINT64_MAX && lf->size >= 8) table = rd64(lf->data + lf->size - 8);
    if (table < first || table > lf->size || lf->size - table < 8)
        return sd_errf(err, SD_EFORMAT, "%s: the chunk table offset %llu (stored at offset %u) "
                       "is outside the file's %zu bytes after the point data", path,
                       (unsigned long long)table, h->data_off, lf->size);
    uint32_t version = rd32(lf->data + table), n = rd32(lf->data + table + 4);
    if (version != 0)
        return sd_errf(err, SD_EUNSUP, "%s: chunk table version %u at offset %llu (only 0)",
                       path, version, (unsigned long long)table);
    /* each chunk holds at least its raw first point */
    uint64_t room = (table - first) / h->rec_len;
    if (n == 0 || n > room || n > h->count)
        return sd_errf(err, SD_EFORMAT, "%s: the chunk table at offset %llu declares %u chunks; "
                       "the %llu bytes of chunks hold at most %llu and the header declares "
                       "%llu points", path, (unsigned long long)table, n,
                       (unsigned long long)(table - first), (unsigned long long)room,
                       (unsigned long long)h->count);
    int variable = lf->chunk_size == UINT32_MAX;
    if (!variable) {
        uint64_t want = (h->count + lf->chunk_size - 1) / lf->chunk_size;
        if (want != n)
            return sd_errf(err, SD_EFORMAT, "%s: %llu points in chunks of %u need %llu chunks; "
                           "the chunk table at offset %llu declares %u", path,
                           (unsigned long long)h->count, lf->chunk_size,
                           (unsigned long long)want, (unsigned long long)table, n);
    }
    lf->chunk_start = malloc(sizeof(uint64_t) * ((size_t)n + 1));
    lf->chunk_first = malloc(sizeof(uint64_t) * ((size_t)n + 1));
    if (!lf->chunk_start || !lf->chunk_first)
        return sd_errf(err, SD_ENOMEM, "%s: no memory for a chunk table of %u chunks", path, n);
    lf->nchunks = n;
    const uint8_t *tend = lf->data + lf->size;
    if (h->nevlr && h->evlr_off > table + 8 && h->evlr_off <= lf->size)
        tend = lf->data + h->evlr_off;
    laz_dec d;
    laz_ic ic;
    if (laz_ic_create(&ic, 32, 2) || laz_ic_init(&ic)) {
        laz_ic_free(&ic);
        return sd_errf(err, SD_ENOMEM, "%s: no memory for the chunk table decoder", path);
    }
    laz_dec_init(&d, lf->data + table + 8, tend);
    int32_t prev_pts = 0, prev_bytes = 0;
    uint64_t pos = first, pts = 0;
    int rc = 0;
    for (uint32_t i = 0; i < n && !rc; i++) {
        uint64_t cp;
        if (variable) {
            prev_pts = laz_ic_decompress(&ic, &d, prev_pts, 0);
            cp = (uint32_t)prev_pts;
        } else {
            cp = i + 1 < n ? lf->chunk_size : h->count - (uint64_t)lf->chunk_size * (n - 1);
        }
        prev_bytes = laz_ic_decompress(&ic, &d, prev_bytes, 1);
        uint64_t cb = (uint32_t)prev_bytes;
        lf->chunk_start[i] = pos;
        lf->chunk_first[i] = pts;
        if (d.overrun)
            rc = sd_errf(err, SD_ETRUNC, "%s: the chunk table at offset %llu ends before the "
                         "entry of chunk %u of %u", path, (unsigned long long)table, i, n);
        else if (cp == 0 || cb > table - pos)
            rc = sd_errf(err, SD_EFORMAT, "%s: chunk %u of %u (at offset %llu) declares %llu "
                         "points in %llu bytes, past the chunk table at offset %llu", path, i,
                         n, (unsigned long long)pos, (unsigned long long)cp,
                         (unsigned long long)cb, (unsigned long long)table);
        else if (cp > 1 + cb * LAZ_MAX_POINTS_PER_BYTE)
            rc = sd_errf(err, SD_EFORMAT, "%s: chunk %u of %u (at offset %llu) declares %llu "
                         "points in %llu bytes, more than the coder can hold", path, i, n,
                         (unsigned long long)pos, (unsigned long long)cp,
                         (unsigned long long)cb);
        pos += cb;
        pts += cp;
    }
    laz_ic_free(&ic);
    if (rc) return rc;
    lf->chunk_start[n] = pos;
    lf->chunk_first[n] = pts;
    if (pts != h->count)
        return sd_errf(err, SD_EFORMAT, "%s: the chunk table at offset %llu adds up to %llu "
                       "points, the header declares %llu", path, (unsigned long long)table,
                       (unsigned long long)pts, (unsigned long long)h->count);
    return 0;
}

int laz_open(laz_file *lf, const char *path, const uint8_t *data, size_t size, sd_err *err)
{
    memset(lf, 0, sizeof *lf);
    lf->path = path;
    lf->data = data;
    lf->size = size;
    int rc = pc__las_header(path, data, size, &lf->h, err);
    if (rc) goto fail;
    if (!lf->h.compressed) {
        rc = sd_errf(err, SD_EUNSUP, "%s: not compressed (the point format byte at offset 104 "
                     "has no LAZ bits): read it as .las", path);
        goto fail;
    }
    unsigned f = lf->h.format;
    if (f == 4 || f == 5 || f == 9 || f == 10) {
        rc = sd_errf(err, SD_EUNSUP, "%s: point format %u carries waveform packets: LAZ with "
                     "waveforms (formats 4, 5, 9, 10) is not supported", path, f);
        goto fail;
    }
    const uint8_t *v;
    uint16_t vlen = 0;
    if ((rc = find_vlrs(lf, &v, &vlen, err)) || (rc = parse_laszip(lf, v, vlen, err))) goto fail;
    if ((f >= 6) != (lf->compressor == 3)) {
        rc = sd_errf(err, SD_EFORMAT, "%s: point format %u with laszip compressor %u (formats "
                     "0-5 are pointwise, 2; 6-10 layered, 3)", path, f, lf->compressor);
        goto fail;
    }
    if ((rc = read_chunk_table(lf, err))) goto fail;
    return 0;
fail:
    laz_close(lf);
    return rc;
}

void laz_close(laz_file *lf)
{
    free(lf->chunk_start);
    free(lf->chunk_first);
    memset(lf, 0, sizeof *lf);
}

static const char *chunk_reason(int code)
{
    switch (code) {
    case LAZ_CHUNK_SHORT: return "its compressed bytes end before its points do (truncated or "
                                 "corrupt)";
    case LAZ_CHUNK_COUNT: return "the point count stored in the chunk differs from the chunk "
                                 "table's";
    case LAZ_CHUNK_LAYERS: return "its layer sizes add up to more than the chunk's bytes";
    default: return "out of memory";
    }
}

int laz_read_span(const laz_file *lf, laz_chunk_dec *cd, uint64_t off, uint64_t bytes,
                  uint64_t npts, const char *label, uint8_t **buf, size_t *cap, sd_err *err)
{
    const size_t rl = lf->h.rec_len;
    if (off > lf->size || bytes > lf->size - off)
        return sd_errf(err, SD_ETRUNC, "%s: %s at offset %llu (%llu bytes) runs past the end of "
                       "the file (%zu bytes)", lf->path, label, (unsigned long long)off,
                       (unsigned long long)bytes, lf->size);
    if (npts == 0) return 0;
    if (npts > 1 + bytes * LAZ_MAX_POINTS_PER_BYTE)
        return sd_errf(err, SD_EFORMAT, "%s: %s declares %llu points in %llu bytes, more than "
                       "the coder can hold", lf->path, label, (unsigned long long)npts,
                       (unsigned long long)bytes);
    const uint8_t *p = lf->data + off, *end = p + bytes;
    const char *what = "points";
    size_t done = 0;
    int rc = 0;
    while (done < npts) {
        /* grow in steps: the buffer only ever holds what decoded plus one step */
        size_t step = npts - done < 65536 ? (size_t)(npts - done) : 65536;
        if ((done + step) * rl > *cap) {
            size_t want = *cap ? *cap : 65536 * rl;
            while (want < (done + step) * rl) want *= 2;
            if (want > npts * rl) want = npts * rl;
            uint8_t *nb = realloc(*buf, want);
            if (!nb)
                return sd_errf(err, SD_ENOMEM, "%s: %s: no memory for %zu points", lf->path,
                               label, done + step);
            *buf = nb;
            *cap = want;
        }
        if (done == 0) {
            rc = laz_chunk_begin(cd, p, end, npts, *buf, &what);
            if (!rc && step > 1) rc = laz_chunk_next(cd, step - 1, *buf + rl, &what);
        } else {
            rc = laz_chunk_next(cd, step, *buf + done * rl, &what);
        }
        if (rc)
            return sd_errf(err, rc == LAZ_CHUNK_NOMEM ? SD_ENOMEM : SD_EFORMAT,
                           "%s: %s (offset %llu, %llu bytes, %llu points): %s: %s", lf->path,
                           label, (unsigned long long)off, (unsigned long long)bytes,
                           (unsigned long long)npts, what, chunk_reason(rc));
        done += step;
    }
    return 0;
}

int laz_read_chunk(const laz_file *lf, laz_chunk_dec *cd, size_t i, uint8_t **buf, size_t *cap,
                   sd_err *err)
{
    char label[48];
    snprintf(label, sizeof label, "chunk %zu of %zu", i, lf->nchunks);
    return laz_read_span(lf, cd, lf->chunk_start[i], lf->chunk_start[i + 1] - lf->chunk_start[i],
                         lf->chunk_first[i + 1] - lf->chunk_first[i], label, buf, cap, err);
}
