/* lod_src.c — the LOD build's point stream (lod_src.h). */
#include "lod_src.h"

#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cloud.h"
#include "e57_stream.h"
#include "las_stream.h"
#include "laz_stream.h"
#include "pcd_stream.h"
#include "ply_stream.h"
#include "progress.h"
#include "xyz_stream.h"

enum { BLOCK = 1 << 16 };
enum { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 }; /* ply_stream.h's types */

struct lod_src {
    char path[4096];
    lod_src_info info;
    /* streamed PLY */
    int fd;
    uint64_t data_off, nrec, rec, next;  /* next record */
    int off[7], type[7];                 /* x y z red green blue alpha: offset, type */
    double cscale[7];                    /* colours: factor to 0..255 (ply_stream.h) */
    uint8_t *buf;
    /* streamed LAS: uncompressed (las) or LAZ and COPC (laz), as coordinates and 16-bit colours */
    pc_las_stream *las;
    pc_laz_stream *laz;
    /* streamed XYZ/PTS text (xyz), PCD (pcd) or E57 (e57, scan by scan, a batch of records at a
     * time): coordinates in las_xyz, colours as RGBA8 */
    pc_xyz_stream *xyz;
    pc_pcd_stream *pcd;
    pc_e57_stream *e57;
    uint8_t *xyz_rgba;
    int las_wide;                        /* colours scaled down from 16 bits (pc_read_las's rule) */
    double *las_xyz;
    uint16_t *las_rgb;
    /* in-memory fallback */
    pc_cloud cloud;
    int have_cloud;
};

static double load(const uint8_t *p, int t)
{
    switch (t) {
    case T_I8: return (int8_t)p[0];
    case T_U8: return p[0];
    case T_I16: { int16_t v; memcpy(&v, p, 2); return v; }
    case T_U16: { uint16_t v; memcpy(&v, p, 2); return v; }
    case T_I32: { int32_t v; memcpy(&v, p, 4); return v; }
    case T_U32: { uint32_t v; memcpy(&v, p, 4); return v; }
    case T_F32: { float v; memcpy(&v, p, 4); return v; }
    case T_F64: { double v; memcpy(&v, p, 8); return v; }
    default: return 0;
    }
}

static uint8_t colour8(double v)
{
    if (!(v > 0)) return 0;
    if (v >= 255) return 255;
    return (uint8_t)(v + 0.5);
}

/* try_ply_header: 1 when path is a binary little-endian PLY whose first element is the
 * vertex element of fixed-size records and pc_read_ply reads it (ply_stream.h; then s is set
 * up for streaming), 0 when it is something else (the fallback reads it), negative when
 * pc_read_ply refuses it (with its message). */
static int try_ply_header(lod_src *s, sd_err *err)
{
    pc_ply_stream sp;
    int rc = pc_ply_stream_plan(s->path, &sp, err);
    if (rc <= 0) return rc;
    s->data_off = sp.data_off;
    s->nrec = sp.count;
    s->rec = sp.rec;
    memcpy(s->off, sp.off, sizeof s->off);
    memcpy(s->type, sp.type, sizeof s->type);
    memcpy(s->cscale, sp.cscale, sizeof s->cscale);
    snprintf(s->info.format, sizeof s->info.format, "%s", sp.format);
    return 1;
}

/* read_records_into: records [r, r + m) into buf (pread: the file offset is not used, so
 * several threads may read at once). */
static int read_records_into(const lod_src *s, uint8_t *buf, uint64_t r, size_t m, sd_err *err)
{
    size_t len = m * s->rec, done = 0;
    while (done < len) {
        ssize_t g = pread(s->fd, buf + done, len - done,
                          (off_t)(s->data_off + r * s->rec + done));
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0)
            return sd_errf(err, SD_EIO, "%s: %s at byte %llu", s->path,
                           g < 0 ? strerror(errno) : "the file ended (it changed)",
                           (unsigned long long)(s->data_off + r * s->rec + done));
        done += (size_t)g;
    }
    return 0;
}

/* Reads records [r, r + m) into s->buf. */
static int read_records(lod_src *s, uint64_t r, size_t m, sd_err *err)
{
    return read_records_into(s, s->buf, r, m, err);
}

