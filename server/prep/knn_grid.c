/* knn_grid.c — exact kNN over the octree cells that Morton order makes contiguous.
 *
 * Build: the points are sorted by 63-bit Morton code (morton.c), and the octree is split into
 * leaves of at most leaf_size points (a leaf is a cell at some level 0..21; the points of any
 * cell are one run of the sorted array, found by (galloping) binary search on the codes).
 *
 * Query for point q (queries are issued in Morton order, so consecutive ones are neighbours):
 *  1. pick a level: the finest whose cells are at least r wide, r = the previous query's k-th
 *     distance x R_SCALE (for the first query, or when that block is huge: q's leaf level);
 *  2. the candidates are all points of the 3x3x3 block of cells around q's cell at that level
 *     (gathered once into structure-of-arrays buffers and shared by the following queries);
 *  3. the k nearest candidates (by squared distance, then index; q itself excluded by index)
 *     are exact if the k-th distance is below the distance from q to the block's boundary:
 *     every point outside the block is at least that far. A block face at the grid's edge has
 *     nothing beyond it and does not count;
 *  4. otherwise the k-th distance found bounds the true one, and the block of cells that wide
 *     settles it in one more step (with too few candidates: the finest coarser level whose
 *     block holds k + 1 points). Level 0 is the whole cloud, so every search ends exact.
 * Selection computes all candidate distances eight at a time (AVX2 where the CPU has it),
 * counts those within a few radii around the previous k-th distance, and sorts only the
 * (distance, index) keys within the smallest radius that holds k + 1. A leaf whose block holds more than GRID_CAP points (a
 * sparse cell next to a dense one: outliers near a surface) starts from the finest level
 * whose block still holds k + 1 points. Measured against FLANN's exact kd-tree on the same
 * Morton-ordered points (tests/bench/bench_prep.sh): about 2x less CPU time. */
#include "knn_grid.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "morton.h"

enum {
    GRID_CAP = 4096, /* candidates above which a leaf's queries search individually */
    NSLOTS = 4,      /* cached candidate blocks per scratch */
    MAXLEVEL = PREP_MORTON_BITS,
};

/* The predicted k-th distance is the previous query's times this (measured on the synthetic
 * 1M scene: 1.0 widens 1.5 % of the blocks, 1.15 0.5 % and is fastest, 1.3 gathers more). */
#define R_SCALE 1.15

struct prep__grid {
    size_t n;
    const float *pos;        /* the caller's points */
    const float *spos;       /* the points in Morton order (pos itself when already sorted) */
    float *spos_own;
    uint64_t *codes;         /* sorted Morton codes */
    uint32_t *order;         /* sorted position -> index in pos; NULL: identity */
    uint32_t *rank;          /* index in pos -> sorted position; NULL: identity */
    uint32_t *leaf_first;    /* nleaves + 1 entries; the last is n */
    uint8_t *leaf_level;
    size_t nleaves, leaf_cap;
    prep_morton_frame f;
    double cell[MAXLEVEL + 1]; /* cell edge length at each level */
    double eps;              /* safety margin on block distances (float rounding) */
};

typedef struct cand_set {
    int valid, level, h, too_big;  /* the block is cell +- h at level */
    uint64_t cell;           /* the centre cell's code at level */
    uint64_t stamp;          /* last use, for replacement */
    size_t m, cap;           /* candidates; arrays are padded to a multiple of 8 */
    float *x, *y, *z;
    uint32_t *id;
    double lo[3], hi[3];     /* block faces; -inf / +inf where the block reaches the grid edge */
} cand_set;

struct prep__grid_scratch {
    cand_set set[NSLOTS];
    uint64_t clock;
    float *d2;               /* candidate distances */
    uint64_t *key;           /* (distance, index) keys of the candidates that pass the filter */
    size_t d2cap;
    float hd[256 + 2];       /* the selected pairs */
    uint32_t hid[256 + 2];
    int have_prev;           /* the previous query, for the level choice and select_k's filter */
    float prev_q[3], prev_kd2;
    size_t leaf;
    prep_knn_counters cnt;
};

