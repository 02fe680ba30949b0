/* test_mpi.c — sort-last rendering over MPI (issue 17, part 2): `splatd --mpi` under
 * `mpirun --oversubscribe -np N` for N = 1..4 on loopback renders `points` frames identical,
 * byte for byte, to the single-process `splatd render` of the same camera (PNG, and EXR with its
 * float colour and depth); `splat` within 50 dB; `soft` and `olt` identical at np 1 and within
 * measured PSNR bounds at np 2-4 (the ranks' images "over" each other in their boxes' order);
 * each rank holds its spatial part (the parts add up to the cloud, each within 15 % of 1/N);
 * pipelines that cannot be composited are refused with a reason; and
 * a rank that dies makes rank 0 answer with an error instead of hanging; and the spatial
 * partition itself (pc_partition, pc_prepared_subset) is checked in-process: parts are boxes
 * made of whole octree cells, holding about 1/N of the points and of the footprint proxy, on
 * the bunny and on a synthetic cloud of very uneven splat sizes, against the earlier median
 * cuts (pc_partition_median). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "rndtest.h"
#include "common/daemonproc.h"
#include "common/exrtest.h"
#include "common/imgtest.h"
#include "common/testutil.h"
#include "boxorder.h"
#include "over.h"
#include "sd_half.h"
#include "partition.h"
#include "cloud.h"
#include "morton.h"
#include "mr_msg.h"
#include "proto.h"
#include "prep.h"
#include "testutil.h"

enum { BUNNY_POINTS = 40256 }; /* "element vertex 40256" in tests/data/bun000.ply */

typedef struct fx {
    char root[512], data[600], cache[600];
    pid_t mpirun;
    int port;
    char log[700];
} fx;

static int setup(void **state)
{
    fx *f = calloc(1, sizeof *f);
    if (!f || !tu_tmpdir(f->root, sizeof f->root)) return -1;
    snprintf(f->cache, sizeof f->cache, "%s/cache", f->root);
    if (tu_data_dir(f->root, "bun000.ply", "bunny.ply", f->data, sizeof f->data) != 0) return -1;
    signal(SIGPIPE, SIG_IGN);
    *state = f;
    return 0;
}

/* rank_pid: the process of MPI rank r among mpirun's children (OMPI_COMM_WORLD_RANK in its
 * environment), or 0. */
static pid_t rank_pid(pid_t mpirun, int r)
{
    char want[48];
    int wl = snprintf(want, sizeof want, "OMPI_COMM_WORLD_RANK=%d", r) + 1; /* with its NUL */
    DIR *d = opendir("/proc");
    if (!d) return 0;
    pid_t found = 0;
    struct dirent *e;
    while (!found && (e = readdir(d))) {
        pid_t pid = (pid_t)atoi(e->d_name);
        if (pid <= 0) continue;
        char path[64], buf[512];
        snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
        FILE *fs = fopen(path, "r");
        if (!fs) continue;
        int ppid = 0;
        size_t n = fread(buf, 1, sizeof buf - 1, fs);
        fclose(fs);
        buf[n] = 0;
        const char *rp = strrchr(buf, ')');
        if (!rp || sscanf(rp + 2, "%*c %d", &ppid) != 1 || ppid != mpirun) continue;
        snprintf(path, sizeof path, "/proc/%d/environ", (int)pid);
        /* /proc files have no size: read until EOF */
        static char env[65536];
        FILE *fe = fopen(path, "r");
        if (!fe) continue;
        size_t len = fread(env, 1, sizeof env - 1, fe);
        fclose(fe);
        env[len] = 0;
        for (size_t i = 0; i < len; i += strlen(env + i) + 1)
            if (len - i >= (size_t)wl && !memcmp(env + i, want, (size_t)wl)) found = pid;
    }
    closedir(d);
    return found;
}

/* stop: SIGTERM to rank 0, the daemon, which stops gracefully and then stops the workers, so
 * mpirun exits 0 (mpirun itself, given SIGTERM, kills every rank at once and exits 1).
 * Returns mpirun's exit status (-1: killed after 30 s or by a signal). */
static int stop(fx *f)
{
    if (f->mpirun <= 0) return -1;
    pid_t r0 = rank_pid(f->mpirun, 0);
    kill(r0 > 0 ? r0 : f->mpirun, SIGTERM);
    int st = 0;
    for (int i = 0; i < 3000; i++) {
        if (waitpid(f->mpirun, &st, WNOHANG) == f->mpirun) {
            f->mpirun = 0;
            return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
        }
        usleep(10000);
    }
    kill(f->mpirun, SIGKILL);
    waitpid(f->mpirun, &st, 0);
    f->mpirun = 0;
    return -1;
}

static int teardown(void **state)
{
    fx *f = *state;
    stop(f);
    tu_rm_rf(f->root);
    free(f);
    return 0;
}

/* mpi_bin: the splatd-mpi next to the splatd under test, when it was built (needs mpicc). */
static int have_mpi(char *why, size_t len)
{
    if (system("command -v mpirun >/dev/null 2>&1") != 0) {
        snprintf(why, len, "mpirun is not installed (Debian openmpi-bin)");
        return 0;
    }
    char p[700];
    snprintf(p, sizeof p, "%s", tu_splatd_bin());
    char *slash = strrchr(p, '/');
    snprintf(slash ? slash + 1 : p, sizeof p - (size_t)(slash ? slash + 1 - p : 0), "splatd-mpi");
    if (access(p, X_OK) != 0) {
        snprintf(why, len, "%s was not built (make builds it where mpicc is)", p);
        return 0;
    }
    return 1;
}

/* start: mpirun -np n splatd --mpi on loopback; waits up to 60 s for the port. With
 * recovery, mpirun keeps the job when a rank dies (--enable-recovery) and rank 0 waits
 * SPLATD_MPI_TIMEOUT = 3 s for the others. */