static void record_xyz(const lod_src *s, const uint8_t *p, double xyz[3])
{
    for (int a = 0; a < 3; a++) xyz[a] = load(p + s->off[a], s->type[a]);
}

/* 1 when x, y, z are floats and the colours (where present) bytes: the layout gen_cloud and
 * most tools write, decoded by plain loads (ply_block_f32) instead of per-field conversions. */
static int layout_f32_u8(const lod_src *s)
{
    for (int a = 0; a < 3; a++)
        if (s->type[a] != T_F32) return 0;
    for (int c = 3; c < 7; c++)
        if (s->off[c] >= 0 && s->type[c] != T_U8) return 0;
    return 1;
}

/* A record's float x, y, z in that layout (record_xyz's values, by plain loads). */
static void record_xyz_f32(const lod_src *s, const uint8_t *p, float xyz[3])
{
    for (int a = 0; a < 3; a++) memcpy(&xyz[a], p + s->off[a], 4);
}

/* The m records of buf in that layout into pos / rgba, the finite ones only, with the values
 * record_xyz and record_rgba give (a float widened to double is exact; a byte's colour8 is the
 * byte itself): the count of points. */
static size_t ply_block_f32(const lod_src *s, const uint8_t *buf, size_t m, float *pos,
                            uint32_t *rgba)
{
    const size_t rec = s->rec;
    const int rgb = s->off[3] >= 0 && s->off[4] >= 0 && s->off[5] >= 0, oa = s->off[6];
    const double o0 = s->info.offset[0], o1 = s->info.offset[1], o2 = s->info.offset[2];
    size_t k = 0;
    for (size_t i = 0; i < m; i++) {
        const uint8_t *p = buf + i * rec;
        float v[3];
        record_xyz_f32(s, p, v);
        if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2])) continue;
        pos[3 * k] = (float)((double)v[0] - o0);
        pos[3 * k + 1] = (float)((double)v[1] - o1);
        pos[3 * k + 2] = (float)((double)v[2] - o2);
        rgba[k++] = !rgb ? 0xFFFFFFFFu
                         : (uint32_t)p[s->off[3]] | (uint32_t)p[s->off[4]] << 8 |
                               (uint32_t)p[s->off[5]] << 16 | (uint32_t)(oa >= 0 ? p[oa] : 255) << 24;
    }
    return k;
}

static uint32_t record_rgba(const lod_src *s, const uint8_t *p)
{
    if (s->off[3] < 0 || s->off[4] < 0 || s->off[5] < 0) return 0xFFFFFFFFu;
    uint32_t v = 0;
    for (int c = 0; c < 4; c++) {
        uint8_t x = 255;
        if (s->off[3 + c] >= 0)
            x = colour8(load(p + s->off[3 + c], s->type[3 + c]) * s->cscale[3 + c]);
        v |= (uint32_t)x << (8 * c);
    }
    return v;
}

/* set_bounds: the bounds of the finite points and the offset (pc_finalize's rule: the centre
 * of the box) into s->info; refuses a span float32 cannot hold. */
static int set_bounds(lod_src *s, const double lo[3], const double hi[3], sd_err *err)
{
    for (int a = 0; a < 3; a++) {
        if (!(0.5 * hi[a] - 0.5 * lo[a] <= FLT_MAX))
            return sd_errf(err, SD_ELIMIT, "%s: the points span %g along %c, more than float32 "
                           "holds", s->path, hi[a] - lo[a], "xyz"[a]);
        s->info.bmin[a] = lo[a];
        s->info.bmax[a] = hi[a];
        s->info.offset[a] = 0.5 * lo[a] + 0.5 * hi[a];
    }
    return 0;
}

/* The PLY bounds pass runs over blocks of records on every core (BOUNDS_THREADS at most), each
 * block's bounds and count kept apart and put together in block order: the same bounds as one
 * pass in file order, down to which of -0 and +0 an extreme is. */
enum { BOUNDS_THREADS = 8 };
typedef struct bounds_job {
    const lod_src *s;
    uint8_t *buf[BOUNDS_THREADS];  /* a block of records per thread */
    double *lo, *hi;               /* 3 per block */
    uint64_t *kept;                /* per block */
} bounds_job;

