/* test_prep.c — preprocessing: Morton order, the eigen solver, kNN (grid and FLANN) against
 * brute force, normals, radius, F, sigma, thread independence, progress and bad input. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "knn.h"
#include "morton.h"
#include "pca.h"
#include "prep.h"
#include "testutil.h"

/* ---- helpers ---- */

#include "rng.h"

/* A cloud of n points with only positions, owning pos (freed by pc_cloud_free). */
static pc_cloud make_cloud(size_t n)
{
    pc_cloud c;
    memset(&c, 0, sizeof c);
    c.n = n;
    c.pos = calloc(3 * n, sizeof(float));
    assert_non_null(c.pos);
    strcpy(c.format, "synthetic");
    return c;
}

static double dot3(const float *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return x < y ? -1 : x > y;
}

static void load_data(const char *name, pc_cloud *c)
{
    char path[1024];
    sd_err err = {0};
    int rc = pc_load(tu_data(name, path, sizeof path), c, &err);
    if (rc != 0) fail_msg("pc_load(%s): %s", path, err.msg);
}

/* ---- Morton codes ---- */

static void test_morton_roundtrip_and_sort(void **state)
{
    (void)state;
    rng r = {1};
    for (int i = 0; i < 10000; i++) {
        uint32_t x = (uint32_t)(next64(&r) & 0x1fffff), y = (uint32_t)(next64(&r) & 0x1fffff);
        uint32_t z = (uint32_t)(next64(&r) & 0x1fffff), a, b, c;
        uint64_t code = prep_morton_encode(x, y, z);
        assert_true(code < (1ull << 63));
        prep_morton_decode(code, &a, &b, &c);
        assert_int_equal(a, x);
        assert_int_equal(b, y);
        assert_int_equal(c, z);
    }
    /* Interleaving: x is bit 0, y bit 1, z bit 2. */
    assert_int_equal(prep_morton_encode(1, 0, 0), 1);
    assert_int_equal(prep_morton_encode(0, 1, 0), 2);
    assert_int_equal(prep_morton_encode(0, 0, 1), 4);
    assert_int_equal(prep_morton_encode(2, 0, 0), 8);

    size_t n = 50000;
    float *pos = malloc(3 * n * sizeof *pos);
    uint64_t *codes = malloc(n * sizeof *codes);
    uint32_t *perm = malloc(n * sizeof *perm);
    uint8_t *seen = calloc(n, 1);
    assert_non_null(pos); assert_non_null(codes); assert_non_null(perm); assert_non_null(seen);
    for (size_t i = 0; i < 3 * n; i++) pos[i] = (float)(uni(&r) * 200 - 100);
    pos[0] = pos[3]; pos[1] = pos[4]; pos[2] = pos[5]; /* a duplicate: stable order */
    prep_morton_frame f;
    prep_morton_frame_of(pos, n, &f);
    sd_err err = {0};
    assert_int_equal(prep_morton_sort(pos, n, &f, codes, perm, &err), 0);
    for (size_t i = 0; i < n; i++) {
        assert_true(perm[i] < n);
        assert_false(seen[perm[i]]);
        seen[perm[i]] = 1;
        assert_true(codes[i] == prep_morton_code(&f, pos + 3 * (size_t)perm[i]));
        if (i) assert_true(codes[i - 1] <= codes[i]);
        if (i && codes[i - 1] == codes[i]) assert_true(perm[i - 1] < perm[i]);
    }
    free(pos); free(codes); free(perm); free(seen);
}

/* morton.h's rule for a point outside the frame: its cell on each axis is clamped to
 * [0, 2^21 - 1]. The frame of the unit cube's two corners; a point far beyond the high corner
 * is in the last cell on all three axes, so its code has all 63 bits set, one far below the low
 * corner (or NaN) in cell 0. Proves the clamp returns the last cell, not one past it (which the
 * 21-bit spreading would wrap to cell 0). */
/* prep_radix_sort64 against qsort by (key, original position) on key sets that take each of
 * its paths: arrays below and above RADIX_MSD_MIN (2^18: LSD passes over the whole array, or an
 * MSD split first), random 64-bit keys (the MSD digit at the top bit), keys that differ only in
 * their low bits (one MSD pass, no LSD), few distinct keys (ties: stability), one bucket
 * holding most keys (a large LSD sort beside tiny ones), short arrays (the insertion sort,
 * with ties). */
typedef struct keypos {
    uint64_t k;
    uint32_t p;
} keypos;

static int cmp_keypos(const void *a, const void *b)
{
    const keypos *x = a, *y = b;
    if (x->k != y->k) return x->k < y->k ? -1 : 1;
    return x->p < y->p ? -1 : x->p > y->p;
}

static void test_radix_sort(void **state)
{
    (void)state;
    enum { N = 300000 };
    uint64_t *k = malloc(N * sizeof *k);
    uint32_t *p = malloc(N * sizeof *p);
    keypos *want = malloc(N * sizeof *want);
    assert_non_null(k); assert_non_null(p); assert_non_null(want);
    rng r = {9};
    for (int set = 0; set < 13; set++) {
        size_t n = set == 12 ? 30 : set == 11 ? 40 : set < 6 ? N : 5000;
        for (size_t i = 0; i < n; i++) {
            uint64_t v = next64(&r);
            switch (set == 12 ? 5 : set % 6) {
            case 0: k[i] = v; break;
            case 1: k[i] = 0x1234000000000000ull | (v & 0x3ff); break;
            case 2: k[i] = (v % 7) << 40 | (v >> 60); break;
            case 3: k[i] = i % 10 ? (0x5ull << 58 | (v & 0xffffffff)) : v >> 1; break;
            case 4: k[i] = v & 0x7fffffffffffull; break;
            default: k[i] = v % (set == 12 ? 3 : 5); break;
            }
            p[i] = (uint32_t)i;
            want[i].k = k[i];
            want[i].p = (uint32_t)i;
        }
        qsort(want, n, sizeof *want, cmp_keypos);
        sd_err err = {0};
        assert_int_equal(prep_radix_sort64(k, p, n, &err), 0);
        for (size_t i = 0; i < n; i++)
            if (k[i] != want[i].k || p[i] != want[i].p)
                fail_msg("key set %d (n %zu), position %zu: key %llx from %u, want %llx from %u",
                         set, n, i, (unsigned long long)k[i], p[i],
                         (unsigned long long)want[i].k, want[i].p);
    }
    free(k); free(p); free(want);
}

static void test_morton_clamps_outside_points(void **state)
{
    (void)state;
    const float corners[6] = {0, 0, 0, 1, 1, 1};
    prep_morton_frame f;
    prep_morton_frame_of(corners, 2, &f);
    const uint64_t all = (1ull << 63) - 1;
    const float high[3] = {5, 5, 5}, low[3] = {-5, -5, -5};
    assert_true(prep_morton_code(&f, high) == all);
    assert_true(prep_morton_code(&f, low) == 0);
    /* Mixed: x beyond the high side (all x bits, every third bit from bit 0), y and z below. */
    const float mixed[3] = {1e6f, -1e6f, NAN};
    assert_true(prep_morton_code(&f, mixed) == 0x1249249249249249ull);
    const float inf[3] = {INFINITY, INFINITY, INFINITY};
    assert_true(prep_morton_code(&f, inf) == all);
}

/* ---- eigen solver ---- */