static void start_job(fx *f, int n, int recovery)
{
    char np[16], portfile[700];
    snprintf(np, sizeof np, "%d", n);
    snprintf(portfile, sizeof portfile, "%s/port%d", f->root, n);
    snprintf(f->log, sizeof f->log, "%s/mpi%d.log", f->root, n);
    unlink(portfile);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        int fd = open(f->log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, 1);
        dup2(fd, 2);
        /* Under ASan, LeakSanitizer stays off in the ranks: Open MPI's components are
         * dlclose'd by MPI_Finalize and their process-lifetime allocations are reported from
         * "<unknown module>" frames that no suppression can name (memory errors are still
         * caught). */
        const char *asan = getenv("ASAN_OPTIONS");
        if (asan) {
            char opts[1024];
            snprintf(opts, sizeof opts, "%s:detect_leaks=0", asan);
            setenv("ASAN_OPTIONS", opts, 1);
        }
        const char *argv[24];
        int k = 0;
        argv[k++] = "mpirun";
        argv[k++] = "--oversubscribe";
        if (geteuid() == 0) argv[k++] = "--allow-run-as-root";
        if (recovery) {
            setenv("SPLATD_MPI_TIMEOUT", "3", 1);
            argv[k++] = "--enable-recovery";
            argv[k++] = "-x";
            argv[k++] = "SPLATD_MPI_TIMEOUT";
        }
        argv[k++] = "-np";
        argv[k++] = np;
        argv[k++] = tu_splatd_bin();
        argv[k++] = "--mpi";
        argv[k++] = "--listen";
        argv[k++] = "127.0.0.1:0";
        argv[k++] = "--data";
        argv[k++] = f->data;
        argv[k++] = "--cache";
        argv[k++] = f->cache;
        argv[k++] = "--port-file";
        argv[k++] = portfile;
        argv[k] = NULL;
        execvp("mpirun", (char *const *)argv);
        _exit(127);
    }
    f->mpirun = pid;
    for (int i = 0; i < 6000; i++) {
        size_t len = 0;
        uint8_t *b = tu_read_file(portfile, &len);
        if (b && len > 0) {
            char t[16] = {0};
            memcpy(t, b, len < 15 ? len : 15);
            f->port = atoi(t);
            free(b);
            if (f->port > 0) return;
        }
        free(b);
        int st;
        if (waitpid(pid, &st, WNOHANG) == pid) {
            f->mpirun = 0;
            char out[8192];
            tu_run(out, sizeof out, "cat '%s'", f->log);
            fail_msg("mpirun -np %d exited at start-up: %s", n, out);
        }
        usleep(10000);
    }
    fail_msg("mpirun -np %d did not start listening in 60 s", n);
}

static void start(fx *f, int n)
{
    start_job(f, n, 0);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec / 1e9;
}

/* A rank killed (SIGKILL) under mpirun --enable-recovery: rank 0 answers the next frame with
 * an error naming the timeout after about 3 s (SPLATD_MPI_TIMEOUT), and every later one at
 * once; it keeps serving its connections, and a SIGTERM then ends the whole job. */
static void test_rank_dies(void **state)
{
    fx *f = *state;
    char why[800], out[16384];
    if (!have_mpi(why, sizeof why)) TU_SKIP("%s", why);
    start_job(f, 3, 1);
    int rc = tu_run(out, sizeof out, "'%s' --port %d -q render bunny --set pipeline=points "
                    "--size 160x120 -o '%s/ok.png' 2>&1", tu_splat_bin(), f->port, f->root);
    if (rc) fail_msg("render before: %s", out);
    pid_t r1 = rank_pid(f->mpirun, 1);
    assert_true(r1 > 0);
    kill(r1, SIGKILL);
    usleep(200000);
    for (int i = 0; i < 2; i++) {
        double t0 = now_s();
        rc = tu_run(out, sizeof out, "'%s' --port %d --timeout 30 render bunny --set "
                    "pipeline=%s --size 160x120 -o '%s/x.png' 2>&1", tu_splat_bin(), f->port,
                    i ? "splat" : "points", f->root);
        double dt = now_s() - t0;
        assert_int_equal(rc, 1);
        if (!strstr(out, "did not answer within 3 s")) fail_msg("frame %d: %s", i, out);
        /* the first waits out the timeout, the next is refused at once */
        if (i == 0 && (dt < 2.5 || dt > 15)) fail_msg("first error after %.1f s", dt);
        if (i == 1 && dt > 2.0) fail_msg("second error after %.1f s", dt);
    }
    pid_t r0 = rank_pid(f->mpirun, 0);
    assert_true(r0 > 0);
    kill(r0, SIGTERM);
    int st;
    for (int t = 0; t < 3000; t++) {
        if (waitpid(f->mpirun, &st, WNOHANG) == f->mpirun) {
            f->mpirun = 0;
            break;
        }
        usleep(10000);
    }
    /* With a rank gone, MPI_Finalize on rank 0 would wait for it forever: the job ending is
     * rank 0's MPI_Abort (mpirun --enable-recovery exits 0 either way, and Open MPI's own
     * "MPI_ABORT was invoked" line is lost from the forwarded output about half the time on a
     * loaded machine, so it is not asserted). */
    if (f->mpirun) fail_msg("the job did not end within 30 s of SIGTERM to rank 0 (rank 0 "
                            "waits in MPI_Finalize for the dead rank instead of aborting)");
    (void)st;
}

/* same_file: 1 when both files hold the same bytes (and at least one). */
static int same_file(const char *a, const char *b)
{
    size_t la, lb;
    uint8_t *da = tu_read_file(a, &la), *db = tu_read_file(b, &lb);
    int same = da && db && la == lb && la > 0 && !memcmp(da, db, la);
    free(da);
    free(db);
    return same;
}

/* exr_rgba8: the EXR frame at path's colour in 8 bits (each half clamped to [0, 1], times 255,
 * rounded), for the PSNR. */
static void exr_rgba8(const char *path, uint32_t *w, uint32_t *h, uint8_t **rgba)
{
    int ww, hh;
    uint16_t *col;
    float *z;
    if (tu_exr_read(path, &ww, &hh, &col, &z) != 0) fail_msg("%s: not a readable EXR", path);
    *rgba = malloc((size_t)ww * hh * 4);
    assert_non_null(*rgba);
    for (size_t i = 0; i < (size_t)ww * hh * 4; i++) {
        float c = tu_half(col[i]);
        (*rgba)[i] = (uint8_t)lrintf((c > 1 ? 1 : c > 0 ? c : 0) * 255);
    }
    *w = (uint32_t)ww, *h = (uint32_t)hh;
    free(col);
    free(z);
}

/* The frames compared: points at the default framing, a close-up from another side with
 * 3-pixel points and a background, and an EXR frame (float colour with coverage, and eye
 * depth), which must be byte-identical; splat (EWA, ewa=split on llvmpipe) at the default
 * framing and a close-up, which must be within 50 dB PSNR (the bound: the sums are
 * added in another order when the GL adds floats; on llvmpipe they are identical too). */
