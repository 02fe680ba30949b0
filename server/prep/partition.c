/* partition.c — spatial parts of a cloud: a kd tree over octree cells balancing points and
 * splat area (see partition.h), and the earlier median cuts it replaced. */
#include "partition.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "morton.h"

enum { CELLS = 1u << PREP_MORTON_BITS }; /* finest-level cells per axis */

/* One unit: a leaf cell of the octree and the points it holds. */
typedef struct unit {
    uint32_t lo[3], size;  /* finest-level cells: [lo, lo + size) per axis */
    uint32_t first, count; /* its points: the sorted positions [first, first + count) */
    double fp;             /* their footprint proxy, sum of pi r^2 */
} unit;

typedef struct kd_ctx {
    const uint32_t *perm;  /* sorted position -> point (NULL: the points were in order) */
    uint16_t *part;
    pc_part_box *box;
    const prep_morton_frame *f;
    int axis;              /* for by_lo */
} kd_ctx;

/* point_at: the point at sorted position j. */
static uint32_t point_at(const uint32_t *perm, uint32_t j)
{
    return perm ? perm[j] : j;
}

/* point_fp: a point's weight in the footprint proxy (a bad radius weighs nothing). */
static double point_fp(const float *radius, uint64_t i)
{
    if (!radius) return 1.0;
    double r = radius[i];
    return r > 0 && isfinite(r) ? M_PI * r * r : 0.0;
}

/* leaves: appends the units of the cell at level with codes[a, b) (all sharing its prefix) to
 * u[*nu] (u NULL: counts them), refining while it holds more than cap points. */
static void leaves(const uint64_t *codes, const uint32_t *perm, const float *radius, uint32_t a,
                   uint32_t b, int level, uint32_t cap, unit *u, size_t *nu)
{
    if ((b - a <= cap && level >= PC_PART_MIN_LEVEL) || level == PREP_MORTON_BITS) {
        if (!u) {
            (*nu)++;
            return;
        }
        unit *x = &u[(*nu)++];
        int shift = 3 * (PREP_MORTON_BITS - level);
        uint64_t corner = codes[a] >> shift << shift;
        prep_morton_decode(corner, &x->lo[0], &x->lo[1], &x->lo[2]);
        x->size = CELLS >> level;
        x->first = a;
        x->count = b - a;
        x->fp = 0;
        for (uint32_t j = a; j < b; j++) x->fp += point_fp(radius, point_at(perm, j));
        return;
    }
    int shift = 3 * (PREP_MORTON_BITS - level - 1);
    while (a < b) { /* the children in order: runs of equal 3-bit digits */
        uint64_t digit = codes[a] >> shift & 7;
        uint32_t lo = a + 1, hi = b; /* first index past the run: binary search */
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2;
            if ((codes[mid] >> shift & 7) == digit) lo = mid + 1;
            else hi = mid;
        }
        leaves(codes, perm, radius, a, lo, level + 1, cap, u, nu);
        a = lo;
    }
}

/* by_lo: orders units by their lower corner on ctx->axis, then on the other axes (units are
 * disjoint cells, so the order is total). */
static int by_lo(const void *pa, const void *pb, void *user)
{
    const kd_ctx *c = user;
    const unit *a = pa, *b = pb;
    for (int d = 0; d < 3; d++) {
        int ax = (c->axis + d) % 3;
        if (a->lo[ax] != b->lo[ax]) return a->lo[ax] < b->lo[ax] ? -1 : 1;
    }
    return 0;
}

/* set_box: part p's region is [rlo, rhi) in cells. */
static void set_box(kd_ctx *c, int p, const uint32_t rlo[3], const uint32_t rhi[3])
{
    if (!c->box) return;
    pc_part_box *b = &c->box[p];
    double cell = c->f->side / CELLS;
    for (int a = 0; a < 3; a++) {
        b->cell_lo[a] = rlo[a];
        b->cell_hi[a] = rhi[a];
        b->lo[a] = c->f->origin[a] + cell * rlo[a];
        b->hi[a] = c->f->origin[a] + cell * rhi[a];
    }
}

/* fallback_cut: a plane on some axis strictly inside [rlo, rhi) crossing none of the nu <= 1
 * units (longest axis first): sets *axis, *at; 0 when the region cannot be cut. */
