/* knn.c — the kNN interface: dispatch to the Morton-cell grid (knn_grid.c) or FLANN. */
#include "knn.h"

#include <flann/flann.h>
#include <stdlib.h>
#include <string.h>

#include "knn_grid.h"

struct prep_knn {
    prep_knn_method method;
    size_t n;
    const float *pos;
    prep__grid *grid;
    flann_index_t flann;
    struct FLANNParameters fp;
};

struct prep_knn_scratch {
    prep__grid_scratch *grid;
    int *fidx;       /* FLANN results for one block of queries: k + 1 per query */
    float *fd2;
    float *fq;       /* gathered query coordinates */
    size_t fcap;     /* entries in fidx and fd2 */
    size_t qcap;     /* queries in fq */
};

enum { FLANN_BLOCK = 4096 }; /* queries per FLANN call (bounds the scratch) */

const char *prep_knn_method_name(prep_knn_method m)
{
    return m == PREP_KNN_FLANN ? "flann" : "grid";
}

/* FLANN parameters for an exact single kd-tree: one tree, unlimited checks, no eps. */
static void flann_params(struct FLANNParameters *p, int leaf, int cores)
{
    *p = DEFAULT_FLANN_PARAMETERS;
    p->algorithm = FLANN_INDEX_KDTREE_SINGLE;
    p->checks = FLANN_CHECKS_UNLIMITED;
    p->eps = 0;
    p->sorted = 1;
    p->trees = 1;
    p->leaf_max_size = leaf > 0 ? leaf : 10;
    p->cores = cores > 0 ? cores : 1;
    p->log_level = FLANN_LOG_NONE;
    p->random_seed = 1;
}

int prep_knn_build(const float *pos, size_t n, const prep_knn_opts *opts, prep_knn **out,
                   sd_err *err)
{
    prep_knn_opts o = opts ? *opts : (prep_knn_opts){0};
    if (n >= UINT32_MAX || n > (size_t)INT32_MAX)
        return sd_errf(err, SD_ELIMIT, "kNN index of %zu points is over the limit of %d", n,
                       INT32_MAX);
    if (o.method != PREP_KNN_GRID && o.method != PREP_KNN_FLANN)
        return sd_errf(err, SD_EINVAL, "unknown kNN method %d", (int)o.method);
    prep_knn *kn = calloc(1, sizeof *kn);
    if (!kn) return sd_errf(err, SD_ENOMEM, "out of memory for a kNN index");
    kn->method = o.method;
    kn->n = n;
    kn->pos = pos;
    if (o.method == PREP_KNN_GRID) {
        int rc = prep__grid_build(pos, n, o.leaf_size, o.frame, o.codes, o.simd, &kn->grid,
                                  err);
        if (rc != 0) {
            free(kn);
            return rc;
        }
    } else {
        flann_params(&kn->fp, o.leaf_size, o.flann_cores);
        float speedup = 0;
        if (n > 0) {
            /* FLANN takes a non-const pointer but only reads the points. */
            kn->flann = flann_build_index_float((float *)pos, (int)n, 3, &speedup, &kn->fp);
            if (!kn->flann) {
                free(kn);
                return sd_errf(err, SD_ENOMEM, "FLANN could not build a kd-tree of %zu points",
                               n);
            }
        }
    }
    *out = kn;
    return 0;
}

void prep_knn_free(prep_knn *kn)
{
    if (!kn) return;
    prep__grid_free(kn->grid);
    if (kn->flann) flann_free_index_float(kn->flann, &kn->fp);
    free(kn);
}

prep_knn_scratch *prep_knn_scratch_new(void)
{
    prep_knn_scratch *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->grid = prep__grid_scratch_new();
    if (!s->grid) {
        free(s);
        return NULL;
    }
    return s;
}

void prep_knn_scratch_free(prep_knn_scratch *s)
{
    if (!s) return;
    prep__grid_scratch_free(s->grid);
    free(s->fidx);
    free(s->fd2);
    free(s->fq);
    free(s);
}