static int bounds_block(void *ctx, size_t c, int tid, sd_err *err)
{
    bounds_job *j = ctx;
    const lod_src *s = j->s;
    uint64_t r = (uint64_t)c * BLOCK;
    size_t m = s->nrec - r < BLOCK ? (size_t)(s->nrec - r) : BLOCK;
    int rc = read_records_into(s, j->buf[tid], r, m, err);
    if (rc < 0) return rc;
    double *lo = j->lo + 3 * c, *hi = j->hi + 3 * c;
    uint64_t kept = 0;
    for (int a = 0; a < 3; a++) lo[a] = INFINITY, hi[a] = -INFINITY;
    const int f32 = layout_f32_u8(s);
    for (size_t i = 0; i < m; i++) {
        double p[3];
        const uint8_t *rp = j->buf[tid] + i * s->rec;
        if (f32) {
            float v[3];
            record_xyz_f32(s, rp, v);
            for (int a = 0; a < 3; a++) p[a] = v[a];
        } else {
            record_xyz(s, rp, p);
        }
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) continue;
        kept++;
        for (int a = 0; a < 3; a++) {
            if (p[a] < lo[a]) lo[a] = p[a];
            if (p[a] > hi[a]) hi[a] = p[a];
        }
    }
    j->kept[c] = kept;
    return 0;
}

static int bounds_pass(lod_src *s, sd_err *err)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    uint64_t kept = 0;
    /* nrec is at most what the file holds (ply_header) */
    size_t nblocks = (size_t)((s->nrec + BLOCK - 1) / BLOCK);
    int nt = prep_default_threads();
    if (nt > BOUNDS_THREADS) nt = BOUNDS_THREADS;
    if ((size_t)nt > nblocks) nt = nblocks ? (int)nblocks : 1;
    bounds_job j = {.s = s};
    j.lo = malloc((nblocks ? nblocks : 1) * 3 * sizeof *j.lo);
    j.hi = malloc((nblocks ? nblocks : 1) * 3 * sizeof *j.hi);
    j.kept = malloc((nblocks ? nblocks : 1) * sizeof *j.kept);
    int ok = j.lo && j.hi && j.kept;
    for (int t = 0; t < nt && ok; t++) ok = (j.buf[t] = malloc((size_t)BLOCK * s->rec)) != NULL;
    int rc = ok ? prep_par_for(nt, nblocks, bounds_block, &j, NULL, err)
                : sd_errf(err, SD_ENOMEM, "%s: out of memory for the bounds pass", s->path);
    for (size_t c = 0; c < nblocks && rc == 0; c++) {
        kept += j.kept[c];
        for (int a = 0; a < 3; a++) {
            if (j.lo[3 * c + a] < lo[a]) lo[a] = j.lo[3 * c + a];
            if (j.hi[3 * c + a] > hi[a]) hi[a] = j.hi[3 * c + a];
        }
    }
    for (int t = 0; t < nt; t++) free(j.buf[t]);
    free(j.lo), free(j.hi), free(j.kept);
    if (rc < 0) return rc;
    if (!kept) return sd_errf(err, SD_EEMPTY, "%s: no finite points (%llu read)", s->path,
                              (unsigned long long)s->nrec);
    if ((rc = set_bounds(s, lo, hi, err)) < 0) return rc;
    s->info.n = kept;
    s->info.n_dropped = s->nrec - kept;
    s->info.attrs = s->off[3] >= 0 && s->off[4] >= 0 && s->off[5] >= 0 ? PC_ATTR_RGB : 0;
    s->info.streamed = 1;
    return 0;
}

/* The streamed LAS or LAZ file's records [first, first + m) as coordinates and colours. */
static int las_read(lod_src *s, uint64_t first, size_t m, int rgb, sd_err *err)
{
    uint16_t *c = rgb ? s->las_rgb : NULL;
    return s->las ? pc_las_stream_read(s->las, first, m, s->las_xyz, c, err)
                  : pc_laz_stream_read(s->laz, first, m, s->las_xyz, c, err);
}

static int las_has_rgb(const lod_src *s)
{
    return s->las ? pc_las_stream_has_rgb(s->las) : pc_laz_stream_has_rgb(s->laz);
}