static int fallback_cut(const unit *u, size_t nu, const uint32_t rlo[3], const uint32_t rhi[3],
                        int *axis, uint32_t *at)
{
    int order[3] = {0, 1, 2};
    for (int i = 0; i < 3; i++) /* by extent, descending; stable on ties */
        for (int j = i + 1; j < 3; j++)
            if (rhi[order[j]] - rlo[order[j]] > rhi[order[i]] - rlo[order[i]]) {
                int t = order[i];
                order[i] = order[j];
                order[j] = t;
            }
    for (int i = 0; i < 3; i++) {
        int a = order[i];
        uint32_t c = nu == 0 ? rlo[a] + (rhi[a] - rlo[a]) / 2
                   : u[0].lo[a] > rlo[a] ? u[0].lo[a] : u[0].lo[a] + u[0].size;
        if (c > rlo[a] && c < rhi[a]) {
            *axis = a;
            *at = c;
            return 1;
        }
    }
    return 0;
}

/* kd: the units u[0, nu) inside the region [rlo, rhi) go to parts [first, first + k). */
static void kd(kd_ctx *c, unit *u, size_t nu, const uint32_t rlo[3], const uint32_t rhi[3],
               int first, int k)
{
    if (k == 1) {
        for (size_t j = 0; j < nu; j++)
            for (uint32_t q = 0; q < u[j].count; q++)
                c->part[point_at(c->perm, u[j].first + q)] = (uint16_t)first;
        set_box(c, first, rlo, rhi);
        return;
    }
    int kl = k / 2;
    double t = (double)kl / k, P = 0, F = 0;
    for (size_t j = 0; j < nu; j++) {
        P += u[j].count;
        F += u[j].fp;
    }
    /* best cut: (few units on a side: only when no cut leaves enough, score, longer axis) */
    int best_axis = -1, best_short = 2;
    size_t best_j = 0;
    double best_score = INFINITY;
    for (int a = 0; a < 3 && nu > 1; a++) {
        c->axis = a;
        qsort_r(u, nu, sizeof *u, by_lo, c);
        double pl = 0, fl = 0;
        uint32_t maxhi = 0;
        for (size_t j = 1; j < nu; j++) {
            pl += u[j - 1].count;
            fl += u[j - 1].fp;
            if (u[j - 1].lo[a] + u[j - 1].size > maxhi) maxhi = u[j - 1].lo[a] + u[j - 1].size;
            if (maxhi > u[j].lo[a]) continue; /* a unit left of j reaches past the plane */
            /* max/mean of the two sides' per-part shares, points and footprint */
            double s = fmax(pl / (t * P), (P - pl) / ((1 - t) * P));
            if (F > 0) s = fmax(s, fmax(fl / (t * F), (F - fl) / ((1 - t) * F)));
            int shrt = j < (size_t)kl || nu - j < (size_t)(k - kl);
            int better = shrt < best_short ||
                         (shrt == best_short &&
                          (s < best_score ||
                           (s == best_score && best_axis != a &&
                            rhi[a] - rlo[a] > rhi[best_axis] - rlo[best_axis])));
            if (better) {
                best_axis = a;
                best_j = j;
                best_score = s;
                best_short = shrt;
            }
        }
    }
    uint32_t llo[3], lhi[3], glo[3], ghi[3];
    memcpy(llo, rlo, sizeof llo);
    memcpy(lhi, rhi, sizeof lhi);
    memcpy(glo, rlo, sizeof glo);
    memcpy(ghi, rhi, sizeof ghi);
    if (best_axis >= 0) {
        c->axis = best_axis;
        qsort_r(u, nu, sizeof *u, by_lo, c);
        lhi[best_axis] = glo[best_axis] = u[best_j].lo[best_axis];
    } else {
        /* no unit boundary separates two units: at most one unit here */
        int a;
        uint32_t at;
        if (!fallback_cut(u, nu, rlo, rhi, &a, &at)) {
            /* the region cannot be cut (one unit filling it): the first part takes it, the
             * others get empty boxes at its upper corner */
            kd(c, u, nu, rlo, rhi, first, 1);
            for (int p = first + 1; p < first + k; p++) set_box(c, p, rhi, rhi);
            return;
        }
        lhi[a] = glo[a] = at;
        best_j = nu == 1 && u[0].lo[a] >= at ? 0 : nu;
    }
    kd(c, u, best_j, llo, lhi, first, kl);
    kd(c, u + best_j, nu - best_j, glo, ghi, first + kl, k - kl);
}

