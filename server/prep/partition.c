/* partition.c — recursive median splits of a cloud into spatial parts (see partition.h). */
#include "partition.h"

#include <stdlib.h>
#include <string.h>

typedef struct split_ctx {
    const float *pos;
    uint16_t *part;
    int axis;
} split_ctx;

/* by_axis: orders point indices by their coordinate on c->axis, then by index. */
static int by_axis(const void *a, const void *b, void *user)
{
    const split_ctx *c = user;
    uint64_t i = *(const uint64_t *)a, j = *(const uint64_t *)b;
    float u = c->pos[3 * i + (uint64_t)c->axis], v = c->pos[3 * j + (uint64_t)c->axis];
    if (u < v) return -1;
    if (u > v) return 1;
    return i < j ? -1 : i > j;
}

/* split: idx[0..cnt) go to parts [first, first + k). */
static void split(split_ctx *c, uint64_t *idx, uint64_t cnt, int first, int k)
{
    if (k == 1 || cnt == 0) {
        for (uint64_t j = 0; j < cnt; j++) c->part[idx[j]] = (uint16_t)first;
        return;
    }
    float lo[3], hi[3];
    for (int a = 0; a < 3; a++) lo[a] = hi[a] = c->pos[3 * idx[0] + (uint64_t)a];
    for (uint64_t j = 1; j < cnt; j++)
        for (int a = 0; a < 3; a++) {
            float v = c->pos[3 * idx[j] + (uint64_t)a];
            if (v < lo[a]) lo[a] = v;
            if (v > hi[a]) hi[a] = v;
        }
    int axis = 0;
    for (int a = 1; a < 3; a++)
        if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    c->axis = axis;
    qsort_r(idx, cnt, sizeof *idx, by_axis, c);
    int kl = k / 2;
    uint64_t nl = (uint64_t)((double)cnt * kl / k + 0.5);
    split(c, idx, nl, first, kl);
    split(c, idx + nl, cnt - nl, first + kl, k - kl);
}

int pc_partition(const float *pos, uint64_t n, int nparts, uint16_t *part, sd_err *err)
{
    if (nparts < 1 || nparts > PC_PART_MAX)
        return sd_errf(err, SD_EINVAL, "%d parts: 1 to %d", nparts, PC_PART_MAX);
    if (nparts == 1 || n == 0) {
        for (uint64_t i = 0; i < n; i++) part[i] = 0;
        return 0;
    }
    uint64_t *idx = n <= SIZE_MAX / sizeof *idx ? malloc((size_t)n * sizeof *idx) : NULL;
    if (!idx)
        return sd_errf(err, SD_ENOMEM, "out of memory partitioning %llu points",
                       (unsigned long long)n);
    for (uint64_t i = 0; i < n; i++) idx[i] = i;
    split_ctx c = {.pos = pos, .part = part};
    split(&c, idx, n, 0, nparts);
    free(idx);
    return 0;
}

int pc_prepared_subset(const pc_prepared *src, const uint16_t *part, int which,
                       pc_prepared *dst, sd_err *err)
{
    memset(dst, 0, sizeof *dst);
    uint64_t m = 0;
    for (uint64_t i = 0; i < src->n; i++) m += part[i] == which;
    dst->n = m;
    dst->attrs = src->attrs;
    dst->k = src->k;
    dst->nbatches = (m + PC_BATCH_POINTS - 1) / PC_BATCH_POINTS;
    int rc = pc_prepared_alloc(dst, err);
    if (rc < 0) {
        memset(dst, 0, sizeof *dst);
        return rc;
    }
    uint64_t o = 0;
    for (uint64_t i = 0; i < src->n; i++) {
        if (part[i] != which) continue;
        memcpy(dst->pos + 3 * o, src->pos + 3 * i, 3 * sizeof *dst->pos);
        dst->F[o] = src->F[i];
#define COPY_(id, fld, type, k)                                                        \
        if (dst->fld && src->fld) memcpy(dst->fld + (k) * o, src->fld + (k) * i, (k) * sizeof(type));
        PC_ATTR_FIELDS(COPY_)
#undef COPY_
        o++;
    }
    pc_prepared_make_batches(dst, PC_BATCH_POINTS);
    memcpy(dst->offset, src->offset, sizeof dst->offset);
    memcpy(dst->bmin, src->bmin, sizeof dst->bmin);
    memcpy(dst->bmax, src->bmax, sizeof dst->bmax);
    dst->sigma = src->sigma;
    dst->F_raw_p99 = src->F_raw_p99;
    memcpy(dst->F_pct, src->F_pct, sizeof dst->F_pct);
    dst->radius_median = src->radius_median;
    dst->n_dropped = src->n_dropped;
    memcpy(dst->format, src->format, sizeof dst->format);
    memcpy(dst->scalar_name, src->scalar_name, sizeof dst->scalar_name);
    return 0;
}