enum { EXACT, SPLAT_DB, OVER_DB };
static const struct {
    const char *name, *args;
    int kind;
    double db;                 /* OVER_DB: the bound for np 2-4 (see below) */
} views[] = {
    {"default.png", "--size 320x240 --set pipeline=points", EXACT, 0},
    {"close.png", "--size 300x200 --eye 0.05,0.2,0.12 --target -0.02,0.11,0.0 --up 0,1,0 "
                  "--fov 40 --set pipeline=points --set point_size=3 "
                  "--set background=0.2,0.3,0.4", EXACT, 0},
    {"frame.exr", "--size 160x120 --set pipeline=points --set color=normal", EXACT, 0},
    {"splat.png", "--size 320x240 --set pipeline=splat", SPLAT_DB, 0},
    {"splat-close.png", "--size 300x200 --eye 0.05,0.2,0.12 --target -0.02,0.11,0.0 "
                        "--up 0,1,0 --fov 40 --set pipeline=splat --set color=normal", SPLAT_DB,
     0},
    /* soft and olt: the ranks' images go "over" each other front to back by their boxes
     * (mpi_render.c, over.h): np 1 is the single process exactly; np 2-4 differ where splats
     * and discs reach across a cut (see README "Farms and sort-last"). Colour by normal, so
     * that the order of differently coloured discs shows. Measured on llvmpipe (np 2 / 3 / 4):
     * soft.png 44.33 / 38.22 / 39.75 dB, soft-close.png 46.88 / 44.16 / 43.98, olt.png
     * 39.31 / 32.29 / 32.42, soft.exr (float colour composited in float, compared in 8 bits)
     * 39.60 / 34.16 / 36.64; with the order reversed (back to front, wrong) 28.70 / 24.94 /
     * 24.90, 36.00 / 32.89 / 34.57, 23.26 / 19.72 / 19.64 and 24.67 / 22.78 / 22.24. Each
     * bound lies about 3 dB under the lowest right figure and above every reversed one, so
     * the test fails when the order is wrong (checked: reversed, it fails at np 2). With the
     * octree-cell partition of the `mpipart` branch merged in (a trial merge, 04:13 UTC) the
     * same frames measured 45.57 / 38.28 / 40.51, 50.10 / 44.89 / 43.20, 36.35 / 33.24 / 31.02
     * and 41.76 / 37.40 / 35.95 dB, reversed at most 27.73, 34.99, 23.15 and 24.02: the
     * bounds hold for both partitions. */
    {"soft.png", "--size 320x240 --set pipeline=soft --set color=normal", OVER_DB, 35.0},
    {"soft-close.png", "--size 300x200 --eye 0.05,0.2,0.12 --target -0.02,0.11,0.0 "
                       "--up 0,1,0 --fov 40 --set pipeline=soft --set color=normal "
                       "--set lambda=0.8 --set background=0.2,0.3,0.4", OVER_DB, 40.0},
    {"olt.png", "--size 320x240 --set pipeline=olt --set color=normal", OVER_DB, 29.0},
    {"soft.exr", "--size 160x120 --set pipeline=soft --set color=normal", OVER_DB, 31.0},
};
enum { NVIEWS = sizeof views / sizeof views[0] };

/* For N = 1..4 ranks: every view identical to the single-process render, the parts of the
 * cloud one per rank adding up to it (each within 15 % of 1/N), and a clean stop. */
static void test_points_identical_1_to_4(void **state)
{
    fx *f = *state;
    char why[800], out[65536];
    if (!have_mpi(why, sizeof why)) TU_SKIP("%s", why);
    /* the single-process references (the cache is made here, once), points drawn in the exact
     * form the ranks use (depth ties broken by float depth, not by the whole cloud's point
     * index, which a rank does not have) */
    for (int v = 0; v < NVIEWS; v++) {
        int rc = tu_run(out, sizeof out, "'%s' render '%s/bunny.ply' -o '%s/ref-%s' %s "
                        "--points-raster exact --cache '%s' 2>&1", tu_splatd_bin(), f->data,
                        f->root, views[v].name,
                        views[v].args, f->cache);
        if (rc) fail_msg("splatd render %s: %s", views[v].name, out);
    }
    for (int n = 1; n <= 4; n++) {
        start(f, n);
        for (int v = 0; v < NVIEWS; v++) {
            char got[800], ref[800];
            snprintf(got, sizeof got, "%s/np%d-%s", f->root, n, views[v].name);
            snprintf(ref, sizeof ref, "%s/ref-%s", f->root, views[v].name);
            int rc = tu_run(out, sizeof out, "'%s' --port %d -q render bunny -o '%s' %s 2>&1",
                            tu_splat_bin(), f->port, got, views[v].args);
            if (rc) fail_msg("np %d, %s: %s", n, views[v].name, out);
            if (views[v].kind == EXACT || (views[v].kind == OVER_DB && n == 1)) {
                if (!same_file(got, ref))
                    fail_msg("np %d: %s differs from splatd render's", n, views[v].name);
                continue;
            }
            uint32_t w1, h1, w2, h2;
            uint8_t *a = NULL, *b = NULL;
            if (strstr(views[v].name, ".exr")) {
                exr_rgba8(got, &w1, &h1, &a);
                exr_rgba8(ref, &w2, &h2, &b);
            } else {
                assert_int_equal(tu_png_read(got, 0, &w1, &h1, &a), 0);
                assert_int_equal(tu_png_read(ref, 0, &w2, &h2, &b), 0);
            }
            assert_true(w1 == w2 && h1 == h2);
            size_t ncov = 0;
            double db = tu_psnr_covered(a, b, (size_t)w1 * h1, &ncov);
            print_message("np %d %s: PSNR %.2f dB over %zu covered pixels%s\n", n,
                          views[v].name, db, ncov, same_file(got, ref) ? " (identical)" : "");
            double bound = views[v].kind == SPLAT_DB ? 50.0 : views[v].db;
            if (!(db >= bound) || ncov < 1000)
                fail_msg("np %d: %s: %.2f dB over %zu pixels", n, views[v].name, db, ncov);
            free(a);
            free(b);
        }
        /* kawata cannot be composited from the ranks' parts: refused, naming why */
        int rc = tu_run(out, sizeof out, "'%s' --port %d render bunny -o '%s/s.png' --size "
                        "64x48 --set pipeline=kawata 2>&1", tu_splat_bin(), f->port, f->root);
        assert_int_equal(rc, 1);
        if (!strstr(out, "pipeline kawata is not available with splatd --mpi"))
            fail_msg("np %d: kawata: %s", n, out);
        if (n == 2) { /* soft's sphere models are not composited: refused, naming why */
            rc = tu_run(out, sizeof out, "'%s' --port %d render bunny -o '%s/s.png' --size "
                        "64x48 --set pipeline=soft --set model=base 2>&1", tu_splat_bin(),
                        f->port, f->root);
            assert_int_equal(rc, 1);
            if (!strstr(out, "soft model=base is not available with splatd --mpi"))
                fail_msg("np %d: soft model=base: %s", n, out);
        }
        int src = stop(f);
        if (src != 0) {
            tu_run(out, sizeof out, "tail -c 1200 '%s'", f->log);
            fail_msg("np %d: mpirun exited %d: %s", n, src, out);
        }
        /* every rank logged its part: they add up to the cloud, each near 1/N */
        char *log = (char *)tu_read_file(f->log, &(size_t){0});
        assert_non_null(log);
        long sum = 0;
        for (int r = 0; r < n; r++) {
            char key[80];
            snprintf(key, sizeof key, "rank %d of %d: bunny.ply: ", r, n);
            const char *at = strstr(log, key);
            if (!at) fail_msg("np %d: no line for rank %d in %s", n, r, log);
            long part = atol(at + strlen(key));
            double share = (double)BUNNY_POINTS / n;
            /* partition.h balances points and footprint: within 15 % of n/N on the bunny
             * (test_partition_cells_bunny) */
            if (fabs(part - share) > 0.15 * share)
                fail_msg("np %d rank %d: %ld points", n, r, part);
            sum += part;
            snprintf(key, sizeof key, "rank %d of %d: %d frames", r, n, NVIEWS);
            if (!strstr(log, key)) fail_msg("np %d: rank %d did not stop cleanly: %s", n, r, log);
        }
        assert_int_equal(sum, BUNNY_POINTS);
        free(log);
    }
}

