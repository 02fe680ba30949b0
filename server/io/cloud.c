/* cloud.c — raw cloud growth, finalisation (NaN removal, re-centring) and reader dispatch. */
#include "cloud.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "e57_stream.h"

static int grow(void **p, size_t cap, size_t elem)
{
    if (cap > SIZE_MAX / elem) return -1;
    void *q = realloc(*p, cap * elem);
    if (!q) return -1;
    *p = q;
    return 0;
}

const pc_attr_info pc_attr_table[PC_ATTR_NFIELDS] = {
#define PC_ATTR_INFO_(id, fld, type, k) {PC_ATTR_##id, #fld, sizeof(type), k},
    PC_ATTR_FIELDS(PC_ATTR_INFO_)
#undef PC_ATTR_INFO_
};

int pc_raw_reserve(pc_raw *raw, size_t cap, sd_err *err)
{
    if (cap <= raw->cap) return 0;
    int bad = grow((void **)&raw->xyz, cap, 3 * sizeof(double));
#define PC_GROW_(id, fld, type, k) \
    if (raw->attrs & PC_ATTR_##id) bad |= grow((void **)&raw->fld, cap, (k) * sizeof(type));
    PC_ATTR_FIELDS(PC_GROW_)
#undef PC_GROW_
    if (bad) return sd_errf(err, SD_ENOMEM, "out of memory for %zu points", cap);
    raw->cap = cap;
    return 0;
}

void pc_raw_free(pc_raw *raw)
{
    free(raw->xyz);
#define PC_FREE_(id, fld, type, k) free(raw->fld);
    PC_ATTR_FIELDS(PC_FREE_)
#undef PC_FREE_
    memset(raw, 0, sizeof *raw);
}

void pc_cloud_free(pc_cloud *c)
{
    free(c->pos);
#define PC_FREE_(id, fld, type, k) free(c->fld);
    PC_ATTR_FIELDS(PC_FREE_)
#undef PC_FREE_
    memset(c, 0, sizeof *c);
}

/* Compacts attribute array a (elem bytes per point) in place, keeping the points in keep. */
static void compact(void *a, size_t elem, const uint8_t *keep, size_t n)
{
    if (!a) return;
    uint8_t *p = a;
    size_t j = 0;
    for (size_t i = 0; i < n; i++) {
        if (!keep[i]) continue;
        if (j != i) memmove(p + j * elem, p + i * elem, elem);
        j++;
    }
}

int pc_finalize(pc_raw *raw, pc_cloud *out, const char *path, sd_err *err)
{
    memset(out, 0, sizeof *out);
    size_t n = raw->n;
    uint8_t *keep = malloc(n ? n : 1);
    if (!keep) return sd_errf(err, SD_ENOMEM, "%s: out of memory for %zu points", path, n);

    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    size_t kept = 0;
    for (size_t i = 0; i < n; i++) {
        const double *p = raw->xyz + 3 * i;
        keep[i] = isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]);
        if (!keep[i]) continue;
        kept++;
        for (int k = 0; k < 3; k++) {
            if (p[k] < lo[k]) lo[k] = p[k];
            if (p[k] > hi[k]) hi[k] = p[k];
        }
    }
    if (kept == 0) {
        free(keep);
        return sd_errf(err, SD_EEMPTY, "%s: no finite points (%zu read)", path, n);
    }

    for (int k = 0; k < 3; k++) {
        /* re-centred coordinates reach half the span: it must fit a float */
        if (!(0.5 * hi[k] - 0.5 * lo[k] <= FLT_MAX)) {
            free(keep);
            return sd_errf(err, SD_ELIMIT, "%s: the points span %g along %c, more than float32 holds",
                           path, hi[k] - lo[k], "xyz"[k]);
        }
    }
    out->pos = malloc(kept * 3 * sizeof(float));
    if (!out->pos) {
        free(keep);
        return sd_errf(err, SD_ENOMEM, "%s: out of memory for %zu points", path, kept);
    }
    for (int k = 0; k < 3; k++) {
        out->bmin[k] = lo[k];
        out->bmax[k] = hi[k];
        out->offset[k] = 0.5 * lo[k] + 0.5 * hi[k]; /* lo + hi may overflow */
    }
    size_t j = 0;
    for (size_t i = 0; i < n; i++) {
        if (!keep[i]) continue;
        for (int k = 0; k < 3; k++)
            out->pos[3 * j + k] = (float)(raw->xyz[3 * i + k] - out->offset[k]);
        j++;
    }
    if (kept != n) {
#define PC_COMPACT_(id, fld, type, k) compact(raw->fld, (k) * sizeof(type), keep, n);
        PC_ATTR_FIELDS(PC_COMPACT_)
#undef PC_COMPACT_
    }
    free(keep);

    out->n = kept;
    out->n_dropped = n - kept;
    out->attrs = raw->attrs;
