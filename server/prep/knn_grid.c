/* knn_grid.c — exact kNN over the octree cells that Morton order makes contiguous.
 *
 * Build: the points are sorted by 63-bit Morton code (morton.c), and the octree is split into
 * leaves of at most leaf_size points (a leaf is a cell at some level 0..21; the points of any
 * cell are one run of the sorted array, found by (galloping) binary search on the codes; a
 * query scratch remembers the run bounds it found, since consecutive blocks share most cells).
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
 *  4. otherwise the k-th distance found bounds the true one, and a block reaching that far
 *     settles it in one more step: two cells each way of the level below the one whose cells
 *     are that wide (2.5 such cells across instead of 3; with too few candidates: the finest
 *     coarser level whose block holds k + 1 points). Level 0 is the whole cloud, so every
 *     search ends exact.
 * Selection computes all candidate distances eight (AVX-512: sixteen) at a time and, in the
 * same pass, left-packs those within the previous k-th distance (times a little) into a short
 * list (AVX2: one compare, one table lookup and two permutes per 8 candidates; AVX-512: one
 * compare into a mask and two compresses per 16; no branch per candidate, no store where none
 * passes); when that holds fewer than k + 1, wider radii, then all; when it holds more than
 * RANK_MAX, a bisection on the distance bits narrows it. The k + 1 smallest (distance, index)
 * pairs of the list are placed by rank: each pair's count of smaller distances builds up in
 * its own vector lane as every pair is broadcast against the list (no sort, no horizontal
 * sum); ties on a distance (ranks not all distinct) take a slower ranking by index. Every
 * path computes each distance as (dx * dx + dy * dy) + dz * dz in float without fused
 * multiply-adds: the same bits, the same neighbours (test_prep pins each path against a brute
 * force). A leaf whose block holds more than GRID_CAP points (a sparse cell next to a dense
 * one: outliers near a surface) starts from the finest level whose block still holds k + 1
 * points. Measured against FLANN's exact kd-tree on the same Morton-ordered points
 * (tests/bench/bench_prep.sh): about 2x less CPU time before the packed selection, which took
 * the 2M synthetic scene's queries from 1.66 to 1.15 us each here, and the AVX-512 path and
 * lane ranks to ~0.8 us (prep_bench --knn-only --threads 1). */
#include "knn_grid.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define PREP_X86_AVX2 1 /* an AVX2 path beside the portable one, chosen per CPU at build */
#endif

#include "morton.h"
#include "simd.h"

enum {
    GRID_CAP = 4096, /* candidates above which a leaf's queries search individually */
    RANK_MAX = 96,   /* selections from more candidates sort keys instead of ranking */
    KD_PAD = 32,     /* room past the packed candidates (vector stores, ranking blocks) */
    NSLOTS = 4,      /* cached candidate blocks per scratch */
    MAXLEVEL = PREP_MORTON_BITS,
    BOUND_BITS = 11, /* the scratch's cache of run bounds: 2^BOUND_BITS entries */
};

/* The predicted k-th distance is the previous query's times this (measured on the synthetic
 * 1M scene: 1.0 widens 1.5 % of the blocks, 1.15 0.5 % and is fastest, 1.3 gathers more). */
#define R_SCALE 1.15
/* select_k's first filter keeps the candidates within the previous query's k-th distance times
 * sqrt(FILTER_GROW) (measured on the synthetic 2M scene: see select_k). */
#ifndef FILTER_GROW
#define FILTER_GROW 1.3f
#endif

struct prep__grid {
    size_t n;
    const float *pos;        /* the caller's points */
    const float *spos;       /* the points in Morton order (pos itself when already sorted) */
    float *spos_own;
    uint64_t *codes;         /* sorted Morton codes */
    int codes_borrowed;      /* codes are the caller's (prep_knn_opts.codes) */
    int simd;                /* PREP_KNN_SIMD_* in use (never BEST) */
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
    size_t m, cap;           /* candidates; arrays are padded to a multiple of 16 */
    float *x, *y, *z;
    uint32_t *id;
    double lo[3], hi[3];     /* block faces; -inf / +inf where the block reaches the grid edge */
} cand_set;

/* A cached run bound: the first sorted position whose code is >= key (lower_bound over the
 * whole array), valid while gen is the scratch's (one prep__grid_query call: one grid). */