/* count_prefix: how many of the sorted codes[0, n) share code's top 3 level bits. */
static uint64_t count_prefix(const uint64_t *codes, uint64_t n, uint64_t code, int level)
{
    int shift = 3 * (PREP_MORTON_BITS - level);
    uint64_t lo_code = code >> shift << shift, hi_code = lo_code + ((uint64_t)1 << shift);
    uint64_t a = 0, b = n; /* first >= lo_code */
    while (a < b) {
        uint64_t m = a + (b - a) / 2;
        if (codes[m] < lo_code) a = m + 1;
        else b = m;
    }
    uint64_t c = a, d = n; /* first >= hi_code */
    while (c < d) {
        uint64_t m = c + (d - c) / 2;
        if (codes[m] < hi_code) c = m + 1;
        else d = m;
    }
    return c - a;
}

/* check_cells: part and box of pc_partition(pos, n, np) are what partition.h promises: every
 * point in exactly one box, its part's; the boxes disjoint and tiling the Morton cube (volumes
 * add up to the cube's); and every octree unit (derived here from the rule: the first level
 * >= PC_PART_MIN_LEVEL whose cell holds at most n / (64 np) points, else the finest) wholly
 * inside the box of its points' part, so the cuts lie on the cell grid. */
static void check_cells(const float *pos, uint64_t n, int np, const uint16_t *part,
                        const pc_part_box *box)
{
    prep_morton_frame f;
    prep_morton_frame_of(pos, n, &f);
    uint64_t *codes = malloc(n * sizeof *codes);
    uint32_t *perm = malloc(n * sizeof *perm);
    assert_true(codes && perm);
    sd_err err = {0};
    assert_int_equal(prep_morton_sort(pos, n, &f, codes, perm, &err), 0);
    uint64_t vol = 0;
    for (int p = 0; p < np; p++) {
        uint64_t v = 1;
        for (int a = 0; a < 3; a++) {
            assert_true(box[p].cell_lo[a] <= box[p].cell_hi[a]);
            assert_true(box[p].cell_hi[a] <= 1u << PREP_MORTON_BITS);
            v *= box[p].cell_hi[a] - box[p].cell_lo[a];
        }
        vol += v;
        for (int q = 0; q < p; q++) { /* disjoint: empty intersection on some axis */
            int apart = 0;
            for (int a = 0; a < 3; a++)
                apart |= box[p].cell_hi[a] <= box[q].cell_lo[a] ||
                         box[q].cell_hi[a] <= box[p].cell_lo[a];
            if (!apart) fail_msg("np %d: boxes %d and %d overlap", np, q, p);
        }
    }
    assert_true(vol == (uint64_t)1 << (3 * PREP_MORTON_BITS));
    uint64_t cap = n / ((uint64_t)PC_PART_CELL_DIV * (uint64_t)np);
    if (cap == 0) cap = 1;
    for (uint64_t j = 0; j < n; j++) {
        uint32_t i = perm[j], c[3];
        assert_true(part[i] < np);
        prep_morton_decode(codes[j], &c[0], &c[1], &c[2]);
        int in = 0;
        for (int p = 0; p < np; p++) {
            int inside = 1;
            for (int a = 0; a < 3; a++)
                inside &= box[p].cell_lo[a] <= c[a] && c[a] < box[p].cell_hi[a];
            in += inside;
            if (inside && p != part[i]) fail_msg("np %d: point %u of part %d in box %d", np, i,
                                                 part[i], p);
        }
        if (in != 1) fail_msg("np %d: point %u in %d boxes", np, i, in);
        int level = PC_PART_MIN_LEVEL;
        while (level < PREP_MORTON_BITS && count_prefix(codes, n, codes[j], level) > cap) level++;
        int shift = 3 * (PREP_MORTON_BITS - level);
        uint32_t lo[3], size = (1u << PREP_MORTON_BITS) >> level;
        prep_morton_decode(codes[j] >> shift << shift, &lo[0], &lo[1], &lo[2]);
        const pc_part_box *b = &box[part[i]];
        for (int a = 0; a < 3; a++) {
            if (lo[a] < b->cell_lo[a] || lo[a] + size > b->cell_hi[a])
                fail_msg("np %d: the level-%d cell of point %u crosses part %d's box on axis "
                         "%d", np, level, i, part[i], a);
            /* the box in local coordinates holds the point (one finest cell of slack for
             * the rounding of the cell index) */
            double slack = f.side / (1u << PREP_MORTON_BITS);
            assert_true(pos[3 * i + a] >= b->lo[a] - slack && pos[3 * i + a] <= b->hi[a] + slack);
        }
    }
    free(perm);
    free(codes);
}