/* A random rotation (from a random unit quaternion) into R (rows are the eigenvectors). */
static void random_rotation(rng *r, double R[3][3])
{
    double q[4], l = 0;
    for (int i = 0; i < 4; i++) { q[i] = gauss(r); l += q[i] * q[i]; }
    l = sqrt(l);
    double w = q[0] / l, x = q[1] / l, y = q[2] / l, z = q[3] / l;
    double m[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                      {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                      {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    memcpy(R, m, sizeof m);
}

/* A = sum_i ev[i] R[i] R[i]^T */
static prep_sym3 compose(double R[3][3], const double ev[3])
{
    double A[3][3] = {{0}};
    for (int i = 0; i < 3; i++)
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) A[a][b] += ev[i] * R[i][a] * R[i][b];
    return (prep_sym3){A[0][0], A[0][1], A[0][2], A[1][1], A[1][2], A[2][2]};
}

static void test_eigen_solver(void **state)
{
    (void)state;
    rng r = {7};
    for (int t = 0; t < 20000; t++) {
        double R[3][3], ev[3], got[3], v[3];
        random_rotation(&r, R);
        /* eigenvalue spreads from isotropic-ish to plane-like (1e-8 relative smallest) */
        double scale = pow(10, uni(&r) * 12 - 6);
        ev[0] = scale * (t % 3 == 0 ? 1e-8 * uni(&r) : uni(&r));
        ev[1] = ev[0] + scale * (0.05 + uni(&r));
        ev[2] = ev[1] + scale * uni(&r);
        prep_sym3 A = compose(R, ev);
        prep_sym3_eigenvalues(&A, got);
        /* Closed-form eigenvalues carry an absolute error of a few ulps of the largest. */
        for (int i = 0; i < 3; i++) assert_true(fabs(got[i] - ev[i]) <= 1e-12 * ev[2]);
        double lam = prep_sym3_smallest(&A, v);
        assert_true(fabs(lam - ev[0]) <= 1e-12 * ev[2]);
        assert_true(fabs(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - 1) < 1e-12);
        /* The gap to the next eigenvalue is at least 5 % of the spread, so the vector is
         * determined to ~1e-10; a wrong vector would be off by ~1. */
        double c = fabs(v[0] * R[0][0] + v[1] * R[0][1] + v[2] * R[0][2]);
        assert_true(c > 1 - 1e-9);
    }
    /* Degenerate: a double smallest eigenvalue: any vector perpendicular to the third. */
    double R[3][3], ev[3] = {1, 1, 5}, v[3];
    random_rotation(&r, R);
    prep_sym3 A = compose(R, ev);
    prep_sym3_smallest(&A, v);
    assert_true(fabs(v[0] * R[2][0] + v[1] * R[2][1] + v[2] * R[2][2]) < 1e-6);
    assert_true(fabs(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - 1) < 1e-12);
    /* Isotropic and zero: (0, 0, 1). */
    prep_sym3 I = {2, 0, 0, 2, 0, 2}, Z = {0, 0, 0, 0, 0, 0};
    prep_sym3_smallest(&I, v);
    assert_true(v[2] == 1);
    prep_sym3_smallest(&Z, v);
    assert_true(v[2] == 1);
}

/* pca.h: the covariance is that of the neighbourhood including the point itself. The point at
 * the origin and four neighbours (+-1, 0, 1), (0, +-1, 1): over the five points the means are
 * (0, 0, 4/5) and the covariance is diag(2/5, 2/5, 4/5 - 16/25) = diag(0.4, 0.4, 0.16), so the
 * normal is +-z and the surface variation lambda_0 / trace = 0.16 / 0.96 = 1/6. Leaving the
 * point out would make the four coplanar neighbours a perfect plane (variation 0). */
static void test_pca_counts_the_point_itself(void **state)
{
    (void)state;
    const float pos[15] = {0, 0, 0, 1, 0, 1, -1, 0, 1, 0, 1, 1, 0, -1, 1};
    const uint32_t nbr[4] = {1, 2, 3, 4};
    float n[3], curv = -1;
    prep_pca_normal(pos, 0, nbr, 4, n, &curv);
    assert_true(fabsf(fabsf(n[2]) - 1) < 1e-6f);
    assert_true(fabsf(n[0]) < 1e-6f && fabsf(n[1]) < 1e-6f);
    assert_true(fabs(curv - 1.0 / 6.0) < 1e-6);
}

/* ---- kNN against brute force ---- */

/* Brute force in double: the k smallest squared distances from point q to the other points,
 * ascending, into out (a sorted insertion buffer: O(n) for k << n). */
static void brute_knn(const float *pos, size_t n, size_t q, int k, double *out)
{
    int m = 0;
    for (size_t j = 0; j < n; j++) {
        if (j == q) continue;
        double dx = (double)pos[3 * j] - pos[3 * q], dy = (double)pos[3 * j + 1] - pos[3 * q + 1];
        double dz = (double)pos[3 * j + 2] - pos[3 * q + 2];
        double d = dx * dx + dy * dy + dz * dz;
        if (m == k && d >= out[k - 1]) continue;
        int i = m < k ? m++ : k - 1;
        while (i > 0 && out[i - 1] > d) { out[i] = out[i - 1]; i--; }
        out[i] = d;
    }
}

/* Checks method m on nq random queries of pos against brute force: the sorted distance lists
 * agree within 1e-6 relative (float distances against double: a few ulps; sets may differ only
 * on exact ties, which leave the distance lists equal), every index is valid, distinct and not
 * the query, and each reported distance is that index's true distance. */
static void check_knn_counted(const float *pos, size_t n, prep_knn_method m, int k, size_t nq,
                              uint64_t seed, prep_knn_counters *cnt)
{
    prep_knn *kn = NULL;
    sd_err err = {0};
    prep_knn_opts o = {.method = m};
    assert_int_equal(prep_knn_build(pos, n, &o, &kn, &err), 0);
    prep_knn_scratch *s = prep_knn_scratch_new();
    assert_non_null(s);
    uint32_t *q = malloc(nq * sizeof *q), *idx = malloc(nq * (size_t)k * sizeof *idx);
    float *d2 = malloc(nq * (size_t)k * sizeof *d2);
    double want[256];
    assert_non_null(q); assert_non_null(idx); assert_non_null(d2);
    rng r = {seed};
    for (size_t i = 0; i < nq; i++) q[i] = (uint32_t)(next64(&r) % n);
    int rc = prep_knn_query(kn, q, 0, nq, k, idx, d2, s, &err);
    if (rc != 0) fail_msg("query: %s", err.msg);
    for (size_t i = 0; i < nq; i++) {
        brute_knn(pos, n, q[i], k, want);
        const uint32_t *ii = idx + i * (size_t)k;
        const float *dd = d2 + i * (size_t)k;
        for (int j = 0; j < k; j++) {
            assert_true(ii[j] < n);
            assert_true(ii[j] != q[i]);
            for (int l = 0; l < j; l++) assert_true(ii[l] != ii[j]);
            if (j) assert_true(dd[j - 1] <= dd[j]);
            double tol = 1e-6 * want[j] + 1e-12;
            if (fabs(dd[j] - want[j]) > tol)
                fail_msg("%s: query %u neighbour %d: d2 %.9g, brute force %.9g",
                         prep_knn_method_name(m), q[i], j, dd[j], want[j]);
            const float *a = pos + 3 * (size_t)q[i], *b = pos + 3 * (size_t)ii[j];
            double dx = (double)a[0] - b[0], dy = (double)a[1] - b[1], dz = (double)a[2] - b[2];
            assert_true(fabs(dx * dx + dy * dy + dz * dz - dd[j]) <= tol);
        }
    }
    if (cnt) prep_knn_scratch_counters(s, cnt);
    free(q); free(idx); free(d2);
    prep_knn_scratch_free(s);
    prep_knn_free(kn);
}

static void check_knn(const float *pos, size_t n, prep_knn_method m, int k, size_t nq,
                      uint64_t seed)
{
    check_knn_counted(pos, n, m, k, nq, seed, NULL);
}

static void test_knn_real_scan(void **state)
{
    (void)state;
    pc_cloud c;
    load_data("bun000.ply", &c);
    assert_true(c.n > 30000);
    check_knn(c.pos, c.n, PREP_KNN_GRID, 24, 2000, 11);
    check_knn(c.pos, c.n, PREP_KNN_FLANN, 24, 2000, 11);
    check_knn(c.pos, c.n, PREP_KNN_GRID, 64, 300, 12);
    pc_cloud_free(&c);
}

static void test_knn_real_scan_guanyin(void **state)
{
    (void)state;
    pc_cloud c;
    load_data("Guanyin.ply", &c);
    check_knn(c.pos, c.n, PREP_KNN_GRID, 24, 500, 13);
    check_knn(c.pos, c.n, PREP_KNN_FLANN, 24, 200, 13);
    pc_cloud_free(&c);
}

/* Hard cases for both methods: many exact duplicates (FLANN may not return the query itself),
 * a dense cluster beside sparse outliers (the grid's per-query path), two distant clusters
 * (wide searches), and points on a grid (exact distance ties). */
static void test_knn_hard_cases(void **state)
{
    (void)state;
    size_t n = 6860;
    pc_cloud c = make_cloud(n);
    rng r = {5};
    for (size_t i = 0; i < n; i++) {
        float *p = c.pos + 3 * i;
        if (i < 60) { p[0] = 1; p[1] = 2; p[2] = 3; }                 /* 60 duplicates */
        else if (i < 5060) { for (int a = 0; a < 3; a++) p[a] = (float)(uni(&r) * 0.01); }
        else if (i < 5160) { for (int a = 0; a < 3; a++) p[a] = (float)(uni(&r) * 100 - 50); }
        else if (i < 5260) { p[0] = 1000 + (float)uni(&r); p[1] = (float)uni(&r); p[2] = 0; }
        else { size_t g = i - 5260; p[0] = 5 + (float)(g % 40) * 0.25f; p[1] = 5 + (float)(g / 40) * 0.25f; p[2] = 5; }
    }
    /* n random queries, so the grid's rare paths run: a leaf beside the 5000-point cluster
     * (more than GRID_CAP candidates: 'dense'), and blocks that must grow ('widened') */
    prep_knn_counters cnt;
    check_knn_counted(c.pos, n, PREP_KNN_GRID, 24, n, 21, &cnt);
    print_message("grid on the hard cloud: %llu widened, %llu dense of %llu queries\n",
                  (unsigned long long)cnt.widened, (unsigned long long)cnt.dense,
                  (unsigned long long)cnt.queries);
    assert_true(cnt.widened > 0 && cnt.dense > 0);
    check_knn(c.pos, n, PREP_KNN_FLANN, 24, 1500, 21);
    for (int m = 0; m < 2; m++) check_knn(c.pos, n, m ? PREP_KNN_FLANN : PREP_KNN_GRID, 1, 500, 22);
    /* k = n - 1: everything is a neighbour. */
    check_knn(c.pos, 200, PREP_KNN_GRID, 199, 50, 23);
    pc_cloud_free(&c);
}

/* Brute force in float, the way the grid computes a distance ((dx * dx + dy * dy) + dz * dz,
 * no fused multiply-add): the k smallest (distance, index) pairs of point q among the others,
 * ascending by distance, then index: the grid's exact answer, ties included. */
static void brute_knn_exact(const float *pos, size_t n, size_t q, int k, float *od, uint32_t *oi)
{
    int m = 0;
    const float *a = pos + 3 * q;
    for (size_t j = 0; j < n; j++) {
        if (j == q) continue;
        float dx = pos[3 * j] - a[0], dy = pos[3 * j + 1] - a[1], dz = pos[3 * j + 2] - a[2];
        float d = dx * dx + dy * dy + dz * dz;
        uint32_t id = (uint32_t)j;
        if (m == k && (d > od[k - 1] || (d == od[k - 1] && id > oi[k - 1]))) continue;
        int i = m < k ? m++ : k - 1;
        while (i > 0 && (od[i - 1] > d || (od[i - 1] == d && oi[i - 1] > id))) {
            od[i] = od[i - 1];
            oi[i] = oi[i - 1];
            i--;
        }
        od[i] = d;
        oi[i] = id;
    }
}

/* Every vector path of the grid (portable, AVX2, AVX-512: those the CPU has) answers every
 * query of pos exactly as the float brute force does: the same indices in the same order and
 * the same distance bits. Queries in index order and in a random order; with codes (pos in
 * Morton order, frame f) the grid indexes the points as they are (no copy, no order). */
static void check_knn_paths_in(const float *pos, size_t n, int k, uint64_t seed,
                               const prep_morton_frame *f, const uint64_t *codes,
                               const char *what)
{
    uint32_t *q = malloc(n * sizeof *q), *idx = malloc(n * (size_t)k * sizeof *idx);
    float *d2 = malloc(n * (size_t)k * sizeof *d2), *wd = malloc(n * (size_t)k * sizeof *wd);
    uint32_t *wi = malloc(n * (size_t)k * sizeof *wi);
    assert_non_null(q); assert_non_null(idx); assert_non_null(d2);
    assert_non_null(wd); assert_non_null(wi);
    for (size_t i = 0; i < n; i++) brute_knn_exact(pos, n, i, k, wd + i * k, wi + i * k);
    rng r = {seed};
    for (int path = PREP_KNN_SIMD_PORTABLE; path <= PREP_KNN_SIMD_AVX512; path++) {
        prep_knn *kn = NULL;
        sd_err err = {0};
        prep_knn_opts o = {.method = PREP_KNN_GRID, .simd = path, .frame = f, .codes = codes};
        assert_int_equal(prep_knn_build(pos, n, &o, &kn, &err), 0);
        prep_knn_scratch *s = prep_knn_scratch_new();
        assert_non_null(s);
        for (int shuffled = 0; shuffled < 2; shuffled++) {
            for (size_t i = 0; i < n; i++) q[i] = (uint32_t)i;
            for (size_t i = n - 1; shuffled && i > 0; i--) {
                size_t j = (size_t)(next64(&r) % (i + 1));
                uint32_t t = q[i]; q[i] = q[j]; q[j] = t;
            }
            if (prep_knn_query(kn, q, 0, n, k, idx, d2, s, &err) != 0)
                fail_msg("%s: query: %s", what, err.msg);
            for (size_t i = 0; i < n; i++) {
                const uint32_t *gi = idx + i * k, *bi = wi + (size_t)q[i] * k;
                const float *gd = d2 + i * k, *bd = wd + (size_t)q[i] * k;
                for (int j = 0; j < k; j++)
                    if (gi[j] != bi[j] || memcmp(&gd[j], &bd[j], sizeof gd[j]) != 0)
                        fail_msg("%s, path %d, %s order: query %u neighbour %d: %u at %.9g, "
                                 "brute force %u at %.9g", what, path,
                                 shuffled ? "random" : "index", q[i], j, gi[j], gd[j], bi[j],
                                 bd[j]);
            }
        }
        prep_knn_scratch_free(s);
        prep_knn_free(kn);
    }
    free(q); free(idx); free(d2); free(wd); free(wi);
}

/* check_knn_paths_in on pos as given, then on a copy in Morton order with its codes. */
static void check_knn_paths_exact(const float *pos, size_t n, int k, uint64_t seed,
                                  const char *what)
{
    check_knn_paths_in(pos, n, k, seed, NULL, NULL, what);
    prep_morton_frame f;
    prep_morton_frame_of(pos, n, &f);
    uint64_t *codes = malloc(n * sizeof *codes);
    uint32_t *perm = malloc(n * sizeof *perm);
    float *sorted = malloc(3 * n * sizeof *sorted);
    assert_non_null(codes); assert_non_null(perm); assert_non_null(sorted);
    sd_err err = {0};
    assert_int_equal(prep_morton_sort(pos, n, &f, codes, perm, &err), 0);
    for (size_t i = 0; i < n; i++) memcpy(sorted + 3 * i, pos + 3 * (size_t)perm[i], 12);
    char w[96];
    snprintf(w, sizeof w, "%s, in Morton order", what);
    check_knn_paths_in(sorted, n, k, seed + 100, &f, codes, w);
    free(codes); free(perm); free(sorted);
}

/* The grid's vector paths against the exact float brute force on random and degenerate
 * clouds: uniform, exact duplicates (every distance tied), a plane, collinear points, a
 * regular lattice (many tied distances), clusters of very different density (wide blocks,
 * retried filters, selections of more than RANK_MAX candidates), and clouds of k + 1 and
 * k + 2 points (every other point a neighbour). */
static void test_knn_paths_exact(void **state)
{
    (void)state;
    enum { N = 2000 };
    pc_cloud c = make_cloud(N);
    rng r = {77};
    float *p = c.pos;
    for (size_t i = 0; i < N; i++)
        for (int a = 0; a < 3; a++) p[3 * i + a] = (float)uni(&r);
    check_knn_paths_exact(p, N, 24, 1, "uniform");
    check_knn_paths_exact(p, N, 7, 2, "uniform, k 7");
    for (size_t i = 0; i < N; i++) { /* 40 points at each of 50 places */
        size_t g = i % 50;
        p[3 * i] = (float)g * 0.1f; p[3 * i + 1] = 1; p[3 * i + 2] = (float)(g % 7);
    }
    check_knn_paths_exact(p, N, 24, 3, "duplicates");
    for (size_t i = 0; i < N; i++) {
        p[3 * i] = (float)uni(&r) * 10; p[3 * i + 1] = (float)uni(&r) * 10; p[3 * i + 2] = 2;
    }
    check_knn_paths_exact(p, N, 24, 4, "plane");
    for (size_t i = 0; i < N; i++) {
        float t = (float)uni(&r);
        p[3 * i] = 1 + t; p[3 * i + 1] = 2 * t; p[3 * i + 2] = -3 * t;
    }
    check_knn_paths_exact(p, N, 24, 5, "collinear");
    for (size_t i = 0; i < N; i++) { /* a 20 x 10 x 10 lattice of step 0.5 */
        p[3 * i] = (float)(i % 20) * 0.5f;
        p[3 * i + 1] = (float)(i / 20 % 10) * 0.5f;
        p[3 * i + 2] = (float)(i / 200) * 0.5f;
    }
    check_knn_paths_exact(p, N, 24, 6, "lattice");
    check_knn_paths_exact(p, N, 64, 7, "lattice, k 64");
    for (size_t i = 0; i < N; i++) {
        double sc = i < 1500 ? 0.01 : i < 1900 ? 1 : 100; /* dense, medium, sparse */
        for (int a = 0; a < 3; a++) p[3 * i + a] = (float)(uni(&r) * sc);
    }
    check_knn_paths_exact(p, N, 24, 8, "clusters");
    check_knn_paths_exact(p, 25, 24, 9, "k + 1 points");
    check_knn_paths_exact(p + 3 * 1500, 26, 24, 10, "k + 2 points");
    pc_cloud_free(&c);
}

/* One query scratch over several grids in turn (the LOD build queries each region's grid with
 * the same scratches): the blocks and run bounds a scratch keeps from one grid must not answer
 * for the next. Two clouds in one Morton frame (the same cell codes, different points: the
 * second holds every third point of the first, shifted), each queried in Morton order with
 * one scratch, alternately, against the float brute force. */
static void test_knn_scratch_across_grids(void **state)
{
    (void)state;
    enum { N = 3000, K = 16 };
    float *a = malloc(3 * N * sizeof *a), *b = malloc(3 * N * sizeof *b);
    assert_non_null(a); assert_non_null(b);
    rng r = {91};
    for (size_t i = 0; i < N; i++) { /* a wavy surface: blocks shared by many queries */
        a[3 * i] = (float)uni(&r) * 8; a[3 * i + 1] = (float)uni(&r) * 8;
        a[3 * i + 2] = 0.5f * sinf(a[3 * i]) + 0.01f * (float)uni(&r);
    }
    size_t nb = 0;
    for (size_t i = 0; i < N; i += 3, nb++)
        for (int x = 0; x < 3; x++) b[3 * nb + x] = a[3 * i + x] + (x == 2 ? 0.05f : 0.0f);
    prep_morton_frame f;
    float box[6] = {0, 0, -1, 8, 8, 1};
    prep_morton_frame_of(box, 2, &f);
    float *cl[2] = {a, b}, *sorted[2];
    uint64_t *codes[2];
    size_t n[2] = {N, nb};
    sd_err err = {0};
    for (int c = 0; c < 2; c++) {
        uint32_t *perm = malloc(n[c] * sizeof *perm);
        codes[c] = malloc(n[c] * sizeof *codes[c]);
        sorted[c] = malloc(3 * n[c] * sizeof *sorted[c]);
        assert_non_null(perm); assert_non_null(codes[c]); assert_non_null(sorted[c]);
        assert_int_equal(prep_morton_sort(cl[c], n[c], &f, codes[c], perm, &err), 0);
        for (size_t i = 0; i < n[c]; i++) memcpy(sorted[c] + 3 * i, cl[c] + 3 * (size_t)perm[i], 12);
        free(perm);
    }
    prep_knn *kn[2] = {NULL, NULL};
    for (int c = 0; c < 2; c++) {
        prep_knn_opts o = {.method = PREP_KNN_GRID, .frame = &f, .codes = codes[c]};
        assert_int_equal(prep_knn_build(sorted[c], n[c], &o, &kn[c], &err), 0);
    }
    prep_knn_scratch *s = prep_knn_scratch_new();
    uint32_t *idx = malloc(N * K * sizeof *idx), wi[K];
    float *d2 = malloc(N * K * sizeof *d2), wd[K];
    assert_non_null(s); assert_non_null(idx); assert_non_null(d2);
    static const int seq[5] = {0, 1, 0, 1, 1};
    for (int t = 0; t < 5; t++) {
        int c = seq[t];
        if (prep_knn_query(kn[c], NULL, 0, n[c], K, idx, d2, s, &err) != 0) fail_msg("%s", err.msg);
        for (size_t i = 0; i < n[c]; i++) {
            brute_knn_exact(sorted[c], n[c], i, K, wd, wi);
            for (int j = 0; j < K; j++)
                if (idx[i * K + j] != wi[j] || memcmp(&d2[i * K + j], &wd[j], 4) != 0)
                    fail_msg("call %d (cloud %d): query %zu neighbour %d: %u at %.9g, brute "
                             "force %u at %.9g", t, c, i, j, idx[i * K + j], d2[i * K + j],
                             wi[j], wd[j]);
        }
    }
    prep_knn_scratch_free(s);
    for (int c = 0; c < 2; c++) {
        prep_knn_free(kn[c]);
        free(codes[c]);
        free(sorted[c]);
    }
    free(idx); free(d2); free(a); free(b);
}

static void test_knn_bad_args(void **state)
{
    (void)state;
    float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    prep_knn *kn = NULL;
    sd_err err = {0};
    prep_knn_opts o = {.method = (prep_knn_method)7};
    assert_int_equal(prep_knn_build(pos, 3, &o, &kn, &err), SD_EINVAL);
    assert_int_equal(prep_knn_build(pos, 3, NULL, &kn, &err), 0);
    prep_knn_scratch *s = prep_knn_scratch_new();
    uint32_t idx[8];
    assert_int_equal(prep_knn_query(kn, NULL, 0, 1, 3, idx, NULL, s, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "k = 3"));
    uint32_t bad = 3;
    assert_int_equal(prep_knn_query(kn, &bad, 0, 1, 2, idx, NULL, s, &err), SD_EINVAL);
    assert_int_equal(prep_knn_query(kn, NULL, 0, 3, 2, idx, NULL, s, &err), 0);
    assert_int_equal(idx[0], 1); /* point 0: (1,0,0) and (0,1,0) tie at 1: lower index first */
    assert_int_equal(idx[1], 2);
    prep_knn_scratch_free(s);
    prep_knn_free(kn);
}

/* ---- normals ---- */

/* Unit normal of a tilted plane: (0.36, -0.48, 0.8). */
static const double PLANE_N[3] = {0.36, -0.48, 0.8};

/* Points on the plane through (3, -2, 1) with normal PLANE_N, on a jittered grid of spacing h,
 * plus Gaussian noise of sigma in every direction. */
static pc_cloud plane_cloud(int side, double h, double sigma, uint64_t seed)
{
    pc_cloud c = make_cloud((size_t)side * side);
    double u[3] = {0.8, 0.6, 0}; /* perpendicular to PLANE_N */
    double v[3] = {PLANE_N[1] * u[2] - PLANE_N[2] * u[1], PLANE_N[2] * u[0] - PLANE_N[0] * u[2],
                   PLANE_N[0] * u[1] - PLANE_N[1] * u[0]};
    rng r = {seed};
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++) {
            double a = (i + 0.3 * uni(&r)) * h, b = (j + 0.3 * uni(&r)) * h;
            float *p = c.pos + 3 * ((size_t)i * side + j);
            double o[3] = {3, -2, 1};
            for (int k = 0; k < 3; k++) p[k] = (float)(o[k] + a * u[k] + b * v[k] + sigma * gauss(&r));
        }
    return c;
}

/* Fibonacci-sphere points of radius rad about (1, 2, 3), with radial... all-direction noise. */
static pc_cloud sphere_cloud(size_t n, double rad, double sigma, uint64_t seed)
{
    pc_cloud c = make_cloud(n);
    rng r = {seed};
    double ga = 3.883222077450933; /* golden angle */
    for (size_t i = 0; i < n; i++) {
        double z = 1 - 2 * (i + 0.5) / n, s = sqrt(1 - z * z), t = ga * i;
        double d[3] = {s * cos(t), s * sin(t), z};
        for (int k = 0; k < 3; k++)
            c.pos[3 * i + k] = (float)((k + 1) + rad * d[k] + sigma * gauss(&r));
    }
    return c;
}

static double angle_deg(const float *n, const double *t)
{
    double c = fabs(dot3(n, t)) / sqrt(dot3(n, (const double[3]){n[0], n[1], n[2]}));
    return acos(c > 1 ? 1 : c) * 57.29577951308232;
}

/* Noise: sigma = 10 % of the spacing h in every direction. A plane fit over K + 1 = 25 points
 * spanning radius ~2.8 h has a slope error of about sigma / sqrt(sum x^2) ~ 0.1 h / 7 h per
 * axis, ~0.8 degrees; the largest of ~15,000 such tilts (Rayleigh) is expected near
 * sqrt(2 ln 15000) x 0.8 ~ 3.5 degrees (measured: 3.8 on the plane and the sphere). 5 degrees
 * leaves that margin while a wrong eigenvector or a broken neighbourhood is tens of degrees
 * off. Noise-free, the only errors are float rounding and (on the sphere) the curvature
 * asymmetry of the neighbourhood: measured 0.0 and 0.44 degrees, bound 1. The data are
 * deterministic (fixed seeds), so these margins do not flake. */
static void check_plane(double sigma, double bound)
{
    double h = 0.05;
    pc_cloud c = plane_cloud(120, h, sigma * h, 3);
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double worst = 0, centroid[3] = {0, 0, 0};
    size_t near = 0;
    for (size_t i = 0; i < p.n; i++)
        for (int k = 0; k < 3; k++) centroid[k] += p.pos[3 * i + k] / (double)p.n;
    for (size_t i = 0; i < p.n; i++) {
        double a = angle_deg(p.normal + 3 * i, PLANE_N);
        if (a > worst) worst = a;
        /* orientation: the plane contains the centroid, so the tie rule n_z >= 0 applies,
         * except within a few noise amplitudes of the centroid where noise decides */
        const float *q = p.pos + 3 * i;
        double dc = 0;
        for (int k = 0; k < 3; k++) dc += (q[k] - centroid[k]) * (q[k] - centroid[k]);
        if (sqrt(dc) > 40 * sigma * h) assert_true(p.normal[3 * i + 2] > 0);
        else near++;
        double l = sqrt(dot3(p.normal + 3 * i, (const double[3]){p.normal[3 * i],
                    p.normal[3 * i + 1], p.normal[3 * i + 2]}));
        assert_true(fabs(l - 1) < 1e-5);
    }
    print_message("plane sigma %.2f h: worst normal error %.3f degrees (bound %.1f), %zu points "
                  "near the centroid not checked for orientation\n", sigma, worst, bound, near);
    assert_true(near < p.n / 100);
    assert_true(worst < bound);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

static void test_normals_plane(void **state)
{
    (void)state;
    check_plane(0, 1);
    check_plane(0.1, 5);
}

static void check_sphere(double sigma_rel, double bound)
{
    size_t n = 20000;
    double rad = 2, h = rad * sqrt(4 * M_PI / n); /* mean spacing */
    pc_cloud c = sphere_cloud(n, rad, sigma_rel * h, 4);
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double worst = 0, cen[3] = {1, 2, 3};
    for (size_t i = 0; i < p.n; i++) {
        const float *q = p.pos + 3 * i, *nn = p.normal + 3 * i;
        double t[3] = {q[0] - cen[0], q[1] - cen[1], q[2] - cen[2]};
        double l = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        for (int k = 0; k < 3; k++) t[k] /= l;
        double a = angle_deg(nn, t);
        if (a > worst) worst = a;
        assert_true(dot3(nn, t) > 0); /* outward: away from the centroid (the centre) */
    }
    print_message("sphere sigma %.2f h: worst normal error %.3f degrees (bound %.1f)\n",
                  sigma_rel, worst, bound);
    assert_true(worst < bound);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

static void test_normals_sphere(void **state)
{
    (void)state;
    check_sphere(0, 1);
    check_sphere(0.1, 5);
}

/* Normals and radii present in the file are kept, not recomputed. */
static void test_file_normals_kept(void **state)
{
    (void)state;
    pc_cloud c = plane_cloud(40, 0.1, 0, 8);
    c.attrs = PC_ATTR_NORMAL | PC_ATTR_RADIUS;
    c.normal = malloc(3 * c.n * sizeof(float));
    c.radius = malloc(c.n * sizeof(float));
    assert_non_null(c.normal); assert_non_null(c.radius);
    for (size_t i = 0; i < c.n; i++) {
        c.normal[3 * i] = 1; c.normal[3 * i + 1] = 0; c.normal[3 * i + 2] = 0;
        c.radius[i] = 0.25f + c.pos[3 * i] * 0.01f; /* tied to the position */
    }
    c.radius[7] = NAN; /* a broken file value must not poison F's percentiles */
    c.radius[8] = -1;
    prep_desc d = {0};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    size_t zero = 0;
    for (size_t i = 0; i < p.n; i++) {
        assert_true(p.normal[3 * i] == 1 && p.normal[3 * i + 2] == 0);
        if (isnan(p.radius[i]) || p.radius[i] < 0) {
            assert_true(p.F[i] == 0);
            zero++;
            continue;
        }
        assert_true(p.radius[i] == 0.25f + p.pos[3 * i] * 0.01f);
        assert_true(p.F[i] > 0 && p.F[i] <= 1);
    }
    assert_int_equal(zero, 2);
    assert_true(p.F_raw_p99 > 0.25f && isfinite(p.F_raw_p99));
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* ---- radius, sigma, F on analytic layouts ---- */

/* A side x side square grid of spacing h = 0.5 (exact in float) in the plane z = 7. For an
 * interior point the 24 nearest are the rings at h (4), sqrt2 h (4), 2h (4), sqrt5 h (8) and
 * sqrt8 h (4): R = sqrt8 h, r = 2 sqrt8 h / sqrt24 exactly, up to float rounding (1e-6); the
 * nearest-neighbour distance of every point is h, so sigma = h. With all normals equal,
 * eq. 21 gives F_raw = r (the sum is K ones). */
static void test_radius_sigma_grid(void **state)
{
    (void)state;
    int side = 64;
    double h = 0.5;
    pc_cloud c = make_cloud((size_t)side * side);
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++) {
            float *p = c.pos + 3 * ((size_t)i * side + j);
            p[0] = (float)(i * h); p[1] = (float)(j * h); p[2] = 7;
        }
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double want = 2 * sqrt(8.0) * h / sqrt(24.0);
    size_t interior = 0;
    for (size_t i = 0; i < p.n; i++) {
        const float *q = p.pos + 3 * i;
        if (q[0] < 3 * h || q[1] < 3 * h || q[0] > (side - 4) * h || q[1] > (side - 4) * h) continue;
        interior++;
        assert_true(fabs(p.radius[i] - want) <= 1e-6 * want);
        assert_true(fabs(p.normal[3 * i + 2] - 1) < 1e-6); /* tie rule: up */
        /* F = F_raw / p99 and F_raw = r for every point; interior points share the p99 */
        assert_true(fabs(p.F[i] * p.F_raw_p99 - p.radius[i]) <= 1e-5 * want);
    }
    assert_true(interior > 3000);
    assert_true(fabs(p.sigma - h) <= 1e-6);
    assert_true(fabs(p.radius_median - want) <= 1e-6 * want);
    assert_int_equal(p.k, 24);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* Normals face the sensor when the file gives its position: a plane z = 0 seen from below
 * (sensor at z = -3, file coordinates, with an offset so the local frame differs) gets -z
 * normals, from above +z; without a sensor the plane through the centroid takes the up rule
 * (+z). */
static void test_normals_face_sensor(void **state)
{
    (void)state;
    const int side = 32;
    const double off[3] = {1000, -500, 20};
    for (int v = 0; v < 3; v++) {
        pc_cloud c = make_cloud((size_t)side * side);
        for (int i = 0; i < side; i++)
            for (int j = 0; j < side; j++) {
                float *q = c.pos + 3 * ((size_t)i * side + j);
                q[0] = (float)(i * 0.5); q[1] = (float)(j * 0.5); q[2] = 0;
            }
        memcpy(c.offset, off, sizeof off);
        if (v < 2) {
            c.has_viewpoint = 1;
            c.viewpoint[0] = off[0] + 8;
            c.viewpoint[1] = off[1] + 8;
            c.viewpoint[2] = off[2] + (v == 0 ? -3 : 3);
        }
        prep_desc d = {.k = 24, .threads = 2};
        pc_prepared p;
        sd_err err = {0};
        assert_int_equal(prep_run(&c, &d, &p, &err), 0);
        float want = v == 0 ? -1.0f : 1.0f;
        for (size_t i = 0; i < p.n; i++) assert_true(fabsf(p.normal[3 * i + 2] - want) < 1e-5f);
        pc_prepared_free(&p);
        pc_cloud_free(&c);
    }
}

/* The grid plane above plus one stray point 20 units above its middle. Eq. 20 alone would give
 * the stray point r = 2 R / sqrt(24) with R ~ 20 (a disc hiding the plane); the limit holds it
 * to PREP_RADIUS_CAP times its neighbours' median radius (the plane's r), while F, computed with
 * the unlimited radius, marks it as the most uncertain point (F = 1). Plane radii are untouched. */
static void test_radius_outlier_limited(void **state)
{
    (void)state;
    int side = 64;
    double h = 0.5;
    size_t n = (size_t)side * side + 1;
    pc_cloud c = make_cloud(n);
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++) {
            float *p = c.pos + 3 * ((size_t)i * side + j);
            p[0] = (float)(i * h); p[1] = (float)(j * h); p[2] = 7;
        }
    float *o = c.pos + 3 * (n - 1);
    o[0] = 16; o[1] = 16; o[2] = 27;
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double want = 2 * sqrt(8.0) * h / sqrt(24.0);
    int found = 0;
    for (size_t i = 0; i < p.n; i++) {
        const float *q = p.pos + 3 * i;
        if (q[2] > 10) {
            found++;
            assert_true(p.radius[i] <= PREP_RADIUS_CAP * want * (1 + 1e-6));
            assert_true(p.radius[i] >= want); /* limited, not shrunk below the plane's */
            assert_true(p.F[i] == 1.0f);
        } else if (q[0] >= 3 * h && q[1] >= 3 * h && q[0] <= (side - 4) * h && q[1] <= (side - 4) * h &&
                   fabs(q[0] - 16) > 4 && fabs(q[1] - 16) > 4) {
            assert_true(fabs(p.radius[i] - want) <= 1e-6 * want);
        }
    }
    assert_int_equal(found, 1);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* Three parts far apart in one cloud: a dense grid plane (spacing 0.5, 4096 points: the median
 * radius), a sparse grid plane (spacing 4, 256 points) and 400 points scattered uniformly
 * through a 60-unit cube (noise, birds: spacing ~8). Eq. 20 gives the scattered points discs of
 * radius ~8, bigger than the sparse plane's, and their neighbours are scattered too, so the
 * neighbours' median does not limit them. Their neighbourhoods are no surface (PCA surface
 * variation > PREP_SURFACE_VAR_MAX), so they are held to PREP_SCATTER_CAP x the cloud's median
 * radius; the sparse plane is a surface and keeps its eq. 20 radius, 8x the dense plane's. */
static void test_radius_scatter_limited(void **state)
{
    (void)state;
    const int side = 64, sside = 16, nscatter = 400;
    size_t n = (size_t)side * side + (size_t)sside * sside + nscatter;
    pc_cloud c = make_cloud(n);
    size_t k = 0;
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++, k++) {
            c.pos[3 * k] = (float)(i * 0.5); c.pos[3 * k + 1] = (float)(j * 0.5); c.pos[3 * k + 2] = 0;
        }
    for (int i = 0; i < sside; i++)
        for (int j = 0; j < sside; j++, k++) {
            c.pos[3 * k] = (float)(200 + i * 4.0); c.pos[3 * k + 1] = (float)(j * 4.0); c.pos[3 * k + 2] = 0;
        }
    rng r = {42};
    for (int i = 0; i < nscatter; i++, k++)
        for (int a = 0; a < 3; a++) c.pos[3 * k + a] = (float)(uni(&r) * 60 + (a == 2 ? 100 : 0));
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double dense = 2 * sqrt(8.0) * 0.5 / sqrt(24.0), sparse = 8 * dense;
    assert_true(fabs(p.radius_median - dense) <= 1e-6 * dense);
    size_t scattered = 0, held = 0, sparse_interior = 0;
    for (size_t i = 0; i < p.n; i++) {
        const float *q = p.pos + 3 * i;
        if (q[2] > 50) {
            scattered++;
            held += p.radius[i] <= PREP_SCATTER_CAP * dense * (1 + 1e-6);
        } else if (q[0] >= 200 + 3 * 4.0 && q[0] <= 200 + (sside - 4) * 4.0 && q[1] >= 3 * 4.0 &&
                   q[1] <= (sside - 4) * 4.0) {
            sparse_interior++;
            assert_true(fabs(p.radius[i] - sparse) <= 1e-5 * sparse);
        }
    }
    printf("scattered points held to the median radius: %zu of %zu\n", held, scattered);
    assert_int_equal(scattered, nscatter);
    assert_int_equal(sparse_interior, 100);
    /* Random neighbourhoods can look planar by chance: nearly all, not all, are held. */
    assert_true(held >= scattered * 9 / 10);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* Eq. 20's r = 2 R / sqrt(k) of point i by brute force, R = the distance to its k-th nearest
 * other point among the points on the same side of x = split. */
static double eq20_radius_brute(const pc_prepared *p, size_t i, int k, float split)
{
    double best[PREP_MAX_K];
    int nb = 0;
    const float *a = p->pos + 3 * i;
    for (size_t j = 0; j < p->n; j++) {
        const float *b = p->pos + 3 * j;
        if (j == i || (a[0] > split) != (b[0] > split)) continue;
        double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
        double d2 = dx * dx + dy * dy + dz * dz;
        if (nb == k && d2 >= best[k - 1]) continue;
        int at = nb < k ? nb++ : k - 1;
        while (at > 0 && best[at - 1] > d2) { best[at] = best[at - 1]; at--; }
        best[at] = d2;
    }
    return 2 * sqrt(best[k - 1]) / sqrt((double)k);
}

/* A noise-free plane and a 'vegetation' ball of random points, far apart in one cloud (so they
 * share F's normalisation). On the plane every term of eq. 21 is (2 - 1)^2 = 1, so F_raw = r.
 * In the ball PCA normals are close to random directions, for which |n_i . n_j| is uniform on
 * [0, 1] and (2 - |n_i . n_j|)^2 averages 7/3; the ball is also sparser (2x the spacing, as
 * vegetation in scans), so its eq. 20 radius is larger: its median F must exceed 3x the
 * plane's. */
static void test_field_vegetation_vs_plane(void **state)
{
    (void)state;
    int side = 100;
    size_t nb = 8000;
    double h = 0.1;
    pc_cloud c = make_cloud((size_t)side * side + nb);
    rng r = {9};
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++) {
            float *p = c.pos + 3 * ((size_t)i * side + j);
            p[0] = (float)((i + 0.5 * uni(&r)) * h); p[1] = (float)((j + 0.5 * uni(&r)) * h); p[2] = 0;
        }
    /* ball: the mean nearest-neighbour distance of random points is 0.554 (V / n)^(1/3); the
     * radius makes it 2h */
    double rad = 2 * h / 0.554 * cbrt(nb * 3 / (4 * M_PI));
    for (size_t i = 0; i < nb; i++) {
        float *p = c.pos + 3 * ((size_t)side * side + i);
        double x, y, z;
        do { x = 2 * uni(&r) - 1; y = 2 * uni(&r) - 1; z = 2 * uni(&r) - 1; } while (x * x + y * y + z * z > 1);
        p[0] = (float)(100 + rad * x); p[1] = (float)(rad * y); p[2] = (float)(rad * z);
    }
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    float *fp = malloc(p.n * sizeof *fp), *fb = malloc(p.n * sizeof *fb), *sb = malloc(p.n * sizeof *sb);
    assert_non_null(fp); assert_non_null(fb); assert_non_null(sb);
    size_t np = 0, nv = 0;
    for (size_t i = 0; i < p.n; i++) {
        if (p.pos[3 * i] > 50) {
            fb[nv] = p.F[i];
            /* the normal-variation factor: F_raw over the eq. 20 radius, which F uses (the ball
             * is no surface, so the rendered radius is limited: step 4) */
            sb[nv++] = p.F[i] * p.F_raw_p99 / eq20_radius_brute(&p, i, 24, 50);
        } else {
            fp[np++] = p.F[i];
            if (p.F[i] < 1) assert_true(fabs(p.F[i] * p.F_raw_p99 / p.radius[i] - 1) < 1e-4);
        }
    }
    assert_int_equal(nv, nb);
    qsort(fp, np, sizeof *fp, cmp_float);
    qsort(fb, nv, sizeof *fb, cmp_float);
    qsort(sb, nv, sizeof *sb, cmp_float);
    double ratio = fb[nv / 2] / fp[np / 2];
    print_message("median F: vegetation %.3f, plane %.3f, ratio %.2f; ball normal factor median %.3f\n",
                  fb[nv / 2], fp[np / 2], ratio, sb[nv / 2]);
    assert_true(ratio > 3);
    /* neighbouring PCA normals in a ball are somewhat correlated: allow 1.8..2.6 around 7/3 */
    assert_true(sb[nv / 2] > 1.8 && sb[nv / 2] < 2.6);
    /* normalisation: F in [0, 1], and exactly 1 % of the points at or above the p99 */
    for (size_t i = 0; i < p.n; i++) assert_true(p.F[i] >= 0 && p.F[i] <= 1);
    assert_true(p.F_pct[0] <= p.F_pct[1] && p.F_pct[1] <= p.F_pct[2] && p.F_pct[2] <= p.F_pct[3]);
    assert_true(fabs(p.F_pct[4] - 1) < 1e-6);
    free(fp); free(fb); free(sb);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* sigma is the median nearest-neighbour distance, not the minimum (DESIGN.md: the paper's
 * minimum is zero for duplicate points). 4096 points on a grid of spacing 1 and, far away,
 * 1024 on a grid of spacing 0.25: four fifths of the points have their nearest neighbour at 1,
 * so the median is 1 while the minimum would be 0.25. */
static void test_sigma_is_median(void **state)
{
    (void)state;
    const int a = 64, b = 32;
    pc_cloud c = make_cloud((size_t)a * a + (size_t)b * b);
    size_t k = 0;
    for (int i = 0; i < a; i++)
        for (int j = 0; j < a; j++, k++) {
            c.pos[3 * k] = (float)i; c.pos[3 * k + 1] = (float)j; c.pos[3 * k + 2] = 0;
        }
    for (int i = 0; i < b; i++)
        for (int j = 0; j < b; j++, k++) {
            c.pos[3 * k] = (float)(1000 + i * 0.25); c.pos[3 * k + 1] = (float)(j * 0.25);
            c.pos[3 * k + 2] = 0;
        }
    prep_desc d = {.k = 24, .threads = 2};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    assert_true(fabs(p.sigma - 1.0) <= 1e-6);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* A cloud of exactly k points has k - 1 neighbours per point: prep uses K = n - 1 rather than
 * asking the kNN for as many neighbours as there are points. The unit square's corners with
 * k = 4: K = 3, the farthest other corner is the diagonal one at sqrt 2, so every radius is
 * r = 2 sqrt2 / sqrt3 (eq. 20) and sigma = 1. */
static void test_cloud_of_exactly_k_points(void **state)
{
    (void)state;
    pc_cloud c = make_cloud(4);
    const float sq[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    memcpy(c.pos, sq, sizeof sq);
    prep_desc d = {.k = 4, .threads = 1};
    pc_prepared p;
    sd_err err = {0};
    int rc = prep_run(&c, &d, &p, &err);
    if (rc != 0) fail_msg("prep_run of 4 points with k = 4: %s", err.msg);
    assert_int_equal(p.k, 3);
    double want = 2 * sqrt(2.0) / sqrt(3.0);
    for (size_t i = 0; i < 4; i++) assert_true(fabs(p.radius[i] - want) <= 1e-6 * want);
    assert_true(fabs(p.sigma - 1.0) <= 1e-6);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* ---- Morton order, batches, attribute permutation ---- */

static uint8_t tag(const float *p, int ch)
{
    uint32_t u[3];
    memcpy(u, p, sizeof u);
    uint32_t h = u[0] * 2654435761u ^ u[1] * 2246822519u ^ u[2] * 3266489917u;
    return (uint8_t)(h >> (8 * ch));
}

static void test_morton_order_and_attributes(void **state)
{
    (void)state;
    pc_cloud c;
    load_data("bun000.ply", &c);
    /* attach attributes derived from each point's position, so we can tell they followed it */
    free(c.rgba); free(c.intensity); free(c.cls); free(c.scalar);
    c.attrs |= PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_CLASS | PC_ATTR_SCALAR;
    c.rgba = malloc(4 * c.n); c.intensity = malloc(4 * c.n); c.cls = malloc(c.n);
    c.scalar = malloc(4 * c.n);
    assert_non_null(c.rgba); assert_non_null(c.intensity); assert_non_null(c.cls);
    assert_non_null(c.scalar);
    strcpy(c.scalar_name, "quality");
    for (size_t i = 0; i < c.n; i++) {
        for (int k = 0; k < 4; k++) c.rgba[4 * i + k] = tag(c.pos + 3 * i, k);
        c.intensity[i] = c.pos[3 * i] * 3 + 1;
        c.cls[i] = tag(c.pos + 3 * i, 2) ^ 0x5a;
        c.scalar[i] = c.pos[3 * i + 2] - c.pos[3 * i + 1];
    }
    prep_desc d = {.k = 16};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    assert_int_equal(p.n, c.n);
    assert_int_equal(p.attrs, c.attrs | PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F);
    assert_string_equal(p.scalar_name, "quality");
    assert_string_equal(p.format, c.format);
    assert_memory_equal(p.offset, c.offset, sizeof p.offset);
    for (size_t i = 0; i < p.n; i++) {
        const float *q = p.pos + 3 * i;
        for (int k = 0; k < 4; k++) assert_int_equal(p.rgba[4 * i + k], tag(q, k));
        assert_true(p.intensity[i] == q[0] * 3 + 1);
        assert_int_equal(p.cls[i], tag(q, 2) ^ 0x5a);
        assert_true(p.scalar[i] == q[2] - q[1]);
    }
    /* the positions are a permutation of the input: compare sorted copies */
    float *a = malloc(3 * c.n * sizeof *a), *b = malloc(3 * c.n * sizeof *b);
    assert_non_null(a); assert_non_null(b);
    memcpy(a, c.pos, 3 * c.n * sizeof *a);
    memcpy(b, p.pos, 3 * c.n * sizeof *b);
    qsort(a, 3 * c.n, sizeof *a, cmp_float);
    qsort(b, 3 * c.n, sizeof *b, cmp_float);
    assert_memory_equal(a, b, 3 * c.n * sizeof *a);
    /* codes are non-decreasing in the output order */
    prep_morton_frame f;
    prep_morton_frame_of(p.pos, p.n, &f);
    for (size_t i = 1; i < p.n; i++)
        assert_true(prep_morton_code(&f, p.pos + 3 * (i - 1)) <= prep_morton_code(&f, p.pos + 3 * i));
    /* batches tile [0, n), contain their points, and are small: random order would make each
     * batch's box about the whole cloud's (sum = nbatches x volume). */
    double vol = 1, sum = 0, step_m = 0, step_r = 0;
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++) { lo[k] = hi[k] = p.pos[k]; }
    for (size_t i = 0; i < p.n; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], p.pos[3 * i + k]);
            hi[k] = fmaxf(hi[k], p.pos[3 * i + k]);
        }
    for (int k = 0; k < 3; k++) vol *= hi[k] - lo[k];
    assert_int_equal(p.nbatches, (p.n + PC_BATCH_POINTS - 1) / PC_BATCH_POINTS);
    uint32_t next = 0;
    for (uint64_t bi = 0; bi < p.nbatches; bi++) {
        const pc_batch *bt = &p.batches[bi];
        assert_int_equal(bt->first, next);
        assert_true(bt->count > 0 && bt->count <= PC_BATCH_POINTS);
        next += bt->count;
        double v = 1;
        for (int k = 0; k < 3; k++) v *= bt->bmax[k] - bt->bmin[k];
        sum += v;
        for (uint32_t i = bt->first; i < bt->first + bt->count; i++)
            for (int k = 0; k < 3; k++) {
                assert_true(p.pos[3 * i + k] >= bt->bmin[k] && p.pos[3 * i + k] <= bt->bmax[k]);
            }
        /* tight: some point touches each face */
        for (int k = 0; k < 3; k++) {
            int tmin = 0, tmax = 0;
            for (uint32_t i = bt->first; i < bt->first + bt->count; i++) {
                tmin |= p.pos[3 * i + k] == bt->bmin[k];
                tmax |= p.pos[3 * i + k] == bt->bmax[k];
            }
            assert_true(tmin && tmax);
        }
    }
    assert_int_equal(next, p.n);
    for (size_t i = 1; i < p.n; i++) {
        const float *x = p.pos + 3 * (i - 1), *y = p.pos + 3 * i;
        const float *u = c.pos + 3 * (i - 1), *w = c.pos + 3 * i;
        step_m += sqrt((x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]));
        step_r += sqrt((u[0] - w[0]) * (u[0] - w[0]) + (u[1] - w[1]) * (u[1] - w[1]) + (u[2] - w[2]) * (u[2] - w[2]));
    }
    print_message("bunny: batch boxes sum %.3f of the cloud's volume over %llu batches; mean step "
                  "%.2e (Morton) vs %.2e (file order), sigma %.2e\n", sum / vol,
                  (unsigned long long)p.nbatches, step_m / (p.n - 1), step_r / (p.n - 1), p.sigma);
    assert_true(sum < 0.25 * vol * (double)p.nbatches);
    /* consecutive points are near: the mean step is a few point spacings */
    assert_true(step_m / (p.n - 1) < 4 * p.sigma);
    free(a); free(b);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* Morton locality on 200k random points in a cube (49 batches): in random order every batch's
 * box is nearly the whole cube (sum ~ 49 volumes); in Morton order the batches split the cube
 * into pieces whose boxes overlap little (sum measured 3.7 volumes: boxes of Z-curve pieces
 * that straddle big octree boundaries are loose), and the mean step
 * between consecutive points is close to the mean nearest-neighbour distance. */
static void test_morton_locality_cube(void **state)
{
    (void)state;
    size_t n = 200000;
    pc_cloud c = make_cloud(n);
    rng r = {17};
    for (size_t i = 0; i < 3 * n; i++) c.pos[i] = (float)uni(&r);
    prep_desc d = {.k = 8};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    double sum = 0, step = 0;
    for (uint64_t b = 0; b < p.nbatches; b++) {
        const pc_batch *bt = &p.batches[b];
        sum += (double)(bt->bmax[0] - bt->bmin[0]) * (bt->bmax[1] - bt->bmin[1]) *
               (bt->bmax[2] - bt->bmin[2]);
    }
    for (size_t i = 1; i < n; i++) {
        const float *x = p.pos + 3 * (i - 1), *y = p.pos + 3 * i;
        step += sqrt((x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) +
                     (x[2] - y[2]) * (x[2] - y[2]));
    }
    step /= (double)(n - 1);
    double nn = 0.554 * cbrt(1.0 / (double)n); /* mean nearest-neighbour distance */
    print_message("cube: %llu batches, box volumes sum %.2f; mean step %.2e = %.2f nn distances\n",
                  (unsigned long long)p.nbatches, sum, step, step / nn);
    assert_true(sum < 6);
    assert_true(step < 4 * nn);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

/* ---- threads, methods, progress, bad input ---- */

static void test_threads_identical(void **state)
{
    (void)state;
    pc_cloud c;
    load_data("bun000.ply", &c);
    for (int m = 0; m < 2; m++) {
        prep_desc d1 = {.k = 24, .threads = 1, .knn = m ? PREP_KNN_FLANN : PREP_KNN_GRID};
        prep_desc d3 = d1;
        d3.threads = 3;
        pc_prepared a, b;
        sd_err err = {0};
        assert_int_equal(prep_run(&c, &d1, &a, &err), 0);
        assert_int_equal(prep_run(&c, &d3, &b, &err), 0);
        assert_int_equal(a.block_len, b.block_len);
        assert_memory_equal(a.block, b.block, a.block_len);
        assert_true(a.sigma == b.sigma && a.F_raw_p99 == b.F_raw_p99);
        assert_memory_equal(a.F_pct, b.F_pct, sizeof a.F_pct);
        pc_prepared_free(&b);
        /* neighbour lists over the memory limit: F's second kNN pass gives the same cloud */
        prep_desc dr = d3;
        dr.max_nbr_bytes = 1;
        assert_int_equal(prep_run(&c, &dr, &b, &err), 0);
        assert_memory_equal(a.block, b.block, a.block_len);
        pc_prepared_free(&a);
        pc_prepared_free(&b);
    }
    pc_cloud_free(&c);
}

/* The grid and FLANN on every point of a real scan: the distance lists are identical (both
 * compute float squared distances of the same coordinates), and the neighbour sets differ only
 * where distinct points tie at the k-th distance (this range scan has quantised coordinates,
 * so such ties exist). prep's sigma, a function of distances only, is then identical. */
static void test_grid_equals_flann(void **state)
{
    (void)state;
    pc_cloud c;
    load_data("bun000.ply", &c);
    int k = 24;
    size_t n = c.n;
    prep_knn *g = NULL, *f = NULL;
    sd_err err = {0};
    prep_knn_opts og = {.method = PREP_KNN_GRID}, of = {.method = PREP_KNN_FLANN};
    assert_int_equal(prep_knn_build(c.pos, n, &og, &g, &err), 0);
    assert_int_equal(prep_knn_build(c.pos, n, &of, &f, &err), 0);
    prep_knn_scratch *s = prep_knn_scratch_new();
    uint32_t *ig = malloc(n * k * sizeof *ig), *iff = malloc(n * k * sizeof *iff);
    float *dg = malloc(n * k * sizeof *dg), *df = malloc(n * k * sizeof *df);
    assert_non_null(ig); assert_non_null(iff); assert_non_null(dg); assert_non_null(df);
    assert_int_equal(prep_knn_query(g, NULL, 0, n, k, ig, dg, s, &err), 0);
    assert_int_equal(prep_knn_query(f, NULL, 0, n, k, iff, df, s, &err), 0);
    size_t differ = 0;
    for (size_t i = 0; i < n; i++) {
        const float *a = dg + i * k, *b = df + i * k;
        for (int j = 0; j < k; j++) assert_true(fabsf(a[j] - b[j]) <= 1e-6f * a[j]);
        if (memcmp(ig + i * k, iff + i * k, k * sizeof *ig) == 0) continue;
        differ++;
        /* a differing index must sit at the k-th distance, which another point shares */
        for (int j = 0; j < k; j++)
            if (ig[i * k + j] != iff[i * k + j]) assert_true(a[j] == a[k - 1]);
    }
    print_message("grid vs flann on %zu points: %zu neighbour lists differ, all by k-th "
                  "distance ties\n", n, differ);
    assert_true(differ < n / 20);
    prep_desc dg_ = {.k = 24, .threads = 2}, df_ = dg_;
    df_.knn = PREP_KNN_FLANN;
    pc_prepared pa, pb;
    assert_int_equal(prep_run(&c, &dg_, &pa, &err), 0);
    assert_int_equal(prep_run(&c, &df_, &pb, &err), 0);
    assert_true(pa.sigma == pb.sigma);
    assert_true(fabsf(pa.radius_median - pb.radius_median) <= 1e-6f * pa.radius_median);
    pc_prepared_free(&pa);
    pc_prepared_free(&pb);
    free(ig); free(iff); free(dg); free(df);
    prep_knn_scratch_free(s);
    prep_knn_free(g);
    prep_knn_free(f);
    pc_cloud_free(&c);
}

typedef struct prog_rec {
    pthread_t main;
    int calls[4], bad_thread, bad_order;
    double last[4];
} prog_rec;

static void record_progress(void *user, int phase, double f)
{
    prog_rec *r = user;
    static const int phases[4] = {PROTO_PHASE_REORDER, PROTO_PHASE_KNN, PROTO_PHASE_NORMALS,
                                  PROTO_PHASE_FIELD};
    if (!pthread_equal(pthread_self(), r->main)) r->bad_thread++;
    for (int i = 0; i < 4; i++)
        if (phase == phases[i]) {
            /* multiples of 1/20, increasing, starting at 0 */
            if (fabs(f * 20 - floor(f * 20 + 0.5)) > 1e-9) r->bad_order++;
            if (r->calls[i] == 0 ? f != 0 : f <= r->last[i]) r->bad_order++;
            r->calls[i]++;
            r->last[i] = f;
            return;
        }
    r->bad_order++;
}

static void test_progress(void **state)
{
    (void)state;
    pc_cloud c = sphere_cloud(200000, 1, 0, 2);
    prog_rec r = {.main = pthread_self()};
    prep_desc d = {.k = 8, .threads = 2, .progress = record_progress, .user = &r};
    pc_prepared p;
    sd_err err = {0};
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    assert_int_equal(r.bad_thread, 0);
    assert_int_equal(r.bad_order, 0);
    for (int i = 0; i < 4; i++) {
        assert_true(r.calls[i] >= 2 && r.calls[i] <= 21);
        assert_true(r.last[i] == 1.0);
    }
    /* 13 chunks on 2 threads: the calling thread finishes several, each reported as it
     * happens with every twentieth crossed, so the normals phase reports in steps */
    assert_true(r.calls[2] >= 5);
    pc_prepared_free(&p);
    pc_cloud_free(&c);
}

static void test_small_and_bad_input(void **state)
{
    (void)state;
    pc_prepared p;
    sd_err err = {0};
    pc_cloud c = make_cloud(5);
    for (int i = 0; i < 5; i++) { c.pos[3 * i] = (float)i; c.pos[3 * i + 1] = (float)(i * i); }
    prep_desc d = {.k = 300};
    assert_int_equal(prep_run(&c, &d, &p, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "k = 300"));
    assert_null(p.block);
    d.k = 24; /* more than the cloud has: K = n - 1 */
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    assert_int_equal(p.k, 4);
    /* the farthest of the 4 others from (0,0,0) is (4,16,0) */
    for (size_t i = 0; i < 5; i++)
        if (p.pos[3 * i] == 0) assert_true(fabsf(p.radius[i] - 2 * sqrtf(272) / 2) < 1e-4f);
    pc_prepared_free(&p);
    c.attrs = PC_ATTR_RGB; /* claims colours without an array */
    assert_int_equal(prep_run(&c, &d, &p, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "rgb"));
    c.attrs = 0;
    c.n = 1;
    assert_int_equal(prep_run(&c, &d, &p, &err), 0);
    assert_int_equal(p.n, 1);
    assert_true(p.normal[2] == 1 && p.radius[0] == 1 && p.F[0] == 0);
    pc_prepared_free(&p);
    c.n = 0;
    assert_int_equal(prep_run(&c, &d, &p, &err), SD_EINVAL);
    assert_int_equal(prep_run(NULL, &d, &p, &err), SD_EINVAL);
    c.n = 5;
    pc_cloud_free(&c);
}

static void test_percentile(void **state)
{
    (void)state;
    rng r = {3};
    for (int t = 0; t < 200; t++) {
        size_t n = 1 + next64(&r) % 3000;
        float *v = malloc(n * sizeof *v), *s = malloc(n * sizeof *s);
        assert_non_null(v); assert_non_null(s);
        int levels = 1 + (int)(next64(&r) % 50); /* many duplicates */
        for (size_t i = 0; i < n; i++) v[i] = s[i] = (float)(next64(&r) % (uint64_t)levels);
        qsort(s, n, sizeof *s, cmp_float);
        double q = uni(&r);
        size_t want = (size_t)floor(q * (n - 1) + 0.5);
        assert_true(prep_percentile(v, n, q) == s[want]);
        free(v); free(s);
    }
    /* small sets (a neighbourhood's radii) take a counting path of their own */
    for (int t = 0; t < 400; t++) {
        size_t n = 1 + next64(&r) % 70;
        float v[70], s[70];
        int levels = 1 + (int)(next64(&r) % 30);
        for (size_t i = 0; i < n; i++) v[i] = s[i] = (float)(next64(&r) % (uint64_t)levels) * 0.25f;
        qsort(s, n, sizeof *s, cmp_float);
        double q = t % 4 == 0 ? 0.5 : uni(&r);
        size_t want = (size_t)floor(q * (n - 1) + 0.5);
        assert_true(prep_percentile(v, n, q) == s[want]);
    }
    float nan3[3] = {1, NAN, 2}; /* NaN: quickselect's answer, whatever it is, and no crash */
    float got = prep_percentile(nan3, 3, 0.5);
    assert_true(got == 1 || got == 2 || got != got);
    assert_true(prep_percentile(NULL, 0, 0.5) == 0);
}

/* gen_cloud (the bench's synthetic scene): N points exactly, same seed same bytes, another
 * seed other bytes, readable by pc_load with colours, and a scene about 100 m across. make test
 * builds the tool and sets $SPLATD_TOOLS, so a missing tool is a failure, not a skip. */
static void test_gen_cloud_tool(void **state)
{
    (void)state;
    char tool[512], dir[512], a[600], b[600], c2[600], cmd[8192];
    snprintf(tool, sizeof tool, "%s/gen_cloud", tu_env("SPLATD_TOOLS", "build/tools"));
    FILE *t = fopen(tool, "rb");
    if (!t) fail_msg("gen_cloud not found at %s (set SPLATD_TOOLS)", tool);
    fclose(t);
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    snprintf(a, sizeof a, "%s/a.ply", dir);
    snprintf(b, sizeof b, "%s/b.ply", dir);
    snprintf(c2, sizeof c2, "%s/c.ply", dir);
    snprintf(cmd, sizeof cmd, "'%s' 20000 '%s' && '%s' 20000 '%s' && '%s' 20000 '%s' --seed 7",
             tool, a, tool, b, tool, c2);
    assert_int_equal(system(cmd), 0);
    size_t la, lb, lc;
    uint8_t *da = tu_read_file(a, &la), *db = tu_read_file(b, &lb), *dc = tu_read_file(c2, &lc);
    assert_non_null(da); assert_non_null(db); assert_non_null(dc);
    assert_int_equal(la, lb);
    assert_memory_equal(da, db, la);
    /* the header names the seed, so only the last 300 kB (the points) are compared */
    assert_true(la > 300000 && lc > 300000);
    assert_true(memcmp(da + la - 300000, dc + lc - 300000, 300000) != 0);
    pc_cloud cl;
    sd_err err = {0};
    if (pc_load(a, &cl, &err) != 0) fail_msg("%s", err.msg);
    assert_int_equal(cl.n, 20000);
    assert_true(cl.attrs & PC_ATTR_RGB);
    for (int k = 0; k < 2; k++) assert_true(cl.bmax[k] - cl.bmin[k] > 90 && cl.bmax[k] - cl.bmin[k] < 110);
    pc_cloud_free(&cl);
    free(da); free(db); free(dc);
    tu_rm_rf(dir);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_morton_roundtrip_and_sort),
        cmocka_unit_test(test_morton_clamps_outside_points),
        cmocka_unit_test(test_radix_sort),
        cmocka_unit_test(test_eigen_solver),
        cmocka_unit_test(test_pca_counts_the_point_itself),
        cmocka_unit_test(test_percentile),
        cmocka_unit_test(test_knn_bad_args),
        cmocka_unit_test(test_knn_hard_cases),
        cmocka_unit_test(test_knn_paths_exact),
        cmocka_unit_test(test_knn_scratch_across_grids),
        cmocka_unit_test(test_knn_real_scan),
        cmocka_unit_test(test_knn_real_scan_guanyin),
        cmocka_unit_test(test_normals_plane),
        cmocka_unit_test(test_normals_sphere),
        cmocka_unit_test(test_file_normals_kept),
        cmocka_unit_test(test_radius_sigma_grid),
        cmocka_unit_test(test_normals_face_sensor),
        cmocka_unit_test(test_radius_outlier_limited),
        cmocka_unit_test(test_radius_scatter_limited),
        cmocka_unit_test(test_field_vegetation_vs_plane),
        cmocka_unit_test(test_sigma_is_median),
        cmocka_unit_test(test_cloud_of_exactly_k_points),
        cmocka_unit_test(test_morton_order_and_attributes),
        cmocka_unit_test(test_morton_locality_cube),
        cmocka_unit_test(test_threads_identical),
        cmocka_unit_test(test_grid_equals_flann),
        cmocka_unit_test(test_progress),
        cmocka_unit_test(test_small_and_bad_input),
        cmocka_unit_test(test_gen_cloud_tool),
    };
    const char *only = getenv("SPLATD_TEST_FILTER"); /* e.g. "test_knn*" */
    if (only && *only) cmocka_set_test_filter(only);
    return cmocka_run_group_tests(tests, NULL, NULL);
}
