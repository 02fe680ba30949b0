/* prep_bench — times pc_load and prep_run's phases on one file; prints Markdown table rows.
 *
 *   prep_bench FILE [--runs R] [--knn grid|flann|both] [--threads T] [--k K] [--leaf L]
 *              [--header] [--knn-only [--file-order] [--hash] [--simd S]]
 *
 * Each figure is the median of R runs (default 3). --knn-only times the kNN alone for every
 * point, comparing FLANN's own OpenMP threads (cores = T, one calling thread) with T pthreads
 * each querying a slice (cores = 1), and the grid with T pthreads, on the points in Morton
 * order (as prep_run queries them) or, with --file-order, in the file's order. --hash prints
 * (to stderr) an XXH64 of every query's neighbour indices and squared distances, per run: two
 * builds of the kNN must print the same for the same file, k and order. --simd pins the grid's
 * vector path (prep_knn_opts.simd: 1 portable, 2 AVX2, 3 AVX-512; 0 the best). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <xxhash.h>

#include "knn.h"
#include "morton.h"
#include "prep.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* CPU seconds (user + system, all threads) this process has used so far. */
static double cpu_s(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return (double)ru.ru_utime.tv_sec + ru.ru_utime.tv_usec * 1e-6 + (double)ru.ru_stime.tv_sec +
           ru.ru_stime.tv_usec * 1e-6;
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return n % 2 ? v[n / 2] : (v[n / 2 - 1] + v[n / 2]) / 2;
}

static const char *base(const char *p)
{
    const char *s = strrchr(p, '/');
    return s ? s + 1 : p;
}

/* ---- --knn-only ---- */

/* Puts the cloud's positions in Morton order, as prep_run does before its kNN. */
static int morton_order(pc_cloud *c)
{
    prep_morton_frame f;
    prep_morton_frame_of(c->pos, c->n, &f);
    uint64_t *codes = malloc(c->n * sizeof *codes);
    uint32_t *perm = malloc(c->n * sizeof *perm);
    float *p = malloc(3 * c->n * sizeof *p);
    sd_err err = {0};
    if (!codes || !perm || !p || prep_morton_sort(c->pos, c->n, &f, codes, perm, &err) != 0) {
        fprintf(stderr, "prep_bench: cannot sort: %s\n", err.msg);
        return -1;
    }
    for (size_t i = 0; i < c->n; i++) memcpy(p + 3 * i, c->pos + 3 * (size_t)perm[i], 12);
    memcpy(c->pos, p, 3 * c->n * sizeof *p);
    free(codes); free(perm); free(p);
    return 0;
}

typedef struct slice_job {
    const prep_knn *kn;
    size_t n;
    int k;
    uint32_t *idx;
    float *d2;
    prep_knn_scratch **s;
} slice_job;

enum { SLICE = 16384 };

static int slice_fn(void *ctx, size_t c, int tid, sd_err *err)
{
    slice_job *j = ctx;
    size_t first = c * SLICE, m = j->n - first < SLICE ? j->n - first : SLICE;
    return prep_knn_query(j->kn, NULL, first, m, j->k, j->idx + first * (size_t)j->k,
                          j->d2 + first * (size_t)j->k, j->s[tid], err);
}

/* Seconds to build and to query every point, method m, threads t; flann_cores > 1 runs one
 * thread with FLANN's OpenMP threads instead of pthreads. */
static int knn_time(const pc_cloud *c, prep_knn_method m, int leaf, int t, int flann_cores,
                    int k, int hash, int simd, double *tb, double *tq, double *tc,
                    prep_knn_counters *cnt)
{
    sd_err err = {0};
    prep_knn *kn = NULL;
    prep_knn_opts o = {.method = m, .leaf_size = leaf, .flann_cores = flann_cores, .simd = simd};
    double t0 = now_s();
    if (prep_knn_build(c->pos, c->n, &o, &kn, &err) != 0) {
        fprintf(stderr, "prep_bench: %s\n", err.msg);
        return -1;
    }
    *tb = now_s() - t0;
    slice_job j = {kn, c->n, k, malloc(c->n * k * sizeof(uint32_t)),
                   malloc(c->n * k * sizeof(float)), calloc(8, sizeof(prep_knn_scratch *))};
    for (int i = 0; i < 8; i++) j.s[i] = prep_knn_scratch_new();
    t0 = now_s();
    double c0 = cpu_s();
    int rc = prep_par_for(flann_cores > 1 ? 1 : t, (c->n + SLICE - 1) / SLICE, slice_fn, &j, NULL,
                          &err);
    *tq = now_s() - t0;
    *tc = cpu_s() - c0;
    if (rc == 0 && hash)
        fprintf(stderr, "knn hash (n %zu, k %d): idx %016llx d2 %016llx\n", c->n, k,
                (unsigned long long)XXH64(j.idx, c->n * k * sizeof(uint32_t), 0),
                (unsigned long long)XXH64(j.d2, c->n * k * sizeof(float), 0));
    memset(cnt, 0, sizeof *cnt);
    for (int i = 0; i < 8; i++) {
        prep_knn_counters x;
        prep_knn_scratch_counters(j.s[i], &x);
        cnt->queries += x.queries;
        cnt->widened += x.widened;
        cnt->dense += x.dense;
        cnt->candidates += x.candidates;
        cnt->filtered += x.filtered;
        cnt->gathers += x.gathers;
        prep_knn_scratch_free(j.s[i]);
    }
    free(j.s);
    free(j.idx);
    free(j.d2);
    prep_knn_free(kn);
    if (rc != 0) fprintf(stderr, "prep_bench: %s\n", err.msg);
    return rc;
}