/* The octree-cell partition on the bunny (prepared here: its radii, and its points in Morton
 * order, so pc_partition skips its sort; the uneven cloud below takes the sort): boxes of whole cells (check_cells)
 * for N = 1..4 and 7; every part within 15 % of n/N points; the footprint proxy (sum of pi r^2)
 * max/mean at most 1.20; and the larger of the two imbalances below the median cuts' (which
 * balance points exactly but leave the footprint 7-45 % off here). Measured (deterministic):
 * points max/mean 1.045, 1.035, 1.078, 1.050 and footprint 1.027, 1.040, 1.111, 1.161 for
 * N = 2, 3, 4, 7, against the median cuts' footprint 1.072, 1.186, 1.224, 1.454. */
static void test_partition_cells_bunny(void **state)
{
    (void)state;
    pc_prepared pc;
    tu_prep_data("bun000.ply", &pc);
    sd_err err = {0};
    assert_int_equal(pc.n, BUNNY_POINTS);
    uint16_t *part = malloc(pc.n * sizeof *part);
    assert_non_null(part);
    static const int counts[] = {1, 2, 3, 4, 7};
    for (size_t t = 0; t < sizeof counts / sizeof counts[0]; t++) {
        int np = counts[t];
        pc_part_box box[7];
        double pts[7], fp[7], ip, ifp, op, ofp;
        assert_int_equal(pc_partition(pc.pos, pc.radius, pc.n, np, part, box, &err), 0);
        check_cells(pc.pos, pc.n, np, part, box);
        pc_partition_balance(pc.radius, pc.n, part, np, pts, fp, &ip, &ifp);
        for (int p = 0; p < np; p++)
            if (fabs(pts[p] * np - 1) > 0.15)
                fail_msg("N %d: part %d holds %.1f %% of the points", np, p, 100 * pts[p]);
        uint16_t *old = malloc(pc.n * sizeof *old);
        assert_non_null(old);
        assert_int_equal(pc_partition_median(pc.pos, pc.n, np, old, &err), 0);
        double opts[7], ofpv[7];
        pc_partition_balance(pc.radius, pc.n, old, np, opts, ofpv, &op, &ofp);
        free(old);
        print_message("bunny N %d: points max/mean %.3f, footprint %.3f (median cuts: %.3f, "
                      "%.3f)\n", np, ip, ifp, op, ofp);
        assert_true(ifp <= 1.20);
        if (np == 1) {
            assert_true(ip == 1.0 && ifp == 1.0);
            continue;
        }
        assert_true(fmax(ip, ifp) < fmax(op, ofp));
        assert_true(op <= 1.0 + (double)np / (double)pc.n); /* split to a point */
    }
    free(part);
    pc_prepared_free(&pc);
}

/* A synthetic cloud of very uneven splats: 20000 points uniform in [0, 2.1) x [0, 2) x [0, 2)
 * (x the longest axis), radius 0.4 where x >= 1.6 (about 24 % of the points) and 0.05 elsewhere:
 * 64 times the area, so that slab holds about 95 % of the footprint. The median cuts cut x first
 * and leave one part most of the footprint; the octree-cell kd tree cuts y and z, balancing
 * both. Asserted: every part within 10 % of n/N points and the footprint max/mean at most 1.05
 * for N = 1..4 and 7, against at least 1.45 for the median cuts (N >= 2, and 1.4 times the new
 * one's); boxes of whole cells. Measured (deterministic): footprint 1.002, 1.007, 1.006, 1.015
 * for N = 2, 3, 4, 7 (points 1.015-1.032) against 1.937, 1.494, 1.966, 1.780.
 * Without radii only points are balanced (within 5 %). And a degenerate cloud (every point at
 * one position: one unit) goes whole to one part, the others empty, the boxes still tiling. */
static void test_partition_cells_uneven(void **state)
{
    (void)state;
    enum { N = 20000 };
    float *pos = malloc(3 * N * sizeof *pos), *radius = malloc(N * sizeof *radius);
    uint16_t *part = malloc(N * sizeof *part);
    assert_true(pos && radius && part);
    uint64_t x = 0x9e3779b97f4a7c15ull; /* xorshift64: a fixed sequence */
    for (int i = 0; i < N; i++) {
        for (int a = 0; a < 3; a++) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            pos[3 * i + a] = (float)((x >> 11) * (1.0 / 9007199254740992.0)) * (a ? 2.0f : 2.1f);
        }
        radius[i] = pos[3 * i] >= 1.6f ? 0.4f : 0.05f;
    }
    sd_err err = {0};
    static const int counts[] = {1, 2, 3, 4, 7};
    for (size_t t = 0; t < sizeof counts / sizeof counts[0]; t++) {
        int np = counts[t];
        pc_part_box box[7];
        double pts[7], fp[7], ip, ifp, op, ofp;
        assert_int_equal(pc_partition(pos, radius, N, np, part, box, &err), 0);
        check_cells(pos, N, np, part, box);
        pc_partition_balance(radius, N, part, np, pts, fp, &ip, &ifp);
        for (int p = 0; p < np; p++)
            if (fabs(pts[p] * np - 1) > 0.10)
                fail_msg("N %d: part %d holds %.1f %% of the points", np, p, 100 * pts[p]);
        assert_int_equal(pc_partition_median(pos, N, np, part, &err), 0);
        pc_partition_balance(radius, N, part, np, pts, fp, &op, &ofp);
        print_message("uneven N %d: points max/mean %.3f, footprint %.3f (median cuts: %.3f, "
                      "%.3f)\n", np, ip, ifp, op, ofp);
        assert_true(ifp <= 1.05);
        if (np > 1) assert_true(ofp >= 1.45 && ofp / ifp >= 1.4);
        /* radii not given: points only */
        assert_int_equal(pc_partition(pos, NULL, N, np, part, box, &err), 0);
        check_cells(pos, N, np, part, box);
        pc_partition_balance(NULL, N, part, np, pts, fp, &ip, &ifp);
        assert_true(ip <= 1.05 && ifp == ip);
    }
    /* degenerate: one position, one unit: every part but one is empty; at 1000 parts the
     * regions around the unit are cut down to its cell itself, and the parts left over get
     * empty boxes */
    for (int i = 0; i < 3 * 100; i++) pos[i] = 0.25f;
    for (int np = 2; np <= 1000; np += np < 16 ? 1 : 984) { /* 2..16, 1000 */
        static pc_part_box box[1000];
        assert_int_equal(pc_partition(pos, radius, 100, np, part, box, &err), 0);
        check_cells(pos, 100, np, part, box);
        for (int i = 1; i < 100; i++) assert_int_equal(part[i], part[0]);
    }
    pc_part_box box[3];
    assert_int_equal(pc_partition(pos, radius, 0, 3, part, box, &err), 0); /* no points */
    for (int p = 0; p < 3; p++) assert_true(box[p].cell_lo[0] <= box[p].cell_hi[0]);
    free(part);
    free(radius);
    free(pos);
}

