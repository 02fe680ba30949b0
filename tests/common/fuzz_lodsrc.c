/* fuzz_lodsrc.c — the body of the lodsrc fuzz target (fuzz_targets.h): the LOD build's point
 * stream (server/prep/lod_src.h) on arbitrary files, its own PLY header parser and the
 * LAS/LAZ/PCD/XYZ streams, checked against pc_load, which lod_src.h says it agrees with point
 * for point. */
#include "fuzz_targets.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cloud.h"
#include "lod_src.h"
#include "sd_err.h"

/* The extensions byte 0 picks from (the streams choose by extension, as pc_load does). */
static const char *const exts[8] = {".ply", ".las", ".laz", ".pcd", ".xyz", ".pts", ".txt",
                                    ".copc.laz"};

/* One pass of the stream: every point in pieces of at most `piece`, with hashes of the
 * positions' and the colours' bits (each over the whole pass, whatever the pieces). */
typedef struct pass {
    uint64_t n, hpos, hrgba;   /* FNV-1a of every position's bits, of every colour's */
    float *pos;      /* all positions (3 n), kept on the first pass for the comparison */
    uint32_t *rgba;
} pass;

static uint64_t fnv(uint64_t h, const void *p, size_t n)
{
    const uint8_t *b = p;
    for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* stream_all: reads s to its end into p (keep: also into p->pos / p->rgba, room for cap
 * points). Returns 0 or the stream's negative code (err filled). */
static int stream_all(lod_src *s, size_t piece, size_t cap, int keep, pass *p, sd_err *err)
{
    float *pos = malloc(piece * 3 * sizeof *pos);
    uint32_t *rgba = malloc(piece * sizeof *rgba);
    if (!pos || !rgba) abort();
    p->n = 0;
    p->hpos = p->hrgba = 1469598103934665603ull;
    int rc = 0;
    for (;;) {
        int64_t m = lod_src_next(s, pos, rgba, piece, err);
        if (m < 0) {
            rc = (int)m;
            break;
        }
        if ((uint64_t)m > piece) fuzz_fail("lodsrc", "lod_src_next gave %lld of %zu points",
                                           (long long)m, piece);
        if (m == 0) break;
        if (p->n + (uint64_t)m > cap)
            fuzz_fail("lodsrc", "the stream gives more than the %zu points its info says",
                      cap);
        p->hpos = fnv(p->hpos, pos, (size_t)m * 12);
        p->hrgba = fnv(p->hrgba, rgba, (size_t)m * 4);
        if (keep) {
            memcpy(p->pos + 3 * p->n, pos, (size_t)m * 12);
            memcpy(p->rgba + p->n, rgba, (size_t)m * 4);
        }
        p->n += (uint64_t)m;
    }
    free(pos);
    free(rgba);
    return rc;
}

/* check_against_load: what pc_load reads of path is what the stream gave (p, info). */
static void check_against_load(const char *path, const lod_src_info *in, const pass *p)
{
    pc_cloud c;
    memset(&c, 0, sizeof c);
    sd_err err = {0};
    int rc = pc_load(path, &c, &err);
    if (rc != 0)
        fuzz_fail("lodsrc", "the stream read %llu points (%s) but pc_load refuses the file: %s",
                  (unsigned long long)p->n, in->format, err.msg);
    if (c.n != p->n || c.n_dropped != in->n_dropped)
        fuzz_fail("lodsrc", "%s: the stream has %llu points (%llu dropped), pc_load %zu (%llu)",
                  in->format, (unsigned long long)p->n, (unsigned long long)in->n_dropped, c.n,
                  (unsigned long long)c.n_dropped);
    for (int a = 0; a < 3; a++)
        if (memcmp(&c.offset[a], &in->offset[a], sizeof(double)) != 0 ||
            memcmp(&c.bmin[a], &in->bmin[a], sizeof(double)) != 0 ||
            memcmp(&c.bmax[a], &in->bmax[a], sizeof(double)) != 0)
            fuzz_fail("lodsrc", "%s: axis %d: the stream's box [%g, %g] offset %g, pc_load's "
                      "[%g, %g] offset %g", in->format, a, in->bmin[a], in->bmax[a],
                      in->offset[a], c.bmin[a], c.bmax[a], c.offset[a]);
    if ((c.attrs & PC_ATTR_RGB) != (in->attrs & PC_ATTR_RGB))
        fuzz_fail("lodsrc", "%s: colours: the stream says %d, pc_load %d", in->format,
                  !!(in->attrs & PC_ATTR_RGB), !!(c.attrs & PC_ATTR_RGB));
    for (size_t i = 0; i < c.n; i++) {
        if (memcmp(c.pos + 3 * i, p->pos + 3 * i, 12) != 0)
            fuzz_fail("lodsrc", "%s: point %zu is (%g %g %g) in the stream, (%g %g %g) by "
                      "pc_load", in->format, i, (double)p->pos[3 * i], (double)p->pos[3 * i + 1],
                      (double)p->pos[3 * i + 2], (double)c.pos[3 * i], (double)c.pos[3 * i + 1],
                      (double)c.pos[3 * i + 2]);
        uint32_t want = 0xFFFFFFFFu;
        if (c.attrs & PC_ATTR_RGB) memcpy(&want, c.rgba + 4 * i, 4);
        if (p->rgba[i] != want)
            fuzz_fail("lodsrc", "%s: point %zu has colour %08x in the stream, %08x by pc_load",
                      in->format, i, p->rgba[i], want);
    }
    pc_cloud_free(&c);
}

int fuzz_one_lodsrc(const uint8_t *data, size_t len)
{
    if (len < 1) return SD_EINVAL;
    char dir[512], path[600];
    fuzz_mkdtemp(dir, sizeof dir, "lodsrc");
    snprintf(path, sizeof path, "%s/f%s", dir, exts[data[0] & 7]);
    /* the piece size: 1 to 8191 points, so that pieces end inside blocks and at their ends */
    size_t piece = 1 + ((size_t)(data[0] >> 3) * 331) % 8191;
    fuzz_write_file(path, data + 1, len - 1);
    lod_src *s = NULL;
    sd_err err = {0};
    int rc = lod_src_open(path, &s, &err);
    fuzz_check_sd_err(rc, &err, path, "lodsrc");
    if (rc == 0) {
        lod_src_info in;
        lod_src_get_info(s, &in);
        if (in.n == 0 || !in.format[0] || !memchr(in.format, 0, sizeof in.format))
            fuzz_fail("lodsrc", "opened with %llu points, format '%.64s'",
                      (unsigned long long)in.n, in.format);
        /* what the file's bytes can hold (as check_raw's bound) */
        if (in.n + in.n_dropped > 30 * (uint64_t)len + 64)
            fuzz_fail("lodsrc", "%llu points from a %zu-byte file", (unsigned long long)in.n, len);
        for (int a = 0; a < 3; a++)
            if (!isfinite(in.offset[a]) || !(in.bmin[a] <= in.bmax[a]))
                fuzz_fail("lodsrc", "axis %d: box [%g, %g], offset %g", a, in.bmin[a],
                          in.bmax[a], in.offset[a]);
        pass p1 = {0}, p2 = {0};
        p1.pos = malloc((size_t)in.n * 12 + 12);
        p1.rgba = malloc((size_t)in.n * 4 + 4);
        if (!p1.pos || !p1.rgba) abort();
        rc = stream_all(s, piece, (size_t)in.n, 1, &p1, &err);
        fuzz_check_sd_err(rc, &err, path, "lodsrc");
        if (rc == 0 && p1.n != in.n)
            fuzz_fail("lodsrc", "%s: the stream gave %llu points, its info says %llu", in.format,
                      (unsigned long long)p1.n, (unsigned long long)in.n);
        if (rc == 0) {
            /* the points lie in the box: float(x - offset) + offset within a float's step */
            for (uint64_t i = 0; i < p1.n; i++)
                for (int a = 0; a < 3; a++) {
                    double x = (double)p1.pos[3 * i + a] + in.offset[a];
                    double slack = 1e-6 * (fabs(in.bmax[a] - in.bmin[a]) + fabs(in.offset[a])) +
                                   FLT_TRUE_MIN; /* a float's rounding, denormals included */
                    if (!isfinite(p1.pos[3 * i + a]) || x < in.bmin[a] - slack ||
                        x > in.bmax[a] + slack)
                        fuzz_fail("lodsrc", "%s: point %llu axis %d at %g, outside [%g, %g]",
                                  in.format, (unsigned long long)i, a, x, in.bmin[a],
                                  in.bmax[a]);
                }
            /* a second pass after a rewind gives the same points */
            rc = lod_src_rewind(s, &err);
            if (rc == 0) rc = stream_all(s, piece == 1 ? 8191 : piece - 1, (size_t)in.n, 0, &p2,
                                         &err);
            fuzz_check_sd_err(rc, &err, path, "lodsrc");
            if (rc == 0 && (p2.n != p1.n || p2.hpos != p1.hpos || p2.hrgba != p1.hrgba))
                fuzz_fail("lodsrc", "%s: after a rewind %llu points (%llu before) or other bits",
                          in.format, (unsigned long long)p2.n, (unsigned long long)p1.n);
        }
        if (rc == 0) check_against_load(path, &in, &p1);
        free(p1.pos);
        free(p1.rgba);
        lod_src_close(s);
    }
    unlink(path);
    rmdir(dir);
    return rc;
}
