/* prepared.c — the section layout of a prepared cloud (shared by prep.c and cache.c). */
#include "prepared.h"

#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "cachefile.h"

#define ALIGN64(x) (((x) + 63u) & ~(uint64_t)63u)

/* Walks the sections in block order; with block == NULL it only measures. */
static uint64_t layout(pc_prepared *p, uint64_t n, uint32_t attrs, uint64_t nb, uint8_t *block)
{
    uint64_t off = 0;
#define SECTION(field, type, per, present)                                   \
    do {                                                                     \
        if (present) {                                                       \
            if (p) p->field = (type *)(block + off);                         \
            off = ALIGN64(off + (uint64_t)(per) * sizeof(type));             \
        } else if (p) {                                                      \
            p->field = NULL;                                                 \
        }                                                                    \
    } while (0)
    /* The order is the cache file's: positions, the attributes prep always makes (normal,
     * radius, F), the file's optional ones in table order (cloud.h), the batches. */
    SECTION(pos, float, 3 * n, 1);
    SECTION(normal, float, 3 * n, 1);
    SECTION(radius, float, n, 1);
    SECTION(F, float, n, 1);
#define OPTIONAL_(id, fld, type, k) \
    if (PC_ATTR_##id != PC_ATTR_NORMAL && PC_ATTR_##id != PC_ATTR_RADIUS) \
        SECTION(fld, type, (k) * n, attrs & PC_ATTR_##id);
    PC_ATTR_FIELDS(OPTIONAL_)
#undef OPTIONAL_
    SECTION(batches, pc_batch, nb, 1);
#undef SECTION
    return off;
}

uint64_t pc_prepared_block_len(uint64_t n, uint32_t attrs, uint64_t nbatches)
{
    return layout(NULL, n, attrs, nbatches, NULL);
}

void pc_prepared_bind(pc_prepared *p, void *block)
{
    p->block = block;
    p->block_len = layout(p, p->n, p->attrs, p->nbatches, block);
}

int pc_prepared_alloc(pc_prepared *p, sd_err *err)
{
    uint64_t len = pc_prepared_block_len(p->n, p->attrs, p->nbatches);
    void *b = NULL;
    if (len > SIZE_MAX || posix_memalign(&b, 64, len ? (size_t)len : 64) != 0)
        return sd_errf(err, SD_ENOMEM, "out of memory for a prepared cloud of %llu points",
                       (unsigned long long)p->n);
    memset(b, 0, (size_t)len);
    p->heap = b;
    pc_prepared_bind(p, b);
    return 0;
}

void pc_prepared_make_batches(pc_prepared *p, uint32_t per)
{
    for (uint64_t b = 0; b < p->nbatches; b++) {
        pc_batch *bt = &p->batches[b];
        bt->first = (uint32_t)(b * per);
        bt->count = (uint32_t)(bt->first >= p->n ? 0 : p->n - bt->first < per ? p->n - bt->first : per);
        if (bt->count == 0) continue; /* nbatches larger than needed: empty batches, zero bounds */
        const float *q = p->pos + 3 * (size_t)bt->first;
        for (int a = 0; a < 3; a++) bt->bmin[a] = bt->bmax[a] = q[a];
        for (uint32_t i = 1; i < bt->count; i++)
            for (int a = 0; a < 3; a++) {
                float v = q[3 * i + a];
                if (v < bt->bmin[a]) bt->bmin[a] = v;
                if (v > bt->bmax[a]) bt->bmax[a] = v;
            }
    }
}

int pc_prepared_check(const pc_prepared *p, sd_err *err)
{
    if (!cf_map_changed(p->file)) return 0;
    return cf_changed_error(err, "cache", p->file->path,
                            "it became shorter: the cloud's data is gone");
}

void pc_prepared_free(pc_prepared *p)
{
    if (p->heap) free(p->heap);
    if (p->file) cf_map_close(p->file);
    else if (p->map) munmap(p->map, p->map_len);
    memset(p, 0, sizeof *p);
}