/* las_bounds_pass: bounds, count and the colours' largest value of a streamed LAS or LAZ
 * file. */
static int las_bounds_pass(lod_src *s, sd_err *err)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    uint64_t n = s->las ? pc_las_stream_count(s->las) : pc_laz_stream_count(s->laz);
    int rgb = las_has_rgb(s);
    unsigned cmax = 0;
    for (uint64_t r = 0; r < n;) {
        size_t m = n - r < BLOCK ? (size_t)(n - r) : BLOCK;
        int rc = las_read(s, r, m, rgb, err);
        if (rc < 0) return rc;
        for (size_t i = 0; i < m; i++)
            for (int a = 0; a < 3; a++) {
                double v = s->las_xyz[3 * i + a];
                if (v < lo[a]) lo[a] = v;
                if (v > hi[a]) hi[a] = v;
            }
        if (rgb)
            for (size_t i = 0; i < 3 * m; i++)
                if (s->las_rgb[i] > cmax) cmax = s->las_rgb[i];
        r += m;
    }
    int rc = set_bounds(s, lo, hi, err);
    if (rc < 0) return rc;
    s->las_wide = cmax > 255;
    s->nrec = n;
    s->info.n = n; /* LAS coordinates are always finite */
    s->info.n_dropped = 0;
    s->info.attrs = rgb ? PC_ATTR_RGB : 0;
    snprintf(s->info.format, sizeof s->info.format, "%s",
             s->las ? pc_las_stream_format(s->las) : pc_laz_stream_format(s->laz));
    s->info.streamed = 1;
    return 0;
}

static int64_t las_next(lod_src *s, float *pos, uint32_t *rgba, size_t max, sd_err *err)
{
    size_t k = 0;
    int rgb = las_has_rgb(s);
    while (k < max && s->next < s->nrec) {
        size_t want = max - k < BLOCK ? max - k : BLOCK;
        size_t m = s->nrec - s->next < want ? (size_t)(s->nrec - s->next) : want;
        int rc = las_read(s, s->next, m, rgb, err);
        if (rc < 0) return rc;
        for (size_t i = 0; i < m; i++, k++) {
            for (int a = 0; a < 3; a++)
                pos[3 * k + a] = (float)(s->las_xyz[3 * i + a] - s->info.offset[a]);
            uint32_t v = 0xFFFFFFFFu;
            if (rgb) {
                v = 0xFF000000u;
                for (int c = 0; c < 3; c++) {
                    unsigned x = s->las_rgb[3 * i + c];
                    v |= (uint32_t)(uint8_t)(s->las_wide ? (x + 128) / 257 : x) << (8 * c);
                }
            }
            rgba[k] = v;
        }
        s->next += m;
    }
    return (int64_t)k;
}

/* The next rows of the streamed text, PCD or E57 file. */
static int64_t rows_next(lod_src *s, uint8_t *rgba, size_t max, sd_err *err)
{
    if (s->e57) {
        pc_e57_points o = {.xyz = s->las_xyz, .rgba = rgba};
        return pc_e57_stream_next(s->e57, &o, max, err);
    }
    return s->xyz ? pc_xyz_stream_next(s->xyz, s->las_xyz, rgba, max, err)
                  : pc_pcd_stream_next(s->pcd, s->las_xyz, rgba, max, err);
}

/* rows_bounds_pass: bounds and count of the finite rows of a streamed text or PCD file; its
 * format and colours are known after it. */