void prep_knn_scratch_counters(const prep_knn_scratch *s, prep_knn_counters *c)
{
    prep__grid_counters(s->grid, c);
}

/* FLANN returns k + 1 neighbours per query, ascending, squared distances for L2. The query
 * itself is normally first, but with duplicate points it may sit anywhere among the distance-0
 * results, or (many duplicates) not at all: drop it where found, else drop the last. */
static int flann_query(const prep_knn *kn, const uint32_t *qidx, size_t first, size_t nq, int k,
                       uint32_t *idx, float *d2, prep_knn_scratch *s, sd_err *err)
{
    size_t kk = (size_t)k + 1;
    size_t blk = nq < FLANN_BLOCK ? nq : FLANN_BLOCK;
    if (blk * kk > s->fcap) {
        int *fi = realloc(s->fidx, blk * kk * sizeof *fi);
        if (fi) s->fidx = fi;
        float *fd = realloc(s->fd2, blk * kk * sizeof *fd);
        if (fd) s->fd2 = fd;
        if (!fi || !fd) return sd_errf(err, SD_ENOMEM, "out of memory in a FLANN query");
        s->fcap = blk * kk;
    }
    if (blk > s->qcap) {
        float *q = realloc(s->fq, 3 * blk * sizeof *q);
        if (!q) return sd_errf(err, SD_ENOMEM, "out of memory in a FLANN query");
        s->fq = q;
        s->qcap = blk;
    }
    struct FLANNParameters fp = kn->fp;
    for (size_t b0 = 0; b0 < nq; b0 += blk) {
        size_t m = nq - b0 < blk ? nq - b0 : blk;
        for (size_t i = 0; i < m; i++) {
            size_t qi = qidx ? qidx[b0 + i] : first + b0 + i;
            if (qi >= kn->n)
                return sd_errf(err, SD_EINVAL, "kNN query point %zu is outside the %zu points",
                               qi, kn->n);
            memcpy(s->fq + 3 * i, kn->pos + 3 * qi, 3 * sizeof(float));
        }
        if (flann_find_nearest_neighbors_index_float(kn->flann, s->fq, (int)m, s->fidx, s->fd2,
                                                     (int)kk, &fp) != 0)
            return sd_errf(err, SD_ENOMEM, "FLANN failed a query of %zu points", m);
        for (size_t i = 0; i < m; i++) {
            uint32_t qi = qidx ? qidx[b0 + i] : (uint32_t)(first + b0 + i);
            const int *fi = s->fidx + i * kk;
            const float *fd = s->fd2 + i * kk;
            uint32_t *oi = idx + (b0 + i) * (size_t)k;
            float tmpd[257];
            float *od = d2 ? d2 + (b0 + i) * (size_t)k : tmpd;
            int drop = k; /* the last, unless the query itself is among the results */
            for (int j = 0; j < (int)kk; j++)
                if (fi[j] == (int)qi) { drop = j; break; }
            int o = 0;
            for (int j = 0; j < (int)kk; j++) {
                if (j == drop) continue;
                oi[o] = (uint32_t)fi[j];
                od[o] = fd[j];
                o++;
            }
            prep__knn_sort_pairs(od, oi, k); /* ties in (distance, index) order, like the grid */
        }
    }
    return 0;
}

int prep_knn_query(const prep_knn *kn, const uint32_t *qidx, size_t first, size_t nq, int k,
                   uint32_t *idx, float *d2, prep_knn_scratch *s, sd_err *err)
{
    if (k < 1 || k > 256 || (size_t)k >= kn->n)
        return sd_errf(err, SD_EINVAL, "kNN query for k = %d neighbours among %zu points (k must "
                       "be in [1, min(256, points - 1)])", k, kn->n);
    if (nq == 0) return 0;
    if (kn->method == PREP_KNN_GRID)
        return prep__grid_query(kn->grid, qidx, first, nq, k, idx, d2, s->grid, err);
    return flann_query(kn, qidx, first, nq, k, idx, d2, s, err);
}
