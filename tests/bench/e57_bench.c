/* e57_bench — E57 read throughput against the LAS reader on the same points; prints Markdown
 * table rows.
 *
 *   e57_bench DIR [--points N] [--runs R] [--header]
 *
 * Writes into DIR (tests/common/e57test.c's writer) two E57 files of N points (default 4M) in
 * two scans with poses, RGB (8-bit) and a 12-bit intensity: one with double coordinates
 * (libE57Format's default), one with scaled-integer coordinates (1 mm, 20-bit); and a LAS 1.2
 * point format 3 file of the same points at 1 mm (the reference). Then, files in the page cache,
 * the median of R runs (default 3) of:
 *   pc_read_e57 / pc_read_las   the whole-file read into a raw cloud (what pc_load does before
 *                               finalizing), points per second of wall time;
 *   stream                      pc_e57_stream_next over every point, positions and colours
 *                               only (the LOD build's pass), bounded memory.
 * Each read's coordinate sum is printed beside it: the readers agree to the 1 mm grid. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cloud.h"
#include "e57_stream.h"
#include "e57test.h"
#include "testutil.h"

static double now_s(void)
{
    return tu_now_us() * 1e-6;
}

/* CPU seconds of the process: steadier than wall time on a shared machine. */
static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* The points: a terrain-like sheet of 1 mm resolution, per scan a 2000-wide grid, values the
 * LAS grid holds exactly (local coordinates in mm, the pose a translation of whole metres). */
static void point(uint64_t i, int64_t mm[3], int rgbi[4])
{
    int64_t gx = (int64_t)(i % 2000), gy = (int64_t)(i / 2000);
    mm[0] = gx * 7;
    mm[1] = gy * 7;
    mm[2] = (int64_t)(500.0 * sin(gx * 0.01) * cos(gy * 0.013)) + 1000;
    rgbi[0] = (int)(gx % 256), rgbi[1] = (int)(gy % 256), rgbi[2] = (int)((gx + gy) % 256);
    rgbi[3] = (int)((gx * 13 + gy * 7) % 4096);
}

static void gen_rec(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx, (void)scan;
    int64_t mm[3];
    int c[4];
    point(i, mm, c);
    for (int k = 0; k < 3; k++) {
        ints[k] = mm[k];
        dbls[k] = (double)mm[k] * 0.001;
    }
    for (int k = 0; k < 4; k++) ints[3 + k] = c[k];
}