int main(int argc, char **argv)
{
    const char *file = NULL, *knn = "grid";
    int runs = 3, threads = 2, k = 24, leaf = 0, header = 0, knn_only = 0, file_order = 0;
    int hash = 0, simd = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--knn") && i + 1 < argc) knn = argv[++i];
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc) threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--k") && i + 1 < argc) k = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--leaf") && i + 1 < argc) leaf = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--header")) header = 1;
        else if (!strcmp(argv[i], "--knn-only")) knn_only = 1;
        else if (!strcmp(argv[i], "--file-order")) file_order = 1;
        else if (!strcmp(argv[i], "--hash")) hash = 1;
        else if (!strcmp(argv[i], "--simd") && i + 1 < argc) simd = atoi(argv[++i]);
        else if (!file) file = argv[i];
        else {
            fprintf(stderr, "prep_bench: unexpected '%s'\n", argv[i]);
            return 2;
        }
    }
    if (!file || runs < 1 || runs > 99 || threads < 1 || threads > 8) {
        fprintf(stderr, "usage: prep_bench FILE [--runs R] [--knn grid|flann|both] [--threads T<=8] "
                        "[--k K] [--leaf L] [--header] [--knn-only [--file-order] [--hash] [--simd S]]\n");
        return 2;
    }
    double tl[99];
    pc_cloud c;
    sd_err err = {0};
    for (int r = 0; r < runs; r++) {
        double t0 = now_s();
        if (pc_load(file, &c, &err) != 0) {
            fprintf(stderr, "prep_bench: %s\n", err.msg);
            return 1;
        }
        tl[r] = now_s() - t0;
        if (r + 1 < runs) pc_cloud_free(&c);
    }
    double load = median(tl, runs);

    if (knn_only) {
        if (!file_order && morton_order(&c) != 0) return 1;
        if (header)
            printf("| file | points | kNN (k = %d) | order | threads | build s | query s | "
                   "queries/s | query CPU s | widened | dense | avg candidates |\n"
                   "|---|---|---|---|---|---|---|---|---|---|---|---|\n", k);
        struct { prep_knn_method m; int fc; const char *name; } v[] = {
            {PREP_KNN_GRID, 1, "grid, pthreads"},
            {PREP_KNN_FLANN, 1, "flann, pthreads (cores = 1)"},
            {PREP_KNN_FLANN, threads, "flann, one thread, cores = T"},
        };
        for (int i = 0; i < 3; i++) {
            if (i == 2 && threads == 1) continue;
            if (!strcmp(knn, "grid") && v[i].m != PREP_KNN_GRID) continue;
            if (!strcmp(knn, "flann") && v[i].m != PREP_KNN_FLANN) continue;
            double b[99], q[99], qc[99];
            prep_knn_counters cnt = {0};
            for (int r = 0; r < runs; r++)
                if (knn_time(&c, v[i].m, leaf, threads, v[i].fc, k, hash, simd, &b[r], &q[r], &qc[r], &cnt) != 0)
                    return 1;
            double mb = median(b, runs), mq = median(q, runs);
            printf("| %s | %zu | %s | %s | %d | %.3f | %.3f | %.2fM | %.3f | %.1f%% | %.2f%% | %.0f |\n",
                   base(file), c.n, v[i].name, file_order ? "file" : "Morton", threads, mb, mq,
                   c.n / mq / 1e6, median(qc, runs),
                   cnt.queries ? 100.0 * cnt.widened / cnt.queries : 0.0,
                   cnt.queries ? 100.0 * cnt.dense / cnt.queries : 0.0,
                   cnt.queries ? (double)cnt.candidates / cnt.queries : 0.0);
        if (getenv("PREP_BENCH_DEBUG"))
            fprintf(stderr, "selected from %.1f per query, %.3f gathers per query\n",
                    (double)cnt.filtered / (cnt.queries ? cnt.queries : 1),
                    (double)cnt.gathers / (cnt.queries ? cnt.queries : 1));
        }
        pc_cloud_free(&c);
        return 0;
    }

    if (header)
        printf("| file | points | kNN | threads | load s | reorder s | knn build s | knn query s | "
               "normals s | radius s | F s | prep total s | prep Mpts/s | prep CPU s |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int m = 0; m < 2; m++) {
        prep_knn_method meth = m ? PREP_KNN_FLANN : PREP_KNN_GRID;
        if (strcmp(knn, "both") && strcmp(knn, prep_knn_method_name(meth))) continue;
        double tr[99], tb[99], tq[99], tn[99], trd[99], tf[99], tt[99], tc[99];
        for (int r = 0; r < runs; r++) {
            prep_desc d = {.k = k, .threads = threads, .knn = meth, .knn_leaf = leaf};
            pc_prepared p;
            double t0 = now_s(), c0 = cpu_s();
            if (prep_run(&c, &d, &p, &err) != 0) {
                fprintf(stderr, "prep_bench: %s\n", err.msg);
                return 1;
            }
            tt[r] = now_s() - t0;
            tc[r] = cpu_s() - c0;
            tr[r] = p.stats.t_reorder;
            tb[r] = p.stats.t_knn_build;
            tq[r] = p.stats.t_knn_query;
            tn[r] = p.stats.t_normals;
            trd[r] = p.stats.t_radius;
            tf[r] = p.stats.t_field;
            pc_prepared_free(&p);
        }
        double total = median(tt, runs);
        printf("| %s | %zu | %s | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.2f | %.3f |\n",
               base(file), c.n, prep_knn_method_name(meth), threads, load, median(tr, runs),
               median(tb, runs), median(tq, runs), median(tn, runs), median(trd, runs),
               median(tf, runs), total, c.n / total / 1e6, median(tc, runs));
    }
    pc_cloud_free(&c);
    return 0;
}