/* pc_partition_median (the earlier partition) on a known layout: a long box split into 2, 3
 * and 4 slabs by recursive median cuts along the longest axis; pc_prepared_subset keeps the
 * whole cloud's summary. */
static void test_partition(void **state)
{
    (void)state;
    enum { N = 1200 };
    float *pos = malloc(3 * N * sizeof *pos);
    uint16_t part[N];
    assert_non_null(pos);
    /* x in [0, 12) (the longest axis), y in [0, 2), z in [0, 1): x = i / 100 */
    for (int i = 0; i < N; i++) {
        pos[3 * i] = i / 100.0f;
        pos[3 * i + 1] = (i % 7) / 3.5f;
        pos[3 * i + 2] = (i % 5) / 5.0f;
    }
    sd_err err = {0};
    for (int k = 1; k <= 4; k++) {
        assert_int_equal(pc_partition_median(pos, N, k, part, &err), 0);
        int count[4] = {0};
        for (int i = 0; i < N; i++) {
            assert_true(part[i] < k);
            count[part[i]]++;
        }
        for (int p = 0; p < k; p++) assert_int_equal(count[p], N / k);
        /* cut along x (the longest axis and, for 3 and 4 parts, still the longest of each
         * half): part p holds the p-th slab of x */
        for (int i = 0; i < N; i++) assert_int_equal(part[i], i / (N / k));
    }
    assert_int_equal(pc_partition_median(pos, N, 0, part, &err), SD_EINVAL);
    assert_int_equal(pc_partition(pos, NULL, N, 0, part, NULL, &err), SD_EINVAL);
    assert_int_equal(pc_partition(pos, NULL, N, PC_PART_MAX + 1, part, NULL, &err), SD_EINVAL);

    /* a cube of 8 points in 2 parts: the longest axis is a tie, x (the first) is cut */
    float cube[24];
    for (int i = 0; i < 8; i++) {
        cube[3 * i] = (float)(i & 1);
        cube[3 * i + 1] = (float)(i >> 1 & 1);
        cube[3 * i + 2] = (float)(i >> 2 & 1);
    }
    uint16_t cp[8];
    assert_int_equal(pc_partition_median(cube, 8, 2, cp, &err), 0);
    for (int i = 0; i < 8; i++) assert_int_equal(cp[i], i & 1);

    /* subset: the points of part 1 of 3, batches re-cut, summary kept */
    pc_prepared src = {.n = N, .attrs = PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F | PC_ATTR_RGB,
                       .k = 24, .nbatches = 1};
    assert_int_equal(pc_prepared_alloc(&src, &err), 0);
    memcpy(src.pos, pos, 3 * N * sizeof *pos);
    for (int i = 0; i < N; i++) {
        src.radius[i] = (float)i;
        src.rgba[4 * i] = (uint8_t)i;
        src.F[i] = i / (float)N;
    }
    pc_prepared_make_batches(&src, N);
    src.bmin[0] = -5;
    src.bmax[0] = 17;
    src.offset[1] = 1e6;
    src.sigma = 0.25f;
    assert_int_equal(pc_partition_median(pos, N, 3, part, &err), 0);
    pc_prepared sub;
    assert_int_equal(pc_prepared_subset(&src, part, 1, &sub, &err), 0);
    assert_int_equal(sub.n, N / 3);
    assert_int_equal(sub.nbatches, 1);
    assert_int_equal(sub.batches[0].count, N / 3);
    assert_true(sub.batches[0].bmin[0] == 4.0f && sub.batches[0].bmax[0] == 7.99f);
    for (uint64_t j = 0; j < sub.n; j++) {
        uint64_t i = N / 3 + j;
        assert_true(sub.pos[3 * j] == pos[3 * i]);
        assert_true(sub.radius[j] == (float)i);
        assert_int_equal(sub.rgba[4 * j], (uint8_t)i);
        assert_true(sub.F[j] == i / (float)N);
    }
    assert_true(sub.bmin[0] == -5 && sub.bmax[0] == 17 && sub.offset[1] == 1e6);
    assert_true(sub.sigma == 0.25f && sub.k == 24);
    pc_prepared_free(&sub);
    pc_prepared_free(&src);
    free(pos);
}

/* bo_order on known layouts: parts cut like pc_partition's (a kd split) ordered by the eye's
 * side of each cut, recursively; boxes no plane separates fall back to distances and say so. */
