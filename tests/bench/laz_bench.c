/* laz_bench — LAZ decode throughput of splatd's decoder; prints one Markdown table row per file.
 *
 *   laz_bench FILE.laz [--twin FILE.las] [--runs R] [--header]
 *   laz_bench FILE.copc.laz --levels [--runs R]
 *
 * Figures are medians of R runs (default 9), the file already in memory (read once):
 *   decode 1 thread   laz_open + every chunk decoded into records (no conversion): the decoder;
 *                     also per CPU second of the decoding thread (steadier on a shared machine)
 *   reader 1 / 2      pc_read_laz_threads with 1 and 2 threads: decode + conversion into the
 *                     cloud's arrays (what pc_load does before finalizing), file mapped
 *   .las read         pc_read_las on the uncompressed twin (when given): the same cloud
 * With --levels: for each octree depth L, pc_read_copc_levels (hierarchy pages down to L,
 * then those nodes) against the whole file, one row per L.
 * and the FNV-1a 64 hash of all decoded records in file order (lazperf_bench.js prints the
 * same hash for laz-perf's decoder, so equal hashes mean equal output). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cloud.h"
#include "laz.h"
#include "common/testutil.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* CPU seconds of the calling thread: what a decode costs, whatever else the machine runs. */
static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return v[n / 2];
}

static uint64_t fnv(uint64_t h, const uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

/* decode_once: every chunk of the file in memory; returns seconds, hash when hash != NULL. */
static double decode_once(const char *path, const uint8_t *d, size_t len, uint64_t *hash,
                          uint64_t *count, double *cpu)
{
    double t0 = now_s(), c0 = cpu_s();
    laz_file lf;
    sd_err e = {0};
    if (laz_open(&lf, path, d, len, &e)) {
        fprintf(stderr, "laz_bench: %s\n", e.msg);
        exit(1);
    }
    laz_chunk_dec *cd = laz_chunk_dec_create(lf.items, lf.nitems);
    uint8_t *buf = NULL;
    size_t cap = 0;
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t c = 0; c < lf.nchunks; c++) {
        if (laz_read_chunk(&lf, cd, c, &buf, &cap, &e)) {
            fprintf(stderr, "laz_bench: %s\n", e.msg);
            exit(1);
        }
        if (hash)
            h = fnv(h, buf, (size_t)(lf.chunk_first[c + 1] - lf.chunk_first[c]) * lf.h.rec_len);
    }
    double t = now_s() - t0;
    if (cpu) *cpu = cpu_s() - c0;
    if (hash) *hash = h;
    *count = lf.h.count;
    free(buf);
    laz_chunk_dec_free(cd);
    laz_close(&lf);
    return t;
}

static double read_laz(const char *path, int threads)
{
    pc_raw r = {0};
    sd_err e = {0};
    double t0 = now_s();
    if (pc_read_laz_threads(path, &r, threads, &e)) {
        fprintf(stderr, "laz_bench: %s\n", e.msg);
        exit(1);
    }
    double t = now_s() - t0;
    pc_raw_free(&r);
    return t;
}

static double read_las(const char *path)
{
    pc_raw r = {0};
    sd_err e = {0};
    double t0 = now_s();
    if (pc_read_las(path, &r, &e)) {
        fprintf(stderr, "laz_bench: %s\n", e.msg);
        exit(1);
    }
    double t = now_s() - t0;
    pc_raw_free(&r);
    return t;
}

static double read_levels(const char *path, int level, size_t *n)
{
    pc_raw r = {0};
    sd_err e = {0};
    double t0 = now_s();
    if (pc_read_copc_levels(path, level, &r, &e)) {
        fprintf(stderr, "laz_bench: %s\n", e.msg);
        exit(1);
    }
    double t = now_s() - t0;
    *n = r.n;
    pc_raw_free(&r);
    return t;
}

/* levels: one row per octree depth, until a depth gives the whole cloud. */
static int levels(const char *file, int runs)
{
    double *t = calloc((size_t)runs, sizeof *t), *tf = calloc((size_t)runs, sizeof *tf);
    for (int r = 0; r < runs; r++) tf[r] = read_laz(file, 1);
    double full = median(tf, runs);
    const char *base = strrchr(file, '/') ? strrchr(file, '/') + 1 : file;
    printf("| %s: levels read | points | ms (1 thread) | share of the full read (%.1f ms) |\n",
           base, full * 1e3);
    printf("|---|---|---|---|\n");
    size_t n = 0, prev = (size_t)-1;
    for (int L = 0; L < 31; L++) {
        for (int r = 0; r < runs; r++) t[r] = read_levels(file, L, &n);
        if (n == prev) break;
        double m = median(t, runs);
        printf("| 0-%d | %zu | %.2f | %.0f%% |\n", L, n, m * 1e3, 100 * m / full);
        prev = n;
    }
    free(t);
    free(tf);
    return 0;
}

int main(int argc, char **argv)
{
    const char *file = NULL, *twin = NULL;
    int runs = 9, header = 0, lv = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--twin") && i + 1 < argc) twin = argv[++i];
        else if (!strcmp(argv[i], "--header")) header = 1;
        else if (!strcmp(argv[i], "--levels")) lv = 1;
        else if (!file) file = argv[i];
    }
    if (!file || runs < 1 || runs > 1000) {
        fprintf(stderr, "usage: laz_bench FILE.laz [--twin FILE.las] [--runs R] [--header]\n");
        return 2;
    }
    if (lv) return levels(file, runs);
    size_t len;
    uint8_t *d = tu_read_file(file, &len);
    if (!d) {
        fprintf(stderr, "laz_bench: cannot read %s\n", file);
        return 1;
    }
    uint64_t hash, n;
    decode_once(file, d, len, &hash, &n, NULL); /* warm-up, and the hash */
    double *td = calloc((size_t)runs, sizeof *td), *t1 = calloc((size_t)runs, sizeof *t1),
           *t2 = calloc((size_t)runs, sizeof *t2), *tl = calloc((size_t)runs, sizeof *tl),
           *tc = calloc((size_t)runs, sizeof *tc);
    for (int r = 0; r < runs; r++) {
        td[r] = decode_once(file, d, len, NULL, &n, &tc[r]);
        t1[r] = read_laz(file, 1);
        t2[r] = read_laz(file, 2);
        tl[r] = twin ? read_las(twin) : 0;
    }
    double md = median(td, runs), m1 = median(t1, runs), m2 = median(t2, runs),
           ml = median(tl, runs), mc = median(tc, runs);
    if (header) {
        printf("| file | points | decode 1 thread Mpts/s | per CPU second | reader 1 thread "
               "Mpts/s | reader 2 threads Mpts/s | 2 / 1 threads | .las twin read Mpts/s | "
               "FNV-1a of records |\n");
        printf("|---|---|---|---|---|---|---|---|---|\n");
    }
    const char *base = strrchr(file, '/') ? strrchr(file, '/') + 1 : file;
    char las[64] = "—";
    if (twin) snprintf(las, sizeof las, "%.1f", (double)n / ml / 1e6);
    printf("| %s | %llu | %.2f | %.2f | %.2f | %.2f | %.2fx | %s | %016llx |\n", base,
           (unsigned long long)n, (double)n / md / 1e6, (double)n / mc / 1e6, (double)n / m1 / 1e6,
           (double)n / m2 / 1e6, m1 / m2, las, (unsigned long long)hash);
    free(td);
    free(t1);
    free(t2);
    free(tl);
    free(tc);
    free(d);
    return 0;
}
