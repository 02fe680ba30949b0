/* copc.c — COPC info, hierarchy pages and nodes (copc.h). */
#include "copc.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ENTRY_SIZE 32u

int copc_info_read(const laz_file *lf, copc_info *out, sd_err *err)
{
    memset(out, 0, sizeof *out);
    const uint8_t *v = lf->copc_info;
    if (!v)
        return sd_errf(err, SD_EFORMAT, "%s: not a COPC file (no 'copc' info VLR, record 1)",
                       lf->path);
    for (int k = 0; k < 3; k++) out->center[k] = rdf64(v + 8 * k);
    out->halfsize = rdf64(v + 24);
    out->spacing = rdf64(v + 32);
    out->root_off = rd64(v + 40);
    out->root_size = rd64(v + 48);
    out->gps_min = rdf64(v + 56);
    out->gps_max = rdf64(v + 64);
    if (out->root_off > lf->size || out->root_size > lf->size - out->root_off ||
        out->root_size % ENTRY_SIZE != 0)
        return sd_errf(err, SD_EFORMAT, "%s: the COPC root hierarchy page (offset %llu, %llu "
                       "bytes, from the info VLR) is not a whole number of 32-byte entries "
                       "inside the file's %zu bytes", lf->path,
                       (unsigned long long)out->root_off, (unsigned long long)out->root_size,
                       lf->size);
    return 0;
}

int copc_page_read(const laz_file *lf, uint64_t off, uint64_t size, copc_entry **out, size_t *n,
                   sd_err *err)
{
    *out = NULL;
    *n = 0;
    if (off > lf->size || size > lf->size - off || size % ENTRY_SIZE != 0)
        return sd_errf(err, SD_EFORMAT, "%s: COPC hierarchy page at offset %llu (%llu bytes) "
                       "is not a whole number of 32-byte entries inside the file's %zu bytes",
                       lf->path, (unsigned long long)off, (unsigned long long)size, lf->size);
    size_t m = (size_t)(size / ENTRY_SIZE);
    if (m == 0) return 0;
    copc_entry *e = malloc(m * sizeof *e);
    if (!e)
        return sd_errf(err, SD_ENOMEM, "%s: no memory for a COPC page of %zu entries", lf->path,
                       m);
    for (size_t i = 0; i < m; i++) {
        const uint8_t *p = lf->data + off + ENTRY_SIZE * i;
        copc_entry *q = &e[i];
        q->level = (int32_t)rd32(p);
        q->x = (int32_t)rd32(p + 4);
        q->y = (int32_t)rd32(p + 8);
        q->z = (int32_t)rd32(p + 12);
        q->off = rd64(p + 16);
        q->bytes = (int32_t)rd32(p + 24);
        q->count = (int32_t)rd32(p + 28);
        const char *bad = NULL;
        if (q->level < 0 || q->level > 30) bad = "a level outside 0..30";
        else if (q->x < 0 || q->y < 0 || q->z < 0 || q->x >= (1 << q->level) ||
                 q->y >= (1 << q->level) || q->z >= (1 << q->level))
            bad = "a key outside its level's 2^level cells";
        else if (q->count < -1) bad = "a point count below -1";
        else if (q->count != 0 && (q->bytes < 0 || q->off > lf->size ||
                                   (uint64_t)q->bytes > lf->size - q->off))
            bad = "data outside the file";
        else if (q->count > 0 && (uint64_t)q->count > 1 + (uint64_t)q->bytes *
                                                              LAZ_MAX_POINTS_PER_BYTE)
            bad = "more points than its bytes can hold";
        if (bad) {
            int rc = sd_errf(err, SD_EFORMAT, "%s: COPC hierarchy page at offset %llu, entry "
                             "%zu (node %d-%d-%d-%d: offset %llu, %d bytes, %d points) has %s",
                             lf->path, (unsigned long long)off, i, q->level, q->x, q->y, q->z,
                             (unsigned long long)q->off, q->bytes, q->count, bad);
            free(e);
            return rc;
        }
    }
    *out = e;
    *n = m;
    return 0;
}

int copc_node_read(const laz_file *lf, laz_chunk_dec *cd, const copc_entry *e, uint8_t **buf,
                   size_t *cap, sd_err *err)
{
    char label[80];
    snprintf(label, sizeof label, "COPC node %d-%d-%d-%d", e->level, e->x, e->y, e->z);
    if (e->count < 0)
        return sd_errf(err, SD_EINVAL, "%s: %s is a hierarchy page link, not a node", lf->path,
                       label);
    return laz_read_span(lf, cd, e->off, (uint64_t)e->bytes, (uint64_t)e->count, label, buf, cap,
                         err);
}

/* The pages still to read: a stack of (offset, size). */
typedef struct page_ref {
    uint64_t off, size;
} page_ref;

int copc_visit(const laz_file *lf, int32_t max_level, int (*fn)(void *ctx, const copc_entry *e),
               void *ctx, sd_err *err)
{
    copc_info info;
    int rc = copc_info_read(lf, &info, err);
    if (rc) return rc;
    size_t max_pages = lf->size / ENTRY_SIZE, read = 0, top = 0, cap = 16;
    page_ref *stack = malloc(cap * sizeof *stack);
    if (!stack) return sd_errf(err, SD_ENOMEM, "%s: no memory for the COPC walk", lf->path);
    stack[top++] = (page_ref){info.root_off, info.root_size};
    while (top && !rc) {
        page_ref pg = stack[--top];
        if (++read > max_pages) {
            rc = sd_errf(err, SD_EFORMAT, "%s: the COPC hierarchy links more pages than the "
                         "file can hold (a page linking back to an ancestor?)", lf->path);
            break;
        }
        copc_entry *e;
        size_t n;
        rc = copc_page_read(lf, pg.off, pg.size, &e, &n, err);
        for (size_t i = 0; i < n && !rc; i++) {
            if (e[i].level > max_level) continue; /* and a deeper page stays unread */
            if (e[i].count >= 0) {
                rc = fn(ctx, &e[i]);
                continue;
            }
            if (top == cap) {
                page_ref *ns = realloc(stack, 2 * cap * sizeof *ns);
                if (!ns) {
                    rc = sd_errf(err, SD_ENOMEM, "%s: no memory for the COPC walk", lf->path);
                    break;
                }
                stack = ns;
                cap *= 2;
            }
            stack[top++] = (page_ref){e[i].off, (uint64_t)(uint32_t)e[i].bytes};
        }
        free(e);
    }
    free(stack);
    return rc;
}