static void test_box_order(void **state)
{
    (void)state;
    int order[8], tmp[8];
    /* 4 slabs along x: [0,1] [1,2] [2,3] [3,4] (touching at the cuts, as points on a cut) */
    bo_box slab[4];
    for (int p = 0; p < 4; p++)
        slab[p] = (bo_box){{(float)p, 0, 0}, {(float)p + 1, 1, 1}};
    assert_int_equal(bo_order(slab, 4, (double[3]){-5, 0.5, 0.5}, order, tmp), 1);
    for (int i = 0; i < 4; i++) assert_int_equal(order[i], i);
    assert_int_equal(bo_order(slab, 4, (double[3]){9, 0.5, 0.5}, order, tmp), 1);
    for (int i = 0; i < 4; i++) assert_int_equal(order[i], 3 - i);
    /* eye inside slab 2: 2 first, then its neighbours before the far ones */
    assert_int_equal(bo_order(slab, 4, (double[3]){2.5, 0.5, 0.5}, order, tmp), 1);
    assert_int_equal(order[0], 2);
    assert_true((order[1] == 1 && order[2] == 0 && order[3] == 3) ||
                (order[1] == 3 && order[2] == 1 && order[3] == 0) ||
                (order[1] == 1 && order[2] == 3 && order[3] == 0));
    /* a kd split: x at 2, then y at 1 on the left and y at 3 on the right; eye at the right
     * top, looking across: right side first, its upper part first; on the left the lower
     * part is behind the upper one only if the eye is above the cut (y = 1): it is */
    bo_box kd[4] = {{{0, 0, 0}, {2, 1, 1}}, {{0, 1, 0}, {2, 4, 1}},
                    {{2, 0, 0}, {4, 3, 1}}, {{2, 3, 0}, {4, 4, 1}}};
    assert_int_equal(bo_order(kd, 4, (double[3]){6, 3.5, 0.5}, order, tmp), 1);
    assert_int_equal(order[0], 3);
    assert_int_equal(order[1], 2);
    assert_int_equal(order[2], 1);
    assert_int_equal(order[3], 0);
    /* an empty part (no point) comes last */
    bo_box e3[3] = {{{0, 0, 0}, {1, 1, 1}}, {{INFINITY, INFINITY, INFINITY},
                    {-INFINITY, -INFINITY, -INFINITY}}, {{1, 0, 0}, {2, 1, 1}}};
    assert_int_equal(bo_order(e3, 3, (double[3]){5, 0.5, 0.5}, order, tmp), 1);
    assert_int_equal(order[0], 2);
    assert_int_equal(order[1], 0);
    assert_int_equal(order[2], 1);
    /* a pinwheel of 4 boxes around a centre square (no axis plane separates them) and the
     * centre: the fallback, nearest first, reported */
    bo_box pin[5] = {{{0, 0, 0}, {2, 1, 1}}, {{2, 0, 0}, {3, 2, 1}}, {{1, 2, 0}, {3, 3, 1}},
                     {{0, 1, 0}, {1, 3, 1}}, {{1, 1, 0}, {2, 2, 1}}};
    assert_int_equal(bo_order(pin, 5, (double[3]){1.5, 1.5, 5}, order, tmp), 0);
    assert_int_equal(order[0], 4);
    /* bo_boxes: the points' boxes of a grid cut into 3 parts, the middle one in y halves
     * numbered 2 and 0, the left slab 1; points on a cut go to either side */
    enum { G = 12 };
    float pos[3 * G * G * G];
    uint16_t part[G * G * G];
    for (int i = 0; i < G * G * G; i++) {
        int x = i % G, y = i / G % G;
        pos[3 * i] = (float)x, pos[3 * i + 1] = (float)y, pos[3 * i + 2] = (float)(i / G / G);
        part[i] = x <= 5 ? 1 : y <= 5 ? 2 : 0;
    }
    bo_box pb[3];
    bo_boxes(pos, G * G * G, part, 3, pb);
    assert_true(pb[1].lo[0] == 0 && pb[1].hi[0] == 5 && pb[1].hi[1] == 11);
    assert_true(pb[2].lo[0] == 6 && pb[2].hi[1] == 5 && pb[0].lo[1] == 6 && pb[0].hi[2] == 11);
    assert_int_equal(bo_order(pb, 3, (double[3]){20, 2, 5}, order, tmp), 1);
    assert_int_equal(order[0], 2);
    assert_int_equal(order[1], 0);
    assert_int_equal(order[2], 1);
}

/* ov_op, the backgrounds and the half conversions against values worked by hand. */
static void test_over(void **state)
{
    (void)state;
    /* 8-bit: front (128, 0, 0, 128) over (0, 255, 0, 255): G = 0 + 127 x 255 / 255 = 127, A =
     * 128 + 127 = 255; an opaque front wins whole; an empty front gives the back */
    uint8_t lo[12] = {128, 0, 0, 128, 10, 20, 30, 255, 0, 0, 0, 0};
    uint8_t hi[12] = {0, 255, 0, 255, 1, 2, 3, 255, 40, 50, 60, 100};
    uint8_t out[12];
    ov_op(lo, hi, out, 3, OV_PX8, NULL);
    const uint8_t want[12] = {128, 127, 0, 255, 10, 20, 30, 255, 40, 50, 60, 100};
    assert_memory_equal(out, want, 12);
    /* the background under a pixel with coverage 128/255: C + (1 - A) bg, alpha 1 */
    uint8_t px[8] = {128, 0, 0, 128, 0, 0, 0, 0};
    ov_background8(px, 2, (float[3]){0, 1, 0.2f});
    const uint8_t wpx[8] = {128, 127, 25, 255, 0, 255, 51, 255};
    assert_memory_equal(px, wpx, 8);
    /* float: (0.5, 0, 0, 0.5) over (0, 1, 0, 1) = (0.5, 0.5, 0, 1); depth the nearer */
    uint8_t fl[OV_PXF], fh[OV_PXF], fo[OV_PXF];
    float zl = 2.0f, zh = 1.5f;
    uint16_t cl[4] = {sd_float_to_half(0.5f), 0, 0, sd_float_to_half(0.5f)};
    uint16_t ch[4] = {0, sd_float_to_half(1.0f), 0, sd_float_to_half(1.0f)};
    memcpy(fl, &zl, 4), memcpy(fl + 4, cl, 8);
    memcpy(fh, &zh, 4), memcpy(fh + 4, ch, 8);
    ov_op(fl, fh, fo, 1, OV_PXF, NULL);
    float z;
    uint16_t co[4];
    memcpy(&z, fo, 4), memcpy(co, fo + 4, 8);
    assert_true(z == 1.5f);
    assert_true(sd_half_to_float(co[0]) == 0.5f && sd_half_to_float(co[1]) == 0.5f);
    assert_true(sd_half_to_float(co[2]) == 0.0f && sd_half_to_float(co[3]) == 1.0f);
    uint16_t rgbaf[4];
    uint8_t rgba8[4];
    cl[1] = 0;
    memcpy(fl + 4, cl, 8);
    ov_backgroundf(fl, 1, (float[3]){0, 0.5f, 0}, rgbaf, rgba8, &z);
    assert_true(sd_half_to_float(rgbaf[0]) == 0.5f && sd_half_to_float(rgbaf[1]) == 0.25f);
    assert_true(sd_half_to_float(rgbaf[3]) == 0.5f); /* coverage kept, as the float target */
    assert_int_equal(rgba8[0], 128);
    assert_int_equal(rgba8[1], 64);
    assert_int_equal(rgba8[3], 255);
    assert_true(z == 2.0f);
    /* halves: every non-NaN bit pattern round-trips; floats round to the nearest half, ties
     * to even; past 65504 is infinity; below 2^-24 / 2 is zero */
    for (uint32_t h = 0; h < 65536; h++) {
        if (((h >> 10) & 31) == 31 && (h & 1023)) continue;
        assert_int_equal(sd_float_to_half(sd_half_to_float((uint16_t)h)), h);
        assert_true(sd_half_to_float((uint16_t)h) == tu_half((uint16_t)h) ||
                    isnan(tu_half((uint16_t)h)));
    }
    assert_int_equal(sd_float_to_half(1.0f + 1.0f / 2048), 0x3c00);          /* tie: even */
    assert_int_equal(sd_float_to_half(1.0f + 3.0f / 2048), 0x3c02);          /* tie: even */
    assert_int_equal(sd_float_to_half(65520.0f), 0x7c00);
    assert_int_equal(sd_float_to_half(65519.0f), 0x7bff);
    assert_int_equal(sd_float_to_half(ldexpf(1.0f, -26)), 0);
    assert_int_equal(sd_float_to_half(ldexpf(3.0f, -25)), 2);                /* 1.5 -> 2 */
}