/* ---- build ---- */

/* First index in [lo, hi) whose code is >= key. */
static size_t lower_bound(const uint64_t *c, size_t lo, size_t hi, uint64_t key)
{
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (c[mid] < key) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* First index in [lo, n) whose code is >= key, searching outwards from hint (>= lo): the runs
 * of a query's neighbour cells lie near the query's own position in Morton order, so a
 * galloping search touches a few nearby cache lines instead of the whole array. */
static size_t lower_bound_near(const uint64_t *c, size_t lo, size_t n, size_t hint, uint64_t key)
{
    if (hint < lo) hint = lo;
    if (hint >= n) return lower_bound(c, lo, n, key);
    size_t step = 1;
    if (c[hint] < key) { /* the answer is right of hint */
        size_t a = hint + 1;
        while (a + step <= n && c[a + step - 1] < key) {
            a += step;
            step *= 2;
        }
        return lower_bound(c, a, a + step <= n ? a + step - 1 : n, key);
    }
    size_t b = hint; /* c[b] >= key: the answer is at or left of b */
    while (b >= lo + step && c[b - step] >= key) {
        b -= step;
        step *= 2;
    }
    return lower_bound(c, b >= lo + step ? b - step + 1 : lo, b, key);
}

static int push_leaf(prep__grid *g, size_t first, int level)
{
    if (g->nleaves + 1 >= g->leaf_cap) {
        size_t cap = g->leaf_cap ? 2 * g->leaf_cap : 1024;
        uint32_t *a = realloc(g->leaf_first, cap * sizeof *a);
        if (!a) return -1;
        g->leaf_first = a;
        uint8_t *b = realloc(g->leaf_level, cap);
        if (!b) return -1;
        g->leaf_level = b;
        g->leaf_cap = cap;
    }
    g->leaf_first[g->nleaves] = (uint32_t)first;
    g->leaf_level[g->nleaves] = (uint8_t)level;
    g->nleaves++;
    return 0;
}

/* Splits the cell at level whose points are codes[lo, hi) until each leaf has at most m points
 * (or is a finest-level cell). Returns 0 or -1 when out of memory. */
static int split(prep__grid *g, size_t lo, size_t hi, int level, size_t m)
{
    if (hi - lo <= m || level >= MAXLEVEL) return push_leaf(g, lo, level);
    int sh = 3 * (MAXLEVEL - level - 1);
    for (size_t a = lo; a < hi;) {
        uint64_t pre = g->codes[a] >> sh;
        size_t b = lower_bound(g->codes, a, hi, (pre + 1) << sh);
        if (split(g, a, b, level + 1, m) != 0) return -1;
        a = b;
    }
    return 0;
}

int prep__grid_build(const float *pos, size_t n, int leaf_size, prep__grid **out, sd_err *err)
{
    prep__grid *g = calloc(1, sizeof *g);
    if (!g) return sd_errf(err, SD_ENOMEM, "out of memory for a kNN grid");
    g->n = n;
    g->pos = pos;
    g->spos = pos;
    prep_morton_frame_of(pos, n, &g->f);
    for (int l = 0; l <= MAXLEVEL; l++) g->cell[l] = g->f.side / (double)(1u << l);
    g->eps = 1e-6 * g->f.side;
    g->codes = malloc((n ? n : 1) * sizeof *g->codes);
    uint32_t *perm = malloc((n ? n : 1) * sizeof *perm);
    if (!g->codes || !perm) {
        free(perm);
        prep__grid_free(g);
        return sd_errf(err, SD_ENOMEM, "out of memory for the kNN grid of %zu points", n);
    }
    int rc = prep_morton_sort(pos, n, &g->f, g->codes, perm, err);
    if (rc != 0) {
        free(perm);
        prep__grid_free(g);
        return rc;
    }
    size_t i = 0;
    while (i < n && perm[i] == i) i++;
    if (i == n) {
        free(perm); /* already in Morton order: index the caller's array directly */
    } else {
        g->order = perm;
        g->rank = malloc(n * sizeof *g->rank);
        g->spos_own = malloc(3 * n * sizeof *g->spos_own);
        if (!g->rank || !g->spos_own) {
            prep__grid_free(g);
            return sd_errf(err, SD_ENOMEM, "out of memory for the kNN grid of %zu points", n);
        }
        for (size_t s = 0; s < n; s++) {
            g->rank[perm[s]] = (uint32_t)s;
            memcpy(g->spos_own + 3 * s, pos + 3 * (size_t)perm[s], 3 * sizeof(float));
        }
        g->spos = g->spos_own;
    }
    if (n > 0 && split(g, 0, n, 0, (size_t)(leaf_size > 0 ? leaf_size : 32)) != 0) {
        prep__grid_free(g);
        return sd_errf(err, SD_ENOMEM, "out of memory for the kNN grid of %zu points", n);
    }
    if (push_leaf(g, n, 0) != 0) { /* sentinel: leaf_first[nleaves] = n */
        prep__grid_free(g);
        return sd_errf(err, SD_ENOMEM, "out of memory for the kNN grid of %zu points", n);
    }
    g->nleaves--;
    *out = g;
    return 0;
}

void prep__grid_free(prep__grid *g)
{
    if (!g) return;
    free(g->spos_own);
    free(g->codes);
    free(g->order);
    free(g->rank);
    free(g->leaf_first);
    free(g->leaf_level);
    free(g);
}

/* ---- scratch ---- */

prep__grid_scratch *prep__grid_scratch_new(void)
{
    return calloc(1, sizeof(prep__grid_scratch));
}

void prep__grid_scratch_free(prep__grid_scratch *s)
{
    if (!s) return;
    for (int i = 0; i < NSLOTS; i++) {
        free(s->set[i].x);
        free(s->set[i].y);
        free(s->set[i].z);
        free(s->set[i].id);
    }
    free(s->d2);
    free(s->key);
    free(s);
}

void prep__grid_counters(const prep__grid_scratch *s, prep_knn_counters *c)
{
    *c = s->cnt;
}

/* ---- blocks of cells ---- */

typedef struct block {
    size_t nr;                 /* runs of consecutive points */
    size_t ra[125], rb[125];   /* [ra, rb) in sorted positions */
    size_t count;
    double lo[3], hi[3];
} block;

/* Finds the runs of sorted points in the cells cell +- h (per axis) at level, the block's
 * faces, and the number of points. Cells adjacent in Morton order are merged into one run. */
static void block_of(const prep__grid *g, uint64_t cell, int level, int h, size_t hint, block *b)
{
    uint32_t c[3], a0[3], a1[3];
    prep_morton_decode(cell, &c[0], &c[1], &c[2]);
    uint32_t maxc = (1u << level) - 1;
    for (int a = 0; a < 3; a++) {
        a0[a] = c[a] > (uint32_t)h ? c[a] - (uint32_t)h : 0;
        a1[a] = c[a] + (uint32_t)h < maxc ? c[a] + (uint32_t)h : maxc;
        b->lo[a] = a0[a] == 0 ? -INFINITY : g->f.origin[a] + a0[a] * g->cell[level];
        b->hi[a] = a1[a] == maxc ? INFINITY : g->f.origin[a] + (a1[a] + 1.0) * g->cell[level];
    }
    uint64_t codes[125];
    int nc = 0;
    for (uint32_t z = a0[2]; z <= a1[2]; z++)
        for (uint32_t y = a0[1]; y <= a1[1]; y++)
            for (uint32_t x = a0[0]; x <= a1[0]; x++) {
                uint64_t v = prep_morton_encode(x, y, z);
                int j = nc++;
                while (j > 0 && codes[j - 1] > v) { codes[j] = codes[j - 1]; j--; }
                codes[j] = v;
            }
    int sh = 3 * (MAXLEVEL - level);
    b->nr = 0;
    b->count = 0;
    size_t from = 0;
    for (int i = 0; i < nc;) {
        int j = i;
        while (j + 1 < nc && codes[j + 1] == codes[j] + 1) j++;
        size_t ra = lower_bound_near(g->codes, from, g->n, hint, codes[i] << sh);
        size_t rb = lower_bound_near(g->codes, ra, g->n, ra, (codes[j] + 1) << sh);
        from = rb;
        if (rb > ra) {
            b->ra[b->nr] = ra;
            b->rb[b->nr] = rb;
            b->nr++;
            b->count += rb - ra;
        }
        i = j + 1;
    }
}

/* Grows a candidate set's arrays to hold cap points (rounded up to a multiple of 8). */
static int reserve(cand_set *cs, size_t cap)
{
    cap = (cap + 7) & ~(size_t)7;
    if (cap <= cs->cap) return 0;
    size_t nc = cs->cap ? cs->cap : 256;
    while (nc < cap) nc *= 2;
    float *x = realloc(cs->x, nc * sizeof *x);
    if (x) cs->x = x;
    float *y = realloc(cs->y, nc * sizeof *y);
    if (y) cs->y = y;
    float *z = realloc(cs->z, nc * sizeof *z);
    if (z) cs->z = z;
    uint32_t *id = realloc(cs->id, nc * sizeof *id);
    if (id) cs->id = id;
    if (!x || !y || !z || !id) return -1;
    cs->cap = nc;
    return 0;
}

/* The candidate set for (cell, level, h), from the scratch's cache or gathered now. With
 * allow_big, a block of more than GRID_CAP points is not gathered but marked too_big. hint is
 * the query's sorted position (where the block's runs are searched from).
 * Returns NULL when out of memory. */
static cand_set *get_set(const prep__grid *g, prep__grid_scratch *s, uint64_t cell, int level,
                         int h, int allow_big, size_t hint)
{
    cand_set *cs = NULL;
    for (int i = 0; i < NSLOTS; i++) {
        cand_set *t = &s->set[i];
        if (t->valid && t->cell == cell && t->level == level && t->h == h &&
            (allow_big || !t->too_big)) {
            t->stamp = ++s->clock;
            return t;
        }
        if (!cs || !t->valid || (cs->valid && t->stamp < cs->stamp)) cs = t;
    }
    block b;
    block_of(g, cell, level, h, hint, &b);
    cs->valid = 0;
    cs->cell = cell;
    cs->level = level;
    cs->h = h;
    cs->stamp = ++s->clock;
    memcpy(cs->lo, b.lo, sizeof b.lo);
    memcpy(cs->hi, b.hi, sizeof b.hi);
    cs->too_big = allow_big && b.count > GRID_CAP;
    cs->m = 0;
    if (!cs->too_big) {
        if (reserve(cs, b.count) != 0) return NULL;
        size_t m = 0;
        for (size_t r = 0; r < b.nr; r++)
            for (size_t p = b.ra[r]; p < b.rb[r]; p++, m++) {
                const float *v = g->spos + 3 * p;
                cs->x[m] = v[0];
                cs->y[m] = v[1];
                cs->z[m] = v[2];
                cs->id[m] = g->order ? g->order[p] : (uint32_t)p;
            }
        cs->m = m;
        for (; m & 7; m++) { cs->x[m] = cs->y[m] = cs->z[m] = 0; cs->id[m] = 0; }
    }
    cs->valid = 1;
    return cs;
}

/* ---- selection ---- */

/* (d, id) pairs are ordered by d, then id: a total order, so results do not depend on the
 * order candidates are visited in. */
static int pair_less(float d, uint32_t id, float e, uint32_t jd)
{
    return d < e || (d == e && id < jd);
}

/* (d, id) as one integer key whose order is pair_less's: a non-negative float's bits compare
 * like the float. */
static uint64_t pair_key(float d, uint32_t id)
{
    uint32_t u;
    memcpy(&u, &d, sizeof u);
    return (uint64_t)u << 32 | id;
}

static void insertion_sort_keys(uint64_t *a, size_t n)
{
    for (size_t i = 1; i < n; i++) {
        uint64_t v = a[i];
        size_t j = i;
        while (j > 0 && a[j - 1] > v) { a[j] = a[j - 1]; j--; }
        a[j] = v;
    }
}

/* Makes a[0..k) the k smallest of the n keys a, ascending (k <= n), by insertion into a sorted
 * prefix: for n a little over k, as select_k's filter leaves it, this beats a quickselect. */
static void smallest_sorted(uint64_t *a, size_t n, size_t k)
{
    if (k == 0) return;
    insertion_sort_keys(a, k);
    for (size_t i = k; i < n; i++) {
        uint64_t v = a[i];
        if (v >= a[k - 1]) continue;
        size_t j = k - 1;
        while (j > 0 && a[j - 1] > v) { a[j] = a[j - 1]; j--; }
        a[j] = v;
    }
}

/* Reorders the n distinct keys a so that a[0..k) are the k smallest, ascending (k <= n):
 * quickselect down to small ranges, then insertion sort of the first k. */
static void smallest_keys(uint64_t *a, size_t n, size_t k)
{
    size_t lo = 0, hi = n; /* the k-th boundary lies in [lo, hi) */
    while (hi - lo > 24) {
        size_t mid = lo + (hi - lo) / 2;
        uint64_t x = a[lo], y = a[mid], z = a[hi - 1];
        uint64_t piv = x < y ? (y < z ? y : (x < z ? z : x)) : (x < z ? x : (y < z ? z : y));
        size_t i = lo, j = hi - 1;
        for (;;) { /* Hoare partition: [lo, j] <= piv <= [j + 1, hi) */
            while (a[i] < piv) i++;
            while (a[j] > piv) j--;
            if (i >= j) break;
            uint64_t t = a[i]; a[i] = a[j]; a[j] = t;
            i++;
            j--;
        }
        if (k <= j + 1) hi = j + 1;
        else lo = j + 1;
    }
    /* a[0..lo) are all smaller than a[lo..n); sort what the boundary range needs */
    insertion_sort_keys(a + lo, hi - lo);
    insertion_sort_keys(a, k);
}

typedef float v8f __attribute__((vector_size(32)));
typedef int v8i __attribute__((vector_size(32)));

/* On x86-64 the distance loop is compiled twice, for AVX2 and for the baseline (where each
 * 8-wide operation becomes two SSE ones); the loader picks one for the CPU at hand. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define PREP_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define PREP_CLONES
#endif

/* Squared distances from q of the m8 candidates x, y, z (m8 a multiple of 8) into d2, and in
 * cnt[i] how many are <= t[i], for the four thresholds t. */
PREP_CLONES static void distances(const float *x, const float *y, const float *z, size_t m8,
                                  const float q[3], const float t[4], float *d2, size_t cnt[4])
{
    const v8f zero = {0, 0, 0, 0, 0, 0, 0, 0};
    const v8f qx = zero + q[0], qy = zero + q[1], qz = zero + q[2];
    const v8f t0 = zero + t[0], t1 = zero + t[1], t2 = zero + t[2], t3 = zero + t[3];
    v8i c0 = {0, 0, 0, 0, 0, 0, 0, 0}, c1 = c0, c2 = c0, c3 = c0;
    for (size_t j = 0; j < m8; j += 8) {
        v8f vx, vy, vz;
        memcpy(&vx, x + j, sizeof vx);
        memcpy(&vy, y + j, sizeof vy);
        memcpy(&vz, z + j, sizeof vz);
        v8f dx = vx - qx, dy = vy - qy, dz = vz - qz;
        v8f d = dx * dx + dy * dy + dz * dz;
        memcpy(d2 + j, &d, sizeof d);
        c0 += d <= t0; /* true lanes are -1 */
        c1 += d <= t1;
        c2 += d <= t2;
        c3 += d <= t3;
    }
    const v8i cs[4] = {c0, c1, c2, c3};
    for (int i = 0; i < 4; i++) {
        int sum = 0;
        for (int l = 0; l < 8; l++) sum -= cs[i][l];
        cnt[i] = (size_t)sum;
    }
}

/* Writes the keys of the candidates j < m whose d2[j] <= t to key; returns how many. The
 * candidates near q come in runs, so most groups of four have none: one mask test skips them,
 * and set lanes are visited by their bits. */
static size_t compact(const float *d2, const uint32_t *id, size_t m, size_t m8, float t,
                      uint64_t *key)
{
    size_t c = 0;
#if defined(__SSE2__)
    const __m128 tv = _mm_set1_ps(t);
    for (size_t j = 0; j < m8; j += 4) {
        unsigned mask = (unsigned)_mm_movemask_ps(_mm_cmple_ps(_mm_loadu_ps(d2 + j), tv));
        while (mask) {
            size_t jj = j + (size_t)__builtin_ctz(mask);
            mask &= mask - 1;
            if (jj < m) key[c++] = pair_key(d2[jj], id[jj]);
        }
    }
#else
    for (size_t j = 0; j < m; j++)
        if (d2[j] <= t) key[c++] = pair_key(d2[j], id[j]);
#endif
    return c;
}

/* Grows the scratch's per-candidate buffers to hold m8 entries. */
static int reserve_scratch(prep__grid_scratch *s, size_t m8)
{
    if (m8 <= s->d2cap) return 0;
    size_t nc = s->d2cap ? s->d2cap : 256;
    while (nc < m8) nc *= 2;
    float *d = realloc(s->d2, nc * sizeof *d);
    if (d) s->d2 = d;
    uint64_t *ky = realloc(s->key, nc * sizeof *ky);
    if (ky) s->key = ky;
    if (!d || !ky) return -1;
    s->d2cap = nc;
    return 0;
}

/* The k nearest candidates of q other than self (by index), ascending, into s->hd / s->hid;
 * returns how many (k, or fewer when the set is small), or -1 when out of memory.
 *
 * Selects the k + 1 smallest pairs of all candidates, then removes self where found, else the
 * last (self is among the k + 1 smallest unless k + 1 other points precede it, and then the k
 * smallest are all other points). To make selection cheap, candidates are first filtered by
 * a radius guessed from the previous query's k-th distance. The filter only prunes when at
 * least k + 1 candidates pass it (then the k + 1 smallest are among them), otherwise all are
 * used, so the result never depends on the guess. */
static int select_k(prep__grid_scratch *s, const cand_set *cs, const float q[3], uint32_t self,
                    int k)
{
    size_t m = cs->m, m8 = (m + 7) & ~(size_t)7;
    if (reserve_scratch(s, m8) != 0) return -1;
    float *d2 = s->d2;
    /* Consecutive queries are neighbours in Morton order with similar k-th distances: count
     * the candidates within radii a little over the previous query's while computing the
     * distances, and keep only those within the smallest radius that holds k + 1. */
    enum { NT = 4 };
    static const float mult[NT] = {1.05f, 1.3f, 1.8f, 4.0f};
    float tp = s->have_prev ? s->prev_kd2 : -1.0f, t[NT];
    for (int i = 0; i < NT; i++) t[i] = tp * mult[i];
    size_t cnt[NT];
    distances(cs->x, cs->y, cs->z, m8, q, t, d2, cnt);
    int k1 = k + 1, found;
    uint64_t *key = s->key;
    size_t c = 0;
    for (int i = 0; i < NT; i++) {
        /* padding lanes (j >= m) have coordinates 0 and may count: an over-count only makes
         * the compaction below come up short, and then every candidate is used */
        if (cnt[i] < (size_t)k1) continue;
        c = compact(d2, cs->id, m, m8, t[i], key);
        break;
    }
    if (c < (size_t)k1)
        for (c = 0; c < m; c++) key[c] = pair_key(d2[c], cs->id[c]);
    s->cnt.filtered += c;
    found = c < (size_t)k1 ? (int)c : k1;
    if (c <= 64) smallest_sorted(key, c, (size_t)found);
    else smallest_keys(key, c, (size_t)found);
    for (int i = 0; i < found; i++) {
        uint32_t u = (uint32_t)(key[i] >> 32);
        memcpy(&s->hd[i], &u, sizeof u);
        s->hid[i] = (uint32_t)key[i];
    }
    int drop = -1;
    for (int i = 0; i < found && drop < 0; i++)
        if (s->hid[i] == self) drop = i;
    if (drop < 0 && found == k1) drop = found - 1;
    if (drop >= 0) {
        memmove(s->hd + drop, s->hd + drop + 1, (size_t)(found - 1 - drop) * sizeof *s->hd);
        memmove(s->hid + drop, s->hid + drop + 1, (size_t)(found - 1 - drop) * sizeof *s->hid);
        found--;
    }
    return found;
}

void prep__knn_sort_pairs(float *d2, uint32_t *idx, int m)
{
    for (int i = 1; i < m; i++) {
        float d = d2[i];
        uint32_t id = idx[i];
        int j = i;
        while (j > 0 && pair_less(d, id, d2[j - 1], idx[j - 1])) {
            d2[j] = d2[j - 1];
            idx[j] = idx[j - 1];
            j--;
        }
        d2[j] = d;
        idx[j] = id;
    }
}

/* The leaf holding sorted position p (the scratch remembers the last one). */
static size_t find_leaf(const prep__grid *g, prep__grid_scratch *s, size_t p)
{
    size_t l = s->leaf;
    if (l < g->nleaves && g->leaf_first[l] <= p && p < g->leaf_first[l + 1]) return l;
    if (l + 1 < g->nleaves && g->leaf_first[l + 1] <= p && p < g->leaf_first[l + 2])
        return s->leaf = l + 1;
    size_t lo = 0, hi = g->nleaves; /* last leaf whose first <= p */
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (g->leaf_first[mid] <= p) lo = mid;
        else hi = mid;
    }
    return s->leaf = lo;
}