typedef struct bound_ent {
    uint64_t key;
    uint32_t pos, gen;
} bound_ent;

struct prep__grid_scratch {
    cand_set set[NSLOTS];
    bound_ent bound[1 << BOUND_BITS];
    uint32_t gen;
    uint64_t clock;
    float *d2;               /* candidate distances */
    uint64_t *key;           /* (distance, index) keys, for selections from many candidates */
    uint32_t *kd, *kid;      /* the candidates that pass the filter: distance bits, index */
    size_t d2cap;            /* entries in d2 and key; kd and kid hold KD_PAD more */
    uint32_t rank[RANK_MAX + KD_PAD]; /* rank_select's ranks */
    uint8_t pack[256][8];    /* for each 8-bit mask, its set lanes in order (left-packing) */
    uint8_t popc[256];
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

int prep__grid_build(const float *pos, size_t n, int leaf_size, const prep_morton_frame *frame,
                     const uint64_t *codes, int simd, prep__grid **out, sd_err *err)
{
    prep__grid *g = calloc(1, sizeof *g);
    if (!g) return sd_errf(err, SD_ENOMEM, "out of memory for a kNN grid");
    g->n = n;
    g->pos = pos;
    g->spos = pos;
    if (frame) g->f = *frame;
    else prep_morton_frame_of(pos, n, &g->f);
    for (int l = 0; l <= MAXLEVEL; l++) g->cell[l] = g->f.side / (double)(1u << l);
    g->eps = 1e-6 * g->f.side;
    int best = PREP_KNN_SIMD_PORTABLE;
#ifdef PREP_X86_AVX2
    if (__builtin_cpu_supports("avx2")) best = PREP_KNN_SIMD_AVX2;
    if (best == PREP_KNN_SIMD_AVX2 && __builtin_cpu_supports("avx512f") &&
        __builtin_cpu_supports("popcnt"))
        best = PREP_KNN_SIMD_AVX512;
#endif
    g->simd = simd > PREP_KNN_SIMD_BEST && simd < best ? simd : best;
    size_t sorted = 1;
    if (codes)
        while (sorted < n && codes[sorted - 1] <= codes[sorted]) sorted++;
    uint32_t *perm = NULL;
    if (codes && sorted >= n) {
        g->codes = (uint64_t *)codes; /* the caller's, in order: index them as they are */
        g->codes_borrowed = 1;
    } else {
        g->codes = malloc((n ? n : 1) * sizeof *g->codes);
        perm = malloc((n ? n : 1) * sizeof *perm);
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
    }
    size_t i = 0;
    while (perm && i < n && perm[i] == i) i++;
    if (!perm || i == n) {
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
    if (!g->codes_borrowed) free(g->codes);
    free(g->order);
    free(g->rank);
    free(g->leaf_first);
    free(g->leaf_level);
    free(g);
}

/* ---- scratch ---- */

prep__grid_scratch *prep__grid_scratch_new(void)
{
    prep__grid_scratch *s = calloc(1, sizeof(prep__grid_scratch));
    if (!s) return NULL;
    for (int m = 0; m < 256; m++) {
        int c = 0;
        for (int l = 0; l < 8; l++)
            if (m >> l & 1) s->pack[m][c++] = (uint8_t)l;
        s->popc[m] = (uint8_t)c;
    }
    return s;
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
    free(s->kd);
    free(s->kid);
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

/* The first sorted position whose code is >= key, from the scratch's cache or searched now
 * outwards from hint and remembered. The cells of consecutive blocks are mostly the same (a
 * 3x3x3 block and the next one share 18 of 27), so most bounds are found again: a search
 * through the codes (cache misses) becomes one hashed lookup. The answer is the whole array's
 * lower bound; callers pass from <= that (block_of: the previous, smaller key's bound). */
static size_t bound_of(const prep__grid *g, prep__grid_scratch *s, size_t from, size_t hint,
                       uint64_t key)
{
    bound_ent *e = &s->bound[(key * 0x9E3779B97F4A7C15ull) >> (64 - BOUND_BITS)];
    if (e->gen == s->gen && e->key == key) return e->pos;
    size_t p = lower_bound_near(g->codes, from, g->n, hint, key);
    e->key = key, e->pos = (uint32_t)p, e->gen = s->gen;
    return p;
}

/* Finds the runs of sorted points in the cells cell +- h (per axis) at level, the block's
 * faces, and the number of points. Cells adjacent in Morton order are merged into one run. */
static void block_of(const prep__grid *g, prep__grid_scratch *s, uint64_t cell, int level,
                     int h, size_t hint, block *b)
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
        size_t ra = bound_of(g, s, from, hint, codes[i] << sh);
        size_t rb = bound_of(g, s, ra, ra, (codes[j] + 1) << sh);
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

/* Grows a candidate set's arrays to hold cap points (rounded up to a multiple of 16). */
static int reserve(cand_set *cs, size_t cap)
{
    cap = (cap + 15) & ~(size_t)15;
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

#ifdef PREP_X86_AVX2
/* Copies the points pa, pa + 1, ... of sp (x, y, z interleaved) into x, y, z, 16 at a time
 * while 16 remain before pb (three loads, six permutes), and with id their positions; returns
 * the first point not copied. */
__attribute__((target("avx512f"))) static size_t copy_run_avx512(const float *sp, size_t pa,
                                                                size_t pb, float *x, float *y,
                                                                float *z, uint32_t *id)
{
    /* from a|b (indices 0-31) the first lanes, then the rest from c (16 + its index) */
    const __m512i xa = _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0);
    const __m512i xc = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29);
    const __m512i ya = _mm512_setr_epi32(1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0);
    const __m512i yc = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30);
    const __m512i za = _mm512_setr_epi32(2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0);
    const __m512i zc = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31);
    const __m512i step = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    size_t p = pa;
    for (; p + 16 <= pb; p += 16) {
        const float *src = sp + 3 * p;
        __m512 a = _mm512_loadu_ps(src), b = _mm512_loadu_ps(src + 16);
        __m512 c = _mm512_loadu_ps(src + 32);
        size_t o = p - pa;
        _mm512_storeu_ps(x + o, _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, xa, b), xc, c));
        _mm512_storeu_ps(y + o, _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, ya, b), yc, c));
        _mm512_storeu_ps(z + o, _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, za, b), zc, c));
        if (id)
            _mm512_storeu_si512(id + o, _mm512_add_epi32(_mm512_set1_epi32((int)p), step));
    }
    return p;
}
#endif

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
    block_of(g, s, cell, level, h, hint, &b);
    s->cnt.gathers++;
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
        float *restrict x = cs->x, *restrict y = cs->y, *restrict z = cs->z;
        uint32_t *restrict id = cs->id;
        const float *restrict sp = g->spos;
        for (size_t r = 0; r < b.nr; r++) {
            size_t pa = b.ra[r], pb = b.rb[r], p = pa;
#ifdef PREP_X86_AVX2
            if (g->simd >= PREP_KNN_SIMD_AVX512) p = copy_run_avx512(sp, pa, pb, x + m, y + m,
                                                                   z + m, g->order ? NULL : id + m);
#endif
            for (; p < pb; p++) {
                x[m + p - pa] = sp[3 * p];
                y[m + p - pa] = sp[3 * p + 1];
                z[m + p - pa] = sp[3 * p + 2];
                if (!g->order) id[m + p - pa] = (uint32_t)p;
            }
            if (g->order) memcpy(id + m, g->order + pa, (pb - pa) * sizeof *id);
            m += pb - pa;
        }
        cs->m = m;
        for (; m & 15; m++) { cs->x[m] = cs->y[m] = cs->z[m] = 0; cs->id[m] = 0; }
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