/* The records rank 0 sends the other ranks (mr_msg.h): what they carry arrives whole, every
 * parameter and the camera bit for bit, and each field is checked at its exact limits. */
static void test_records(void **state)
{
    (void)state;
    enum { N = MR_CMD_BYTES };
    static uint8_t rec[N];
    sd_err e = {0};
    mr_cmd c = {.op = MR_RENDER, .key = 7, .want_float = 1,
                .cam = {{1.5, -2, 3e9}, {0, 0, 0}, {1, 0, 0}, 33.25f, 0.5f, 900.0f, 640, 1}};
    sp_params_defaults(&c.params);
    /* every parameter away from its default: what a rank renders with is rank 0's */
    for (int id = 0; id < SP_PARAM_COUNT; id++) {
        proto_param_rec r;
        proto_param_rec_from(&c.params, id, &r);
        const sp_param_info *in = &sp_param_table[id];
        switch (r.type) {
        case SP_T_ENUM: r.u.e = r.u.e ? 0 : 1; break;
        case SP_T_INT: r.u.i = r.u.i != (int64_t)in->max ? (int64_t)in->max : (int64_t)in->min; break;
        case SP_T_FLOAT: r.u.f = r.u.f != (float)in->max ? (float)in->max : (float)in->min; break;
        case SP_T_VEC3: for (int k = 0; k < 3; k++) r.u.v[k] = 0.25f * (float)(k + 1); break;
        }
        proto_error pe = {0};
        if (proto_param_apply(&r, &c.params, NULL, &pe) != 0) fail_msg("%s", pe.msg);
    }
    assert_int_equal(mr_cmd_encode(&c, rec, &e), 0);
    mr_cmd d;
    if (mr_cmd_decode(rec, N, &d, &e) != 0) fail_msg("%s", e.msg);
    assert_int_equal(d.op, MR_RENDER);
    assert_int_equal(d.key, 7);
    assert_int_equal(d.want_float, 1);
    assert_memory_equal(&d.cam, &c.cam, sizeof d.cam);
    for (int id = 0; id < SP_PARAM_COUNT; id++) {
        proto_param_rec a, b;
        proto_param_rec_from(&c.params, id, &a);
        proto_param_rec_from(&d.params, id, &b);
        if (memcmp(&a, &b, sizeof a)) fail_msg("parameter %s differs", sp_param_table[id].name);
    }
    assert_memory_equal(&d.params, &c.params, sizeof d.params);
    /* the record's size, exactly */
    assert_int_equal(mr_cmd_decode(rec, N - 1, &d, &e), SD_EFORMAT);
    /* want_float 0 or 1 only; a width the wire refuses (0); a padding byte set */
    rec[8] = 2;
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "want_float 2"));
    rec[8] = 1;
    rec[N - 1] = 1;
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "byte 8191"));
    c.cam.width = 0;
    assert_int_not_equal(mr_cmd_encode(&c, rec, &e) == 0 && mr_cmd_decode(rec, N, &d, &e) == 0, 1);
    /* LOAD: a path of PATH_MAX - 1 bytes travels, one of PATH_MAX does not */
    mr_cmd l = {.op = MR_LOAD, .key = 1};
    memset(l.path, 'p', PATH_MAX - 1);
    assert_int_equal(mr_cmd_encode(&l, rec, &e), 0);
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), 0);
    assert_int_equal(strlen(d.path), PATH_MAX - 1);
    rec[12] = (uint8_t)PATH_MAX, rec[13] = (uint8_t)(PATH_MAX >> 8);
    memset(rec + 14 + PATH_MAX - 1, 'p', 1);
    memset(rec + 14 + PATH_MAX, 0, 8);
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "not shorter than PATH_MAX"));
    /* a length whose field ends exactly at the record's end is read; one byte more is not */
    memset(rec, 0, N);
    rec[0] = MR_LOAD, rec[4] = 1;
    size_t pl = N - 14 - 8;
    rec[12] = (uint8_t)pl, rec[13] = (uint8_t)(pl >> 8);
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "not shorter than PATH_MAX")); /* read to the end: fits */
    pl++;
    rec[12] = (uint8_t)pl, rec[13] = (uint8_t)(pl >> 8);
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "runs past"));
    /* op and key */
    memset(rec, 0, N);
    rec[0] = 4;
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "unknown MPI command 4"));
    rec[0] = MR_QUIT;
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), 0);
    rec[0] = MR_LOAD, rec[12] = 1, rec[14] = 'a';
    assert_int_equal(mr_cmd_decode(rec, N, &d, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "key 0"));
    /* a failure record: its code when an SD_E* code, else SD_EIO; its message */
    mr_fail f = {.code = SD_ENOTFOUND};
    snprintf(f.msg, sizeof f.msg, "rank 2 of 3: gone");
    assert_int_equal(mr_fail_decode(&f, sizeof f, &e), SD_ENOTFOUND);
    assert_string_equal(e.msg, "rank 2 of 3: gone");
    f.code = SD_ENOTFOUND - 1;
    assert_int_equal(mr_fail_decode(&f, sizeof f, &e), SD_EIO);
    f.code = 0;
    assert_int_equal(mr_fail_decode(&f, sizeof f, &e), SD_EIO);
    f.code = SD_EIO;
    memset(f.msg, 'm', sizeof f.msg); /* no terminator */
    assert_int_equal(mr_fail_decode(&f, sizeof f, &e), SD_EIO);
    assert_int_equal(strlen(e.msg), sizeof e.msg - 1);
    assert_int_equal(mr_fail_decode(&f, sizeof f - 1, &e), SD_EIO);
    assert_non_null(strstr(e.msg, "cut short"));
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_partition_cells_bunny),
        cmocka_unit_test(test_partition_cells_uneven),
        cmocka_unit_test(test_partition),
        cmocka_unit_test(test_box_order),
        cmocka_unit_test(test_over),
        cmocka_unit_test(test_records),
        cmocka_unit_test_setup_teardown(test_points_identical_1_to_4, setup, teardown),
        cmocka_unit_test_setup_teardown(test_rank_dies, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