static int rows_bounds_pass(lod_src *s, sd_err *err)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    uint64_t kept = 0, rows = 0;
    int64_t m;
    while ((m = rows_next(s, NULL, BLOCK, err)) > 0) {
        for (int64_t i = 0; i < m; i++) {
            const double *p = s->las_xyz + 3 * i;
            if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) continue;
            kept++;
            for (int a = 0; a < 3; a++) {
                if (p[a] < lo[a]) lo[a] = p[a];
                if (p[a] > hi[a]) hi[a] = p[a];
            }
        }
        rows += (uint64_t)m;
    }
    if (m < 0) return (int)m;
    if (!kept) return sd_errf(err, SD_EEMPTY, "%s: no finite points (%llu read)", s->path,
                              (unsigned long long)rows);
    int rc = set_bounds(s, lo, hi, err);
    if (rc < 0) return rc;
    s->info.n = kept;
    s->info.n_dropped = rows - kept;
    int rgb = s->e57 ? (pc_e57_stream_attrs(s->e57) & PC_ATTR_RGB) != 0
            : s->xyz ? pc_xyz_stream_has_rgb(s->xyz) : pc_pcd_stream_has_rgb(s->pcd);
    s->info.attrs = rgb ? PC_ATTR_RGB : 0;
    snprintf(s->info.format, sizeof s->info.format, "%s",
             s->e57 ? pc_e57_stream_format(s->e57)
             : s->xyz ? pc_xyz_stream_format(s->xyz) : pc_pcd_stream_format(s->pcd));
    if (s->pcd)
        s->info.has_viewpoint = pc_pcd_stream_viewpoint(s->pcd, s->info.viewpoint, s->info.viewpoint_q);
    s->info.streamed = 1;
    return 0;
}

static int64_t rows_next_points(lod_src *s, float *pos, uint32_t *rgba, size_t max, sd_err *err)
{
    size_t k = 0;
    while (k < max) {
        size_t want = max - k < BLOCK ? max - k : BLOCK;
        int64_t m = rows_next(s, s->xyz_rgba, want, err);
        if (m <= 0) return m < 0 ? m : (int64_t)k;
        for (int64_t i = 0; i < m; i++) {
            const double *x = s->las_xyz + 3 * i;
            if (!isfinite(x[0]) || !isfinite(x[1]) || !isfinite(x[2])) continue;
            for (int a = 0; a < 3; a++) pos[3 * k + a] = (float)(x[a] - s->info.offset[a]);
            memcpy(&rgba[k++], s->xyz_rgba + 4 * i, 4);
        }
    }
    return (int64_t)k;
}

int lod_src_open(const char *path, lod_src **out, sd_err *err)
{
    *out = NULL;
    lod_src *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    snprintf(s->path, sizeof s->path, "%s", path);
    s->fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (s->fd < 0) {
        int e = errno;
        free(s);
        return sd_errf(err, SD_EIO, "%s: %s", path, strerror(e));
    }
    struct stat st;
    /* each stream takes only the files pc_load would give the same reader (by extension;
     * pc_read_las hands LAZ on to pc_read_laz), so that both read a file alike */
    const char *ext = pc_ext(path);
    int is_las = !strcasecmp(ext, "las"), is_laz = !strcasecmp(ext, "laz");
    int rc = fstat(s->fd, &st) < 0 || !S_ISREG(st.st_mode)
                 ? sd_errf(err, SD_EIO, "%s: not a regular file", path)
                 : !strcasecmp(ext, "ply") ? try_ply_header(s, err) : 0;
    int las = 0; /* 1: a streamed LAS or LAZ file */
    if (rc == 0 && is_las) las = rc = pc_las_stream_open(path, &s->las, err);
    if (rc == 0 && (is_las || is_laz)) las = rc = pc_laz_stream_open(path, 0, &s->laz, err);
    int rows = 0; /* 1: a streamed text or PCD file */
    if (rc == 0) rows = rc = pc_xyz_stream_open(path, &s->xyz, err);
    if (rc == 0) rows = rc = pc_pcd_stream_open(path, &s->pcd, err);
    if (rc == 0) rows = rc = pc_e57_stream_open(path, &s->e57, err);
    if (rc == 1 && rows) {
        s->las_xyz = malloc((size_t)BLOCK * 3 * sizeof(double));
        s->xyz_rgba = malloc((size_t)BLOCK * 4);
        rc = s->las_xyz && s->xyz_rgba ? rows_bounds_pass(s, err)
                                       : sd_errf(err, SD_ENOMEM, "out of memory");
        if (rc == 0) rc = lod_src_rewind(s, err); /* the bounds pass read these to the end */
    } else if (rc == 1 && !las) {
        s->buf = malloc((size_t)BLOCK * s->rec);
        rc = s->buf ? bounds_pass(s, err) : sd_errf(err, SD_ENOMEM, "out of memory");
    } else if (rc == 1) {
        s->las_xyz = malloc((size_t)BLOCK * 3 * sizeof(double));
        s->las_rgb = malloc((size_t)BLOCK * 3 * sizeof(uint16_t));
        rc = s->las_xyz && s->las_rgb ? las_bounds_pass(s, err)
                                      : sd_errf(err, SD_ENOMEM, "out of memory");
    } else if (rc == 0) {
        rc = pc_load(path, &s->cloud, err);
        if (rc == 0) {
            s->have_cloud = 1;
            lod_src_info *in = &s->info;
            in->n = s->cloud.n;
            in->n_dropped = s->cloud.n_dropped;
            memcpy(in->offset, s->cloud.offset, sizeof in->offset);
            memcpy(in->bmin, s->cloud.bmin, sizeof in->bmin);
            memcpy(in->bmax, s->cloud.bmax, sizeof in->bmax);
            in->attrs = s->cloud.attrs & PC_ATTR_RGB;
            in->has_viewpoint = s->cloud.has_viewpoint;
            memcpy(in->viewpoint, s->cloud.viewpoint, sizeof in->viewpoint);
            memcpy(in->viewpoint_q, s->cloud.viewpoint_q, sizeof in->viewpoint_q);
            memcpy(in->format, s->cloud.format, sizeof in->format);
            in->format[sizeof in->format - 1] = 0;
        }
    }
    if (rc < 0) {
        lod_src_close(s);
        return rc;
    }
    *out = s;
    return 0;
}