static int no_memory(uint64_t n, sd_err *err)
{
    return sd_errf(err, SD_ENOMEM, "out of memory partitioning %llu points", (unsigned long long)n);
}

int pc_partition(const float *pos, const float *radius, uint64_t n, int nparts, uint16_t *part,
                 pc_part_box *box, sd_err *err)
{
    if (nparts < 1 || nparts > PC_PART_MAX)
        return sd_errf(err, SD_EINVAL, "%d parts: 1 to %d", nparts, PC_PART_MAX);
    if (n >= UINT32_MAX)
        return sd_errf(err, SD_EINVAL, "%llu points to partition: at most %u",
                       (unsigned long long)n, UINT32_MAX - 1);
    prep_morton_frame f;
    prep_morton_frame_of(pos, (size_t)n, &f);
    size_t m = n ? (size_t)n : 1;
    uint64_t *codes = malloc(m * sizeof *codes);
    uint32_t *perm = NULL;
    unit *u = NULL;
    int rc = codes ? 0 : no_memory(n, err);
    /* A prepared cloud is stored in the Morton order of this very frame (prep.c): then the
     * codes are already sorted and the radix sort and its 16 bytes a point are skipped. */
    int sorted = 1;
    for (uint64_t i = 0; rc == 0 && i < n; i++) {
        codes[i] = prep_morton_code(&f, pos + 3 * i);
        if (i && codes[i] < codes[i - 1]) sorted = 0;
    }
    if (rc == 0 && !sorted) {
        perm = malloc(m * sizeof *perm);
        rc = perm ? prep_morton_sort(pos, (size_t)n, &f, codes, perm, err) : no_memory(n, err);
    }
    uint64_t cap = n / ((uint64_t)PC_PART_CELL_DIV * (uint64_t)nparts);
    size_t nu = 0;
    if (rc == 0 && n) { /* count the units, then make them */
        leaves(codes, perm, radius, 0, (uint32_t)n, 0, cap ? (uint32_t)cap : 1, NULL, &nu);
        u = malloc(nu * sizeof *u);
        if (!u) rc = sd_errf(err, SD_ENOMEM, "out of memory for %zu octree cells", nu);
        nu = 0;
        if (u) leaves(codes, perm, radius, 0, (uint32_t)n, 0, cap ? (uint32_t)cap : 1, u, &nu);
    }
    if (rc == 0) {
        kd_ctx c = {.perm = perm, .part = part, .box = box, .f = &f};
        uint32_t rlo[3] = {0, 0, 0}, rhi[3] = {CELLS, CELLS, CELLS};
        kd(&c, u, nu, rlo, rhi, 0, nparts);
    }
    free(u);
    free(perm);
    free(codes);
    return rc;
}

void pc_partition_balance(const float *radius, uint64_t n, const uint16_t *part, int nparts,
                          double *pts, double *fp, double *pts_imb, double *fp_imb)
{
    double tp = 0, tf = 0;
    for (int p = 0; p < nparts; p++) pts[p] = fp[p] = 0;
    for (uint64_t i = 0; i < n; i++) {
        double w = point_fp(radius, i);
        pts[part[i]] += 1;
        fp[part[i]] += w;
        tp += 1;
        tf += w;
    }
    double mp = 0, mf = 0;
    for (int p = 0; p < nparts; p++) {
        pts[p] = tp > 0 ? pts[p] / tp : 0;
        fp[p] = tf > 0 ? fp[p] / tf : 0;
        mp = fmax(mp, pts[p]);
        mf = fmax(mf, fp[p]);
    }
    *pts_imb = mp * nparts;
    *fp_imb = mf * nparts;
}

/* ---- the earlier partition: recursive median cuts along the longest axis ---- */

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

/* split (median cuts): idx[0..cnt) go to parts [first, first + k). */
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

int pc_partition_median(const float *pos, uint64_t n, int nparts, uint16_t *part, sd_err *err)
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