static void insertion_sort_keys(uint64_t *a, size_t n)
{
    for (size_t i = 1; i < n; i++) {
        uint64_t v = a[i];
        size_t j = i;
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

static uint32_t fbits(float d)
{
    uint32_t u;
    memcpy(&u, &d, sizeof u);
    return u;
}

typedef prep_v8f v8f;
typedef prep_v8i v8i;

/* The squared distances from q of the m8 candidates x, y, z (a multiple of 8) into d2. */
PREP_CLONES static void distances(const cand_set *cs, size_t m8, const float q[3], float *d2)
{
    const v8f zero = {0, 0, 0, 0, 0, 0, 0, 0};
    const v8f qx = zero + q[0], qy = zero + q[1], qz = zero + q[2];
    for (size_t j = 0; j < m8; j += 8) {
        v8f vx, vy, vz;
        memcpy(&vx, cs->x + j, sizeof vx);
        memcpy(&vy, cs->y + j, sizeof vy);
        memcpy(&vz, cs->z + j, sizeof vz);
        v8f dx = vx - qx, dy = vy - qy, dz = vz - qz;
        v8f d = dx * dx + dy * dy + dz * dz;
        memcpy(d2 + j, &d, sizeof d);
    }
}

/* The squared distances from q of the m candidates x, y, z into d2 (with fresh; otherwise they
 * are in d2 already), and the candidates with d2 <= t left-packed into kd (distance bits) and
 * kid (index); returns how many. Every distance is dx * dx + dy * dy + dz * dz in float, in
 * that order, on both paths: the same bits either way. */
static size_t pack_scalar(const cand_set *cs, const float q[3], float t, int fresh, float *d2,
                          uint32_t *kd, uint32_t *kid)
{
    size_t c = 0;
    if (fresh) distances(cs, (cs->m + 7) & ~(size_t)7, q, d2);
    for (size_t j = 0; j < cs->m; j++) {
        kd[c] = fbits(d2[j]); /* written always, counted when it passes: no branch */
        kid[c] = cs->id[j];
        c += d2[j] <= t;
    }
    return c;
}

#ifdef PREP_X86_AVX2
/* pack_scalar 8 candidates at a time (arrays padded to a multiple of 8; kd, kid 8 more). */
__attribute__((target("avx2"))) static size_t pack_avx2(const prep__grid_scratch *s,
                                                        const cand_set *cs, const float q[3],
                                                        float t, int fresh, float *d2,
                                                        uint32_t *kd, uint32_t *kid)
{
    const __m256 qx = _mm256_set1_ps(q[0]), qy = _mm256_set1_ps(q[1]), qz = _mm256_set1_ps(q[2]);
    const __m256 tv = _mm256_set1_ps(t);
    const float *restrict x = cs->x, *restrict y = cs->y, *restrict z = cs->z;
    const uint32_t *restrict id = cs->id;
    const uint8_t(*restrict lut)[8] = s->pack, *restrict popc = s->popc;
    size_t m = cs->m, c = 0;
    for (size_t j = 0; j < m; j += 8) {
        __m256 d;
        if (fresh) {
            __m256 dx = _mm256_sub_ps(_mm256_loadu_ps(x + j), qx);
            __m256 dy = _mm256_sub_ps(_mm256_loadu_ps(y + j), qy);
            __m256 dz = _mm256_sub_ps(_mm256_loadu_ps(z + j), qz);
            d = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                              _mm256_mul_ps(dz, dz));
            _mm256_storeu_ps(d2 + j, d);
        } else {
            d = _mm256_loadu_ps(d2 + j);
        }
        unsigned mask = (unsigned)_mm256_movemask_ps(_mm256_cmp_ps(d, tv, _CMP_LE_OQ));
        if (m - j < 8) mask &= (1u << (m - j)) - 1; /* padding lanes */
        if (!mask) continue; /* most blocks: nothing passes, nothing stored */
        __m256i perm = _mm256_cvtepu8_epi32(_mm_loadl_epi64((const __m128i *)lut[mask]));
        __m256i vd = _mm256_permutevar8x32_epi32(_mm256_castps_si256(d), perm);
        __m256i vi = _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i *)(id + j)),
                                                 perm);
        _mm256_storeu_si256((__m256i *)(kd + c), vd);
        _mm256_storeu_si256((__m256i *)(kid + c), vi);
        c += popc[mask];
    }
    return c;
}
#endif