#define PC_MOVE_(id, fld, type, k) out->fld = raw->fld, raw->fld = NULL;
    PC_ATTR_FIELDS(PC_MOVE_)
#undef PC_MOVE_
    memcpy(out->scalar_name, raw->scalar_name, sizeof out->scalar_name);
    memcpy(out->format, raw->format, sizeof out->format);
    out->has_viewpoint = raw->has_viewpoint;
    memcpy(out->viewpoint, raw->viewpoint, sizeof out->viewpoint);
    memcpy(out->viewpoint_q, raw->viewpoint_q, sizeof out->viewpoint_q);
    pc_raw_free(raw);
    return 0;
}

const char *pc_ext(const char *name)
{
    const char *slash = strrchr(name, '/');
    const char *dot = strrchr(slash ? slash : name, '.');
    return dot ? dot + 1 : "";
}

typedef int (*reader_fn)(const char *, pc_raw *, sd_err *);

static reader_fn reader_for(const char *path)
{
    const char *e = pc_ext(path);
    if (!strcasecmp(e, "ply")) return pc_read_ply;
    if (!strcasecmp(e, "pcd")) return pc_read_pcd;
    if (!strcasecmp(e, "las")) return pc_read_las;
    if (!strcasecmp(e, "laz")) return pc_read_laz; /* also .copc.laz */
    if (!strcasecmp(e, "xyz") || !strcasecmp(e, "pts") || !strcasecmp(e, "txt")) return pc_read_xyz;
    if (!strcasecmp(e, "e57")) return pc_read_e57;
    return NULL;
}

/* reader_by_magic: the reader of a file whose extension names none, from its first bytes (E57's
 * signature); NULL when they match no format. */
static reader_fn reader_by_magic(const char *path)
{
    return pc_e57_signature(path) ? pc_read_e57 : NULL;
}

int pc_supported_ext(const char *name)
{
    return reader_for(name) != NULL;
}

int pc_load_threads(const char *path, int threads, pc_cloud *out, sd_err *err)
{
    reader_fn rd = reader_for(path);
    if (!rd) rd = reader_by_magic(path);
    memset(out, 0, sizeof *out);
    if (!rd)
        return sd_errf(err, SD_EUNSUP,
                       "%s: unknown extension '.%s' (supported: ply, pcd, las, laz, copc.laz, "
                       "xyz, pts, txt, e57)",
                       path, pc_ext(path));
    pc_raw raw = {0};
    /* the LAZ reader decodes chunks on threads; every other reader is single-threaded */
    int rc = rd == pc_read_laz ? pc_read_laz_threads(path, &raw, threads, err)
                               : rd(path, &raw, err);
    if (rc < 0) {
        pc_raw_free(&raw);
        return rc;
    }
    rc = pc_finalize(&raw, out, path, err);
    pc_raw_free(&raw); /* pc_finalize empties raw on success but leaves it on failure */
    return rc;
}

int pc_load(const char *path, pc_cloud *out, sd_err *err)
{
    return pc_load_threads(path, 0, out, err);
}
