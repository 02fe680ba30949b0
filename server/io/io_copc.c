/* io_copc.c — the top levels of a COPC file's octree as a cloud: the hierarchy read page by
 * page down to a level only (deeper pages stay unread), then those nodes' chunks decoded. A
 * coarse but complete preview of the whole extent (COPC's levels are spatially uniform
 * subsamples), in a fraction of the full decode: what a first image can be drawn from while
 * the full load runs. */
#include "cloud.h"
#include "copc.h"
#include "io_text.h"
#include "las_header.h"
#include "laz.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct levels_job {
    const char *path;
    const pc__file *f;
    int32_t max_level;
    uint64_t budget;            /* > 0: keep only the levels whose running total fits this */
    int *level_out;
    pc_raw *raw;
    sd_err *err;
    /* everything allocated, reachable for the caller to free after a jump */
    laz_file lf;
    copc_entry *nodes;
    size_t n, cap;
    laz_chunk_dec *cd;
    uint8_t *buf;
    size_t buf_cap;
    uint16_t *rgb16;
} levels_job;

static int add_node(void *ctx, const copc_entry *e)
{
    levels_job *j = ctx;
    if (e->count <= 0) return 0;
    if (j->n == j->cap) {
        size_t nc = j->cap ? 2 * j->cap : 64;
        copc_entry *nn = realloc(j->nodes, nc * sizeof *nn);
        if (!nn) return sd_errf(j->err, SD_ENOMEM, "%s: no memory for the COPC nodes", j->path);
        j->nodes = nn;
        j->cap = nc;
    }
    j->nodes[j->n++] = *e;
    return 0;
}

static int by_level(const void *a, const void *b)
{
    const copc_entry *x = a, *y = b;
    return x->level != y->level ? (x->level < y->level ? -1 : 1)
                                : (x->off < y->off ? -1 : x->off > y->off);
}

/* budget_cut: how many of the n nodes (sorted by level) to keep: every node of levels 0..L,
 * L the deepest level whose nodes together with all shallower ones hold at most budget points;
 * at least level 0 (the root alone may hold more). */
static size_t budget_cut(const copc_entry *e, size_t n, uint64_t budget)
{
    size_t keep = 0, i = 0;
    uint64_t sum = 0;
    while (i < n) {
        size_t k = i;
        uint64_t lv = 0;
        for (; k < n && e[k].level == e[i].level; k++) lv += (uint64_t)e[k].count;
        if (keep && sum + lv > budget) break;
        sum += lv;
        keep = k;
        i = k;
    }
    return keep;
}

static int levels_parse(void *arg)
{
    levels_job *j = arg;
    int rc = laz_open(&j->lf, j->path, j->f->data, j->f->size, j->err);
    if (rc) return rc;
    if ((rc = copc_visit(&j->lf, j->max_level, add_node, j, j->err))) return rc;
    if (j->n == 0)
        return sd_errf(j->err, SD_EEMPTY, "%s: no COPC node of level %d or less holds points",
                       j->path, j->max_level);
    qsort(j->nodes, j->n, sizeof *j->nodes, by_level);
    if (j->budget) j->n = budget_cut(j->nodes, j->n, j->budget);
    if (j->level_out) *j->level_out = j->nodes[j->n - 1].level;
    const las_header *h = &j->lf.h;
    int has_rgb = pc__las_formats[h->format].rgb != 0;
    pc_raw *raw = j->raw;
    raw->attrs = PC_ATTR_INTENSITY | PC_ATTR_CLASS | (has_rgb ? PC_ATTR_RGB : 0);
    j->cd = laz_chunk_dec_create(j->lf.items, j->lf.nitems);
    if (!j->cd) return sd_errf(j->err, SD_ENOMEM, "%s: no memory for a LAZ decoder", j->path);
    for (size_t i = 0; i < j->n; i++) {
        const copc_entry *e = &j->nodes[i];
        if ((rc = copc_node_read(&j->lf, j->cd, e, &j->buf, &j->buf_cap, j->err))) return rc;
        /* the points decoded: now the cloud may hold them */
        size_t need = raw->n + (size_t)e->count;
        if ((rc = pc_raw_reserve(raw, need, j->err))) return rc;
        if (has_rgb) {
            uint16_t *nr = realloc(j->rgb16, sizeof(uint16_t) * 3 * need);
            if (!nr) return sd_errf(j->err, SD_ENOMEM, "%s: no memory for colours", j->path);
            j->rgb16 = nr;
        }
        pc__las_convert(h, j->buf, (size_t)e->count, raw, raw->n, 0, has_rgb ? j->rgb16 : NULL);
        raw->n = need;
    }
    if (has_rgb) pc__las_rgb16(j->rgb16, raw->n, raw);
    snprintf(raw->format, sizeof raw->format, "COPC LAZ 1.%u format %u, levels 0-%d", h->minor,
             h->format, j->nodes[j->n - 1].level);
    return 0;
}

static int read_levels(const char *path, int max_level, uint64_t budget, int *level, pc_raw *raw,
                       sd_err *err)
{
    pc__file file;
    int rc = pc__file_open(path, &file, err);
    if (rc) return rc;
    levels_job j = {.path = path, .f = &file, .max_level = max_level, .budget = budget,
                    .level_out = level, .raw = raw, .err = err};
    rc = pc__guarded(&file, path, levels_parse, &j, err);
    free(j.rgb16);
    free(j.buf);
    laz_chunk_dec_free(j.cd);
    free(j.nodes);
    laz_close(&j.lf);
    pc__file_close(&file);
    return rc;
}

int pc_read_copc_levels(const char *path, int max_level, pc_raw *raw, sd_err *err)
{
    return read_levels(path, max_level, 0, NULL, raw, err);
}

int pc_read_copc_budget(const char *path, uint64_t budget, pc_raw *raw, int *level, sd_err *err)
{
    /* Level 24 is 2^72 cells: no real file reaches it; deeper pages stay unread. */
    return read_levels(path, 24, budget ? budget : 1, level, raw, err);
}