#ifdef PREP_X86_AVX2
/* pack_scalar 16 candidates at a time (arrays padded to a multiple of 16; kd, kid 16 more):
 * one compare into a mask and two compresses, no table. */
__attribute__((target("avx512f,popcnt"))) static size_t pack_avx512(const cand_set *cs,
                                                                  const float q[3], float t,
                                                                  int fresh, float *d2,
                                                                  uint32_t *kd, uint32_t *kid)
{
    const __m512 qx = _mm512_set1_ps(q[0]), qy = _mm512_set1_ps(q[1]), qz = _mm512_set1_ps(q[2]);
    const __m512 tv = _mm512_set1_ps(t);
    const float *restrict x = cs->x, *restrict y = cs->y, *restrict z = cs->z;
    const uint32_t *restrict id = cs->id;
    size_t m = cs->m, c = 0;
    (void)fresh; /* distances are recomputed (cheaper than storing them for a rare retry) */
    (void)d2;
    for (size_t j = 0; j < m; j += 16) {
        __m512 dx = _mm512_sub_ps(_mm512_loadu_ps(x + j), qx);
        __m512 dy = _mm512_sub_ps(_mm512_loadu_ps(y + j), qy);
        __m512 dz = _mm512_sub_ps(_mm512_loadu_ps(z + j), qz);
        /* no fused multiply-add: the same bits as the other paths */
        __m512 d = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(dx, dx), _mm512_mul_ps(dy, dy)),
                                 _mm512_mul_ps(dz, dz));
        __mmask16 k = _mm512_cmp_ps_mask(d, tv, _CMP_LE_OQ);
        if (m - j < 16) k &= (__mmask16)((1u << (m - j)) - 1); /* padding lanes */
        if (!k) continue; /* most blocks: nothing passes, nothing stored */
        _mm512_storeu_si512(kd + c, _mm512_maskz_compress_epi32(k, _mm512_castps_si512(d)));
        _mm512_storeu_si512(kid + c,
                            _mm512_maskz_compress_epi32(k, _mm512_loadu_si512(id + j)));
        c += (size_t)__builtin_popcount(k);
    }
    return c;
}
#endif