static void put_le(uint8_t *p, uint64_t v, int n)
{
    for (int i = 0; i < n; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* write_las: the same points (the second scan shifted by the pose) as LAS 1.2 format 3. */
static int write_las(const char *path, uint64_t per_scan)
{
    FILE *f = fopen(path, "wb");
    if (!f) return -1;
    uint8_t h[227] = {0};
    memcpy(h, "LASF", 4);
    h[24] = 1, h[25] = 2;
    put_le(h + 94, 227, 2);
    put_le(h + 96, 227, 4);
    h[104] = 3;
    put_le(h + 105, 34, 2);
    put_le(h + 107, 2 * per_scan, 4);
    double sc[3] = {0.001, 0.001, 0.001}, off[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
        memcpy(h + 131 + 8 * k, &sc[k], 8);
        memcpy(h + 155 + 8 * k, &off[k], 8);
    }
    double box[6] = {1e9, -1e9, 1e9, -1e9, 1e9, -1e9}; /* max, min per axis (unused here) */
    memcpy(h + 179, box, sizeof box);
    int ok = fwrite(h, 1, sizeof h, f) == sizeof h;
    uint8_t *buf = malloc(34 * 65536);
    for (int s = 0; s < 2 && ok; s++)
        for (uint64_t i = 0; i < per_scan && ok;) {
            uint64_t m = per_scan - i < 65536 ? per_scan - i : 65536;
            memset(buf, 0, 34 * m);
            for (uint64_t j = 0; j < m; j++) {
                int64_t mm[3];
                int c[4];
                point(i + j, mm, c);
                uint8_t *r = buf + 34 * j;
                mm[0] += s * 1000000; /* the second scan's pose: +1000 m in x */
                for (int k = 0; k < 3; k++) put_le(r + 4 * k, (uint64_t)mm[k], 4);
                put_le(r + 12, (uint64_t)c[3], 2);
                for (int k = 0; k < 3; k++) put_le(r + 28 + 2 * k, (uint64_t)c[k], 2);
            }
            ok = fwrite(buf, 34, m, f) == m;
            i += m;
        }
    free(buf);
    return fclose(f) == 0 && ok ? 0 : -1;
}

static double sum_xyz(const pc_raw *r)
{
    double s = 0;
    for (size_t i = 0; i < 3 * r->n; i++) s += r->xyz[i];
    return s;
}

/* read_whole: median seconds of runs reads with rd (*cpu: median CPU seconds); *n and *sum of
 * the last. */
static double read_whole(int (*rd)(const char *, pc_raw *, sd_err *), const char *path, int runs,
                         size_t *n, double *sum, double *cpu)
{
    double t[32], c[32];
    for (int k = 0; k < runs; k++) {
        pc_raw r = {0};
        sd_err e = {0};
        double t0 = now_s(), c0 = cpu_s();
        if (rd(path, &r, &e)) {
            fprintf(stderr, "e57_bench: %s\n", e.msg);
            exit(1);
        }
        t[k] = now_s() - t0;
        c[k] = cpu_s() - c0;
        *n = r.n;
        *sum = sum_xyz(&r);
        pc_raw_free(&r);
    }
    *cpu = tu_median(c, runs);
    return tu_median(t, runs);
}

/* stream_pass: median seconds of runs passes of the E57 point stream (xyz and colours). */
static double stream_pass(const char *path, int runs, uint64_t *n)
{
    double t[32];
    double *xyz = malloc(3 * 65536 * sizeof *xyz);
    uint8_t *rgba = malloc(4 * 65536);
    for (int k = 0; k < runs; k++) {
        pc_e57_stream *s;
        sd_err e = {0};
        double t0 = now_s();
        if (pc_e57_stream_open(path, &s, &e) != 1) {
            fprintf(stderr, "e57_bench: %s\n", e.msg);
            exit(1);
        }
        pc_e57_points o = {.xyz = xyz, .rgba = rgba};
        int64_t m;
        *n = 0;
        while ((m = pc_e57_stream_next(s, &o, 65536, &e)) > 0) *n += (uint64_t)m;
        if (m < 0) {
            fprintf(stderr, "e57_bench: %s\n", e.msg);
            exit(1);
        }
        pc_e57_stream_close(s);
        t[k] = now_s() - t0;
    }
    free(xyz);
    free(rgba);
    return tu_median(t, runs);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: e57_bench DIR [--points N] [--runs R] [--header]\n");
        return 2;
    }
    const char *dir = argv[1];
    uint64_t npts = 4000000;
    int runs = 3, header = 0;
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--points") && i + 1 < argc) npts = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--header")) header = 1;
    }
    if (runs < 1 || runs > 31) runs = 3;
    uint64_t per = npts / 2;
    e57w_field dbl[7] = {
        {"cartesianX", E57W_F64, 0, 0, 0, 0, 0},   {"cartesianY", E57W_F64, 0, 0, 0, 0, 0},
        {"cartesianZ", E57W_F64, 0, 0, 0, 0, 0},   {"colorRed", E57W_INT, 0, 255, 0, 0, 0},
        {"colorGreen", E57W_INT, 0, 255, 0, 0, 0}, {"colorBlue", E57W_INT, 0, 255, 0, 0, 0},
        {"intensity", E57W_INT, 0, 4095, 0, 0, 0},
    };
    e57w_field sci[7];
    memcpy(sci, dbl, sizeof sci);
    for (int k = 0; k < 3; k++) {
        sci[k].kind = E57W_SCALED;
        sci[k].min = 0, sci[k].max = (1 << 20) - 1, sci[k].scale = 0.001;
    }
    char p[3][4096];
    snprintf(p[0], sizeof p[0], "%s/bench_double.e57", dir);
    snprintf(p[1], sizeof p[1], "%s/bench_scaled.e57", dir);
    snprintf(p[2], sizeof p[2], "%s/bench.las", dir);
    for (int v = 0; v < 2; v++) {
        e57w_scan s[2];
        for (int k = 0; k < 2; k++)
            s[k] = (e57w_scan){.nfields = 7, .fields = v ? sci : dbl, .records = per, .pose = 1,
                               .quat = {1, 0, 0, 0}, .trans = {1000.0 * k, 0, 0}};
        double t0 = now_s();
        if (e57w_write(p[v], s, 2, NULL, gen_rec, NULL)) return 1;
        fprintf(stderr, "e57_bench: wrote %s in %.1f s\n", p[v], now_s() - t0);
    }
    if (write_las(p[2], per)) return 1;
    if (header) {
        printf("| file | points | size MB | whole-file read Mpts/s (per CPU s) | LAS reader, same "
               "points, Mpts/s (per CPU s) | E57 / LAS (CPU) | stream (xyz + rgb) Mpts/s | "
               "coordinate sums E57 / LAS |\n");
        printf("|---|---|---|---|---|---|---|---|\n");
    }
    size_t nl;
    double suml, cl;
    double tl = read_whole(pc_read_las, p[2], runs, &nl, &suml, &cl);
    for (int v = 0; v < 2; v++) {
        size_t n;
        double sum, ce;
        double te = read_whole(pc_read_e57, p[v], runs, &n, &sum, &ce);
        uint64_t ns;
        double ts = stream_pass(p[v], runs, &ns);
        FILE *f = fopen(p[v], "rb");
        fseek(f, 0, SEEK_END);
        long sz = ftell(f);
        fclose(f);
        if (n != nl || ns != n) {
            fprintf(stderr, "e57_bench: %zu points from E57, %zu from LAS, %llu streamed\n", n,
                    nl, (unsigned long long)ns);
            return 1;
        }
        printf("| %s | %zu | %.1f | %.1f (%.1f) | %.1f (%.1f) | %.2f (%.2f) | %.1f | %.6e / %.6e "
               "|\n",
               v ? "scaled integers (1 mm, 20-bit), RGB, intensity" : "doubles, RGB, intensity", n,
               sz / 1e6, n / te / 1e6, n / ce / 1e6, nl / tl / 1e6, nl / cl / 1e6, tl / te,
               cl / ce, ns / ts / 1e6, sum, suml);
    }
    return 0;
}