/* The finest level in [lo, hi] whose block (h = 1) around code holds more than k points, or lo
 * when none does; the count only shrinks as levels get finer, so a binary search finds it. */
static int finest_level(const prep__grid *g, uint64_t code, size_t hint, int lo, int hi, int k)
{
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        block b;
        block_of(g, code >> 3 * (MAXLEVEL - mid), mid, 1, hint, &b);
        if (b.count > (size_t)k) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

/* The finest level whose cells are at least r wide (0 when even the root is narrower). */
static int level_for(const prep__grid *g, double r)
{
    int l = MAXLEVEL;
    while (l > 0 && g->cell[l] < r) l--;
    return l;
}

/* Whether the k-th distance found is provably the k-th nearest: below the distance from q to
 * every finite face of the block, less a margin for float rounding. */
static int exact_enough(const prep__grid *g, const cand_set *cs, const float q[3], int found,
                        int k, float maxd2)
{
    double dmin = INFINITY;
    for (int a = 0; a < 3; a++) {
        dmin = fmin(dmin, (double)q[a] - cs->lo[a]);
        dmin = fmin(dmin, cs->hi[a] - (double)q[a]);
    }
    if (dmin == INFINITY) return 1; /* the block is the whole cloud */
    if (found < k) return 0;
    double lim = dmin - g->eps;
    return lim > 0 && (double)maxd2 < lim * lim;
}

/* One query: the k nearest points of the point at index qi, into idx/d2 (ascending). */
static int query_one(const prep__grid *g, prep__grid_scratch *s, uint32_t qi, int k,
                     uint32_t *idx, float *d2)
{
    size_t sp = g->rank ? g->rank[qi] : qi;
    const float *q = g->pos + 3 * (size_t)qi;
    uint64_t code = g->codes[sp];
    int level = -1, h = 1;
    cand_set *cs;
    float ddx = q[0] - s->prev_q[0], ddy = q[1] - s->prev_q[1], ddz = q[2] - s->prev_q[2];
    if (s->have_prev && ddx * ddx + ddy * ddy + ddz * ddz <= 16 * s->prev_kd2) {
        /* The previous query, when it is a neighbour (as in Morton order), predicts the k-th
         * distance r: cells at least r wide make the 3x3x3 block reach r beyond q in every
         * direction. */
        int l = level_for(g, sqrt((double)s->prev_kd2) * R_SCALE);
        cs = get_set(g, s, code >> 3 * (MAXLEVEL - l), l, 1, 1, sp);
        if (!cs) return -1;
        if (!cs->too_big) level = l;
    }
    if (level < 0) { /* no usable prediction: the leaf's level */
        size_t lf = find_leaf(g, s, sp);
        level = g->leaf_level[lf];
        cs = get_set(g, s, code >> 3 * (MAXLEVEL - level), level, 1, 1, sp);
        if (!cs) return -1;
        if (cs->too_big) {
            s->cnt.dense++;
            level = finest_level(g, code, sp, level, MAXLEVEL, k);
        }
    }
    int found;
    for (;;) {
        cs = get_set(g, s, code >> 3 * (MAXLEVEL - level), level, h, 0, sp);
        if (!cs) return -1;
        found = select_k(s, cs, q, qi, k);
        if (found < 0) return -1;
        s->cnt.candidates += cs->m;
        if (exact_enough(g, cs, q, found, k, found > 0 ? s->hd[found - 1] : 0)) break;
        s->cnt.widened++;
        int l = level;
        if (found == k) {
            /* The k-th distance found bounds the true one, so a block of cells that wide
             * settles it in one step. */
            l = level_for(g, sqrt((double)s->hd[k - 1]) * (1 + 1e-5) + 2 * g->eps);
        } else if (level > 0) {
            /* Too few points: the finest coarser level whose block holds enough. */
            l = finest_level(g, code, sp, 0, level - 1, k);
        }
        if (l < level) { level = l; h = 1; }
        else if (h == 1) h = 2; /* float rounding at a cell face: widen in place */
        else if (level > 0) level--;
        else break; /* unreachable: level 0 is the whole cloud */
    }
    memcpy(idx, s->hid, (size_t)found * sizeof *idx);
    if (d2) memcpy(d2, s->hd, (size_t)found * sizeof *d2);
    s->have_prev = found == k;
    memcpy(s->prev_q, q, sizeof s->prev_q);
    s->prev_kd2 = found > 0 ? s->hd[found - 1] : 0;
    s->cnt.queries++;
    return 0;
}

int prep__grid_query(const prep__grid *g, const uint32_t *qidx, size_t first, size_t nq, int k,
                     uint32_t *idx, float *d2, prep__grid_scratch *s, sd_err *err)
{
    if (k < 1 || k > 256 || (size_t)k >= g->n)
        return sd_errf(err, SD_EINVAL, "kNN query for k = %d neighbours among %zu points", k,
                       g->n);
    /* The cached blocks may belong to another grid: start clean. */
    for (int i = 0; i < NSLOTS; i++) s->set[i].valid = 0;
    s->leaf = 0;
    s->have_prev = 0;

    for (size_t i = 0; i < nq; i++) {
        uint32_t qi = qidx ? qidx[i] : (uint32_t)(first + i);
        if (qi >= g->n)
            return sd_errf(err, SD_EINVAL, "kNN query point %u is outside the %zu points", qi,
                           g->n);
        if (query_one(g, s, qi, k, idx + i * (size_t)k, d2 ? d2 + i * (size_t)k : NULL) != 0)
            return sd_errf(err, SD_ENOMEM, "out of memory in a kNN query");
    }
    return 0;
}