static size_t pack(const prep__grid *g, const prep__grid_scratch *s, const cand_set *cs,
                   const float q[3], float t, int fresh, float *d2, uint32_t *kd, uint32_t *kid)
{
#ifdef PREP_X86_AVX2
    if (g->simd >= PREP_KNN_SIMD_AVX512) return pack_avx512(cs, q, t, fresh, d2, kd, kid);
    if (g->simd >= PREP_KNN_SIMD_AVX2) return pack_avx2(s, cs, q, t, fresh, d2, kd, kid);
#endif
    (void)g;
    (void)s;
    return pack_scalar(cs, q, t, fresh, d2, kd, kid);
}

/* The rank of each of the c packed pairs in (distance, index) order, 8 pairs at a time; those
 * of rank < found go to hd / hid at their rank: the found smallest, ascending, with no sort and
 * no branch per pair. The pairs are distinct (indices are), so the ranks are 0..c-1, each once.
 * Distance bits of non-negative floats order like the floats and are below 2^31, so signed
 * compares do. kd and kid have room for c rounded up to 8 (padded here with a pair greater
 * than any). A distance shared with another pair (rare: duplicate points, regular grids)
 * settles its rank by the indices, in a scalar loop. */
PREP_CLONES static void rank_pairs(uint32_t *kd, uint32_t *kid, size_t c, int found, float *hd,
                                   uint32_t *hid)
{
    size_t c8 = (c + 7) & ~(size_t)7;
    for (size_t j = c; j < c8; j++) kd[j] = kid[j] = 0x7fffffffu;
    for (size_t i = 0; i < c; i++) {
        const v8i di = (v8i){0, 0, 0, 0, 0, 0, 0, 0} + (int)kd[i];
        v8i lt = {0, 0, 0, 0, 0, 0, 0, 0}, eq = lt;
        for (size_t j = 0; j < c8; j += 8) {
            v8i dj;
            memcpy(&dj, kd + j, sizeof dj);
            lt += dj < di; /* true lanes are -1 */
            eq += dj == di;
        }
        /* both counts in one horizontal sum: lt in the high half-words, eq in the low */
        v8i v = (lt << 16) + eq;
        int sum = 0;
        for (int l = 0; l < 8; l++) sum += v[l];
        uint32_t u = (uint32_t)-sum;
        size_t r = u >> 16;
        if ((u & 0xffff) > 1) /* ties on the distance: the smaller indices come first */
            for (size_t j = 0; j < c; j++) r += kd[j] == kd[i] && kid[j] < kid[i];
        if (r < (size_t)found) {
            memcpy(&hd[r], &kd[i], sizeof kd[i]);
            hid[r] = kid[i];
        }
    }
}