void lod_src_close(lod_src *s)
{
    if (!s) return;
    if (s->fd >= 0) close(s->fd);
    free(s->buf);
    pc_las_stream_close(s->las);
    pc_laz_stream_close(s->laz);
    pc_xyz_stream_close(s->xyz);
    pc_pcd_stream_close(s->pcd);
    pc_e57_stream_close(s->e57);
    free(s->xyz_rgba);
    free(s->las_xyz);
    free(s->las_rgb);
    if (s->have_cloud) pc_cloud_free(&s->cloud);
    free(s);
}

void lod_src_get_info(const lod_src *s, lod_src_info *info)
{
    *info = s->info;
}

int lod_src_rewind(lod_src *s, sd_err *err)
{
    (void)err;
    s->next = 0;
    if (s->xyz) pc_xyz_stream_rewind(s->xyz);
    if (s->pcd) pc_pcd_stream_rewind(s->pcd);
    if (s->e57) pc_e57_stream_rewind(s->e57);
    return 0;
}

int64_t lod_src_next(lod_src *s, float *pos, uint32_t *rgba, size_t max, sd_err *err)
{
    size_t k = 0;
    if (s->have_cloud) {
        while (k < max && s->next < s->cloud.n) {
            uint64_t i = s->next++;
            memcpy(pos + 3 * k, s->cloud.pos + 3 * i, 12);
            uint32_t v = 0xFFFFFFFFu;
            if (s->cloud.attrs & PC_ATTR_RGB) memcpy(&v, s->cloud.rgba + 4 * i, 4);
            rgba[k++] = v;
        }
        return (int64_t)k;
    }
    if (s->las || s->laz) return las_next(s, pos, rgba, max, err);
    if (s->xyz || s->pcd || s->e57) return rows_next_points(s, pos, rgba, max, err);
    while (k < max && s->next < s->nrec) {
        size_t want = max - k < BLOCK ? max - k : BLOCK;
        size_t m = s->nrec - s->next < want ? (size_t)(s->nrec - s->next) : want;
        int rc = read_records(s, s->next, m, err);
        if (rc < 0) return rc;
        if (layout_f32_u8(s)) {
            k += ply_block_f32(s, s->buf, m, pos + 3 * k, rgba + k);
            s->next += m;
            continue;
        }
        for (size_t i = 0; i < m; i++) {
            const uint8_t *p = s->buf + i * s->rec;
            double x[3];
            record_xyz(s, p, x);
            if (!isfinite(x[0]) || !isfinite(x[1]) || !isfinite(x[2])) continue;
            for (int a = 0; a < 3; a++) pos[3 * k + a] = (float)(x[a] - s->info.offset[a]);
            rgba[k++] = record_rgba(s, p);
        }
        s->next += m;
    }
    return (int64_t)k;
}