/* r[j] = how many of the c distance bits kd are below kd[j] (kd padded to a multiple of 16):
 * each block of pairs is compared with every pair broadcast, so a rank builds up in its lane,
 * with no horizontal sum. Two blocks at a time (independent chains). */
PREP_CLONES static void ranks_below(const uint32_t *kd, size_t c, uint32_t *r)
{
    for (size_t j = 0; j < c; j += 16) {
        v8i d0, d1, a0 = {0, 0, 0, 0, 0, 0, 0, 0}, a1 = a0;
        memcpy(&d0, kd + j, sizeof d0);
        memcpy(&d1, kd + j + 8, sizeof d1);
        for (size_t i = 0; i < c; i++) {
            int di = (int)kd[i];
            a0 += d0 > di; /* true lanes are -1 */
            a1 += d1 > di;
        }
        a0 = -a0;
        a1 = -a1;
        memcpy(r + j, &a0, sizeof a0);
        memcpy(r + j + 8, &a1, sizeof a1);
    }
}

#ifdef PREP_X86_AVX2
/* ranks_below 16 lanes wide, two blocks at a time (kd padded to a multiple of 32). */
__attribute__((target("avx512f"))) static void ranks_below_avx512(const uint32_t *kd, size_t c,
                                                                  uint32_t *r)
{
    const __m512i one = _mm512_set1_epi32(1);
    size_t j = 0;
    for (; j + 16 < c; j += 32) {
        __m512i d0 = _mm512_loadu_si512(kd + j), d1 = _mm512_loadu_si512(kd + j + 16);
        __m512i a0 = _mm512_setzero_si512(), a1 = a0;
        for (size_t i = 0; i < c; i++) {
            __m512i di = _mm512_set1_epi32((int)kd[i]);
            a0 = _mm512_mask_add_epi32(a0, _mm512_cmplt_epi32_mask(di, d0), a0, one);
            a1 = _mm512_mask_add_epi32(a1, _mm512_cmplt_epi32_mask(di, d1), a1, one);
        }
        _mm512_storeu_si512(r + j, a0);
        _mm512_storeu_si512(r + j + 16, a1);
    }
    if (j < c) {
        __m512i d0 = _mm512_loadu_si512(kd + j), a0 = _mm512_setzero_si512();
        for (size_t i = 0; i < c; i++)
            a0 = _mm512_mask_add_epi32(
                a0, _mm512_cmplt_epi32_mask(_mm512_set1_epi32((int)kd[i]), d0), a0, one);
        _mm512_storeu_si512(r + j, a0);
    }
}
#endif

/* The found smallest of the c packed pairs (c <= RANK_MAX) into s->hd / s->hid, ascending.
 * Ranks by distance alone (ranks_below); when no two distances are equal these are the ranks
 * 0..c-1, each once, which their sum tells: each pair goes straight to its place. Otherwise
 * (duplicate points, regular grids) rank_pairs settles the ties by index. */
static void rank_select(const prep__grid *g, prep__grid_scratch *s, size_t c, int found)
{
    uint32_t *kd = s->kd, *kid = s->kid, *r = s->rank;
    for (size_t j = c; j < ((c + KD_PAD - 1) & ~(size_t)(KD_PAD - 1)); j++) kd[j] = 0x7fffffffu;
#ifdef PREP_X86_AVX2
    if (g->simd >= PREP_KNN_SIMD_AVX512) ranks_below_avx512(kd, c, r);
    else ranks_below(kd, c, r);
#else
    (void)g;
    ranks_below(kd, c, r);
#endif
    size_t sum = 0;
    for (size_t j = 0; j < c; j++) sum += r[j];
    if (sum != c * (c - 1) / 2) {
        rank_pairs(kd, kid, c, found, s->hd, s->hid);
        return;
    }
    for (size_t j = 0; j < c; j++) { /* every rank < c <= RANK_MAX: inside hd, hid */
        memcpy(&s->hd[r[j]], &kd[j], sizeof kd[j]);
        s->hid[r[j]] = kid[j];
    }
}

/* How many of the c distance bits kd are <= v (kd padded to a multiple of 8 with values above
 * any distance). */
PREP_CLONES static size_t count_le(const uint32_t *kd, size_t c, int v)
{
    v8i acc = {0, 0, 0, 0, 0, 0, 0, 0};
    for (size_t j = 0; j < c; j += 8) {
        v8i d;
        memcpy(&d, kd + j, sizeof d);
        acc += d <= v; /* true lanes are -1 */
    }
    int sum = 0;
    for (int l = 0; l < 8; l++) sum -= acc[l];
    return (size_t)sum;
}

/* When more than RANK_MAX candidates passed the filter (a bad guess: the first query of a
 * call, a jump in density), keeps only those within a smaller distance that still holds at
 * least k1 of them, found by a few guesses, then bisection, on the distance bits (which order
 * like the distances),
 * so the ranking applies. Returns the new count (unchanged when ties at one distance hold
 * more than RANK_MAX: the caller sorts keys then). The k1 smallest are among those kept. */
enum { NARROW_AIM = 48, NARROW_GUESSES = 4 };

static size_t narrow(uint32_t *kd, uint32_t *kid, size_t c, size_t k1)
{
    for (size_t j = c; j < ((c + 7) & ~(size_t)7); j++) kd[j] = 0x7fffffffu;
    uint32_t lo = 0x7fffffffu, hi = 0;
    for (size_t j = 0; j < c; j++) {
        hi = kd[j] > hi ? kd[j] : hi;
        lo = kd[j] < lo ? kd[j] : lo;
    }
    /* invariant: count(<= hi) > RANK_MAX and count(< lo) < k1 (at first: none below the least).
     * The first steps guess where NARROW_AIM of them lie, as if the count grew with the square
     * of the distance (points on a surface; d is a squared distance: linearly), scaling the last
     * guess by the count it gave; then bisection. Only the steps differ: any cut that keeps
     * between k1 and RANK_MAX keeps the k1 smallest pairs. */
    float g;
    memcpy(&g, &hi, sizeof g);
    size_t n = c;
    for (int step = 0; lo < hi; step++) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (step < NARROW_GUESSES) { /* g: the last cut tried, n: how many it kept */
            float t = g * ((float)NARROW_AIM / (float)n);
            uint32_t tb;
            memcpy(&tb, &t, sizeof tb);
            if (tb >= lo && tb < hi) mid = tb; /* else (or NaN, inf) bisect */
        }
        n = count_le(kd, c, (int)mid);
        memcpy(&g, &mid, sizeof g);
        if (n < k1) {
            lo = mid + 1;
        } else if (n > RANK_MAX) {
            hi = mid;
        } else {
            size_t w = 0;
            for (size_t j = 0; j < c; j++) { /* left-pack those <= mid, no branch */
                kd[w] = kd[j];
                kid[w] = kid[j];
                w += kd[j] <= mid;
            }
            return w;
        }
    }
    return c;
}

/* Grows the scratch's per-candidate buffers to hold m16 entries. */
static int reserve_scratch(prep__grid_scratch *s, size_t m16)
{
    if (m16 <= s->d2cap) return 0;
    size_t nc = s->d2cap ? s->d2cap : 256;
    while (nc < m16) nc *= 2;
    float *d = realloc(s->d2, nc * sizeof *d);
    if (d) s->d2 = d;
    uint64_t *ky = realloc(s->key, nc * sizeof *ky);
    if (ky) s->key = ky;
    uint32_t *kd = realloc(s->kd, (nc + KD_PAD) * sizeof *kd);
    if (kd) s->kd = kd;
    uint32_t *ki = realloc(s->kid, (nc + KD_PAD) * sizeof *ki);
    if (ki) s->kid = ki;
    if (!d || !ky || !kd || !ki) return -1;
    s->d2cap = nc;
    return 0;
}


/* The k nearest candidates of q other than self (by index), ascending, into s->hd / s->hid;
 * returns how many (k, or fewer when the set is small), or -1 when out of memory.
 *
 * Selects the k + 1 smallest pairs of all candidates, then removes self where found, else the
 * last (self is among the k + 1 smallest unless k + 1 other points precede it, and then the k
 * smallest are all other points). To make selection cheap, candidates are first filtered by
 * a radius guessed from the previous query's k-th distance, in the same pass that computes
 * the distances. The filter only prunes when at least k + 1 candidates pass it (then the
 * k + 1 smallest are among them); otherwise wider radii are tried, and at last all candidates
 * are used, so the result never depends on the guess. The few that pass are ranked against
 * each other (no sort, no branch per candidate). */
static int select_k(const prep__grid *g, prep__grid_scratch *s, const cand_set *cs,
                    const float q[3], uint32_t self, int k)
{
    size_t m = cs->m, m16 = (m + 15) & ~(size_t)15;
    if (reserve_scratch(s, m16) != 0) return -1;
    float *d2 = s->d2;
    uint32_t *kd = s->kd, *kid = s->kid;
    int k1 = k + 1, found;
    /* Consecutive queries are neighbours in Morton order with similar k-th distances. */
    float tp = s->have_prev ? s->prev_kd2 : INFINITY;
    size_t c = pack(g, s, cs, q, tp * FILTER_GROW, 1, d2, kd, kid);
    if (c < (size_t)k1 && c < m) {
        static const float wider[2] = {2.0f, 4.0f};
        for (int i = 0; i < 3 && c < (size_t)k1; i++)
            c = pack(g, s, cs, q, i < 2 ? tp * wider[i] : INFINITY, 0, d2, kd, kid);
    }
    if (c > RANK_MAX) c = narrow(kd, kid, c, (size_t)k1);
    s->cnt.filtered += c;
    found = c < (size_t)k1 ? (int)c : k1;
    if (c <= RANK_MAX) {
        rank_select(g, s, c, found);
    } else {
        uint64_t *key = s->key;
        for (size_t j = 0; j < c; j++) key[j] = (uint64_t)kd[j] << 32 | kid[j];
        smallest_keys(key, c, (size_t)found);
        for (int i = 0; i < found; i++) {
            uint32_t u = (uint32_t)(key[i] >> 32);
            memcpy(&s->hd[i], &u, sizeof u);
            s->hid[i] = (uint32_t)key[i];
        }
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
static int finest_level(const prep__grid *g, prep__grid_scratch *s, uint64_t code, size_t hint,
                        int lo, int hi, int k)
{
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        block b;
        block_of(g, s, code >> 3 * (MAXLEVEL - mid), mid, 1, hint, &b);
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
    double dmin = INFINITY; /* no NaN here (finite q, faces finite or infinite): fmin's result */
    for (int a = 0; a < 3; a++) {
        double lo = (double)q[a] - cs->lo[a], hi = cs->hi[a] - (double)q[a];
        if (lo < dmin) dmin = lo;
        if (hi < dmin) dmin = hi;
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
            level = finest_level(g, s, code, sp, level, MAXLEVEL, k);
        }
    }
    int found;
    for (;;) {
        cs = get_set(g, s, code >> 3 * (MAXLEVEL - level), level, h, 0, sp);
        if (!cs) return -1;
        found = select_k(g, s, cs, q, qi, k);
        if (found < 0) return -1;
        s->cnt.candidates += cs->m;
        if (exact_enough(g, cs, q, found, k, found > 0 ? s->hd[found - 1] : 0)) break;
        s->cnt.widened++;
        int l = level;
        if (found == k) {
            /* The k-th distance found bounds the true one, so a block of cells that wide
             * settles it in one step. */
            l = level_for(g, sqrt((double)s->hd[k - 1]) * (1 + 1e-5) + 2 * g->eps);
            /* Two cells of the next finer level reach as far as one of l: that block is 2.5
             * cells of l wide instead of 3 (0.58 of the volume; widened blocks are a query's
             * own, mostly sparse points beside dense ones). When it does not settle it
             * (rounding at a face), the block of l follows. */
            if (l < MAXLEVEL && (l + 1 < level || (l + 1 == level && h == 1))) {
                level = l + 1;
                h = 2;
                continue;
            }
        } else if (level > 0) {
            /* Too few points: the finest coarser level whose block holds enough. */
            l = finest_level(g, s, code, sp, 0, level - 1, k);
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
    /* The cached blocks and bounds may belong to another grid: start clean. */
    for (int i = 0; i < NSLOTS; i++) s->set[i].valid = 0;
    if (++s->gen == 0) { /* wrapped: no entry may look current */
        memset(s->bound, 0, sizeof s->bound);
        s->gen = 1;
    }
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
