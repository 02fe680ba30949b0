/* test_daemon_cli.c — what a newcomer meets first, through the real binaries: splatd's
 * command line (--preload with several names), LIST on a prepared but unloaded cloud, the
 * error a client sees when a cloud fails to load, OPEN's progress reaching 100 % in every
 * phase, `splat --version` and each command's own --help, progress written as whole lines when
 * stderr is no terminal, and a thin client that does not need the GL stack. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "common/daemonproc.h"
#include "common/imgtest.h"
#include "common/testutil.h"
#include "splat_client.h"
#include "testutil.h"

enum { BUNNY_POINTS = 40256 }; /* "element vertex 40256" in tests/data/bun000.ply */

typedef struct fx {
    char root[512];
    char data[600], cache[600];
    tu_daemon d;
} fx;

/* add_bunny: copies tests/data/bun000.ply into the data directory as name. */
static void add_bunny(const fx *f, const char *name)
{
    char src[600], dst[700];
    tu_data("bun000.ply", src, sizeof src);
    snprintf(dst, sizeof dst, "%s/%s", f->data, name);
    assert_int_equal(tu_copy_file(src, dst), 0);
}

static int setup(void **state)
{
    fx *f = calloc(1, sizeof *f);
    if (!f || !tu_tmpdir(f->root, sizeof f->root)) return -1;
    snprintf(f->data, sizeof f->data, "%s/data", f->root);
    snprintf(f->cache, sizeof f->cache, "%s/cache", f->root);
    if (mkdir(f->data, 0755) != 0 || mkdir(f->cache, 0700) != 0) return -1;
    signal(SIGPIPE, SIG_IGN);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fx *f = *state;
    if (f->d.pid > 0) tu_daemon_stop(&f->d);
    tu_rm_rf(f->root);
    free(f);
    return 0;
}

static spc_client *connect_to(const fx *f)
{
    spc_options o = {.host = "127.0.0.1", .port = f->d.port, .timeout_ms = 60000,
                     .client_name = "test_daemon_cli"};
    spc_client *c = NULL;
    char err[300];
    if (spc_connect(&o, &c, err, sizeof err) < 0) fail_msg("connect: %s", err);
    return c;
}

/* find: the entry named name in a LIST answer, or NULL. */
static const spc_cloud *find(const spc_cloud *l, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (!strcmp(l[i].name, name)) return &l[i];
    return NULL;
}

/* `splatd --preload A B` preloads both (README's and --help's form), as does a repeated
 * --preload; an operand anywhere else is still refused, naming it. */
static void test_preload_several_names(void **state)
{
    fx *f = *state;
    add_bunny(f, "a.ply");
    add_bunny(f, "b.ply");
    add_bunny(f, "c.ply");
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache,
                          "--preload", "a", "b", "--max-clients", "4", "--preload", "c", NULL};
    if (tu_daemon_start(&f->d, f->root, NULL, args) != 0) {
        size_t l;
        char *log = (char *)tu_read_file(f->d.log, &l);
        fail_msg("splatd did not start: %s", log ? log : "(no log)");
    }
    spc_client *c = connect_to(f);
    int loaded = 0;
    for (int tries = 0; tries < 600 && loaded < 3; tries++) { /* up to 60 s */
        spc_cloud *l;
        int n = spc_list(c, &l);
        assert_true(n >= 3);
        loaded = 0;
        for (int i = 0; i < n; i++)
            if (l[i].flags & 2) {
                assert_int_equal(l[i].points, BUNNY_POINTS);
                loaded++;
            }
        spc_free_list(l);
        if (loaded < 3) usleep(100000);
    }
    assert_int_equal(loaded, 3);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);

    char out[4096];
    int rc = tu_run(out, sizeof out, "'%s' --data '%s' stray 2>&1", tu_splatd_bin(), f->data);
    assert_int_equal(rc, 2);
    assert_non_null(strstr(out, "unexpected argument 'stray'"));
}

/* A cloud prepared by `splatd prep` but not loaded lists as prepared with its point count
 * (from the cache header), not 0; an unprepared one lists no count. */
static void test_list_prepared_counts(void **state)
{
    fx *f = *state;
    add_bunny(f, "prepped.ply");
    add_bunny(f, "raw.ply");
    char out[8192];
    int rc = tu_run(out, sizeof out, "'%s' prep '%s/prepped.ply' --cache '%s' --quiet 2>&1",
                 tu_splatd_bin(), f->data, f->cache);
    if (rc != 0) fail_msg("splatd prep failed (%d): %s", rc, out);
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    spc_client *c = connect_to(f);
    spc_cloud *l;
    int n = spc_list(c, &l);
    assert_int_equal(n, 2);
    const spc_cloud *p = find(l, n, "prepped.ply"), *r = find(l, n, "raw.ply");
    assert_non_null(p);
    assert_non_null(r);
    assert_int_equal(p->flags, 1);               /* prepared, not loaded */
    assert_int_equal(p->points, BUNNY_POINTS);
    assert_int_equal(r->flags, 0);
    assert_int_equal(r->points, 0);
    spc_free_list(l);

    /* the CLI shows the same */
    rc = tu_run(out, sizeof out, "'%s' --port %d list 2>&1", tu_splat_bin(), f->d.port);
    assert_int_equal(rc, 0);
    char want[128];
    snprintf(want, sizeof want, "%d  prepared", BUNNY_POINTS);
    if (!strstr(out, want)) fail_msg("splat list does not show '%s':\n%s", want, out);
    spc_close(c);
}

typedef struct progress_log {
    char phase[16][32];
    float best[16];
    int n;
} progress_log;

static void on_progress(void *user, const char *phase, float fraction, const char *text)
{
    (void)text;
    progress_log *p = user;
    int i = 0;
    while (i < p->n && strcmp(p->phase[i], phase)) i++;
    if (i == p->n) {
        if (p->n == 16) return;
        snprintf(p->phase[p->n], sizeof p->phase[0], "%s", phase);
        p->best[p->n++] = fraction;
    } else if (fraction > p->best[i]) {
        p->best[i] = fraction;
    }
}

/* OPEN of an unprepared cloud reports its phases, and the upload phase reaches 100 % (it
 * used to stop at 0 %). A cloud that fails to load is named by its name in the client's error,
 * never by the server's absolute path (which only the daemon's log shows). */
static void test_open_progress_and_failure(void **state)
{
    fx *f = *state;
    add_bunny(f, "bunny.ply");
    char bad[700];
    snprintf(bad, sizeof bad, "%s/broken.ply", f->data);
    const char trunc[] = "ply\nformat binary_little_endian 1.0\nelement vertex 1000\n"
                         "property float x\nproperty float y\nproperty float z\nend_header\n"
                         "\x01\x02\x03";
    assert_int_equal(tu_write_file(bad, trunc, sizeof trunc - 1), 0);
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    spc_client *c = connect_to(f);

    progress_log pl = {0};
    spc_info info;
    assert_int_equal(spc_open(c, "bunny", &info, on_progress, &pl), 0);
    assert_int_equal(info.points, BUNNY_POINTS);
    int up = -1;
    for (int i = 0; i < pl.n; i++)
        if (!strcmp(pl.phase[i], "upload")) up = i;
    if (up < 0) fail_msg("no upload phase reported (%d phases)", pl.n);
    assert_true(pl.best[up] == 1.0f);

    int rc = spc_open(c, "broken", NULL, NULL, NULL);
    assert_int_equal(rc, SPC_E_LOAD_FAILED);
    const char *msg = spc_errmsg(c);
    if (!strstr(msg, "broken.ply")) fail_msg("the error does not name the cloud: %s", msg);
    if (strstr(msg, f->root)) fail_msg("the error shows the server's path: %s", msg);
    spc_close(c);
    size_t ll;
    char *log = (char *)tu_read_file(f->d.log, &ll);
    assert_non_null(log);
    assert_non_null(strstr(log, bad)); /* the operator still sees the full path */
    free(log);
}

/* `splat --version`, and each command's own help (not the overview), exit 0 without a server;
 * `splatd --version` too. */
static void test_help_and_version(void **state)
{
    (void)state;
    char out[16384];
    assert_int_equal(tu_run(out, sizeof out, "'%s' --version", tu_splat_bin()), 0);
    assert_int_equal(strncmp(out, "splat ", 6), 0);
    assert_non_null(strstr(out, "protocol version 1"));
    assert_int_equal(tu_run(out, sizeof out, "'%s' --version", tu_splatd_bin()), 0);
    assert_int_equal(strncmp(out, "splatd ", 7), 0);

    static const struct { const char *args, *want, *unwanted; } h[] = {
        {"--help", "commands (splat COMMAND --help", NULL},
        {"render --help", "usage: splat render NAME -o FILE", "usage: splat list"},
        {"render x --help -o", "usage: splat render NAME -o FILE", NULL},
        {"-h path", "usage: splat path NAME", "usage: splat render"},
        {"list -h", "usage: splat list", "--eye"},
        {"info --help", "usage: splat info NAME", "--orbit"},
    };
    for (size_t i = 0; i < sizeof h / sizeof h[0]; i++) {
        int rc = tu_run(out, sizeof out, "'%s' %s", tu_splat_bin(), h[i].args);
        if (rc != 0 || !strstr(out, h[i].want) || (h[i].unwanted && strstr(out, h[i].unwanted)))
            fail_msg("splat %s: exit %d, wanted '%s'%s%s, got:\n%s", h[i].args, rc, h[i].want,
                     h[i].unwanted ? " and not " : "", h[i].unwanted ? h[i].unwanted : "", out);
    }
    /* render's help lists the parameters; list's does not */
    assert_int_equal(tu_run(out, sizeof out, "'%s' render --help", tu_splat_bin()), 0);
    assert_non_null(strstr(out, "pipeline"));
}

/* With stderr not a terminal (a log file, CI), progress comes as whole lines: no carriage
 * return anywhere, from `splat info` (first OPEN prepares), `splat path` and `splatd render`. */
static void test_progress_lines_off_terminal(void **state)
{
    fx *f = *state;
    add_bunny(f, "bunny.ply");
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    char out[65536];
    int rc = tu_run(out, sizeof out, "'%s' --port %d info bunny 2>&1 >/dev/null", tu_splat_bin(),
                 f->d.port);
    assert_int_equal(rc, 0);
    if (!strstr(out, "preparing bunny")) fail_msg("no progress lines: %s", out);
    assert_null(strchr(out, '\r'));
    rc = tu_run(out, sizeof out, "'%s' --port %d path bunny --orbit 3 --size 64x48 "
                "-o '%s/o/%%d.jpg' 2>&1 >/dev/null", tu_splat_bin(), f->d.port, f->root);
    assert_int_equal(rc, 0);
    if (!strstr(out, "3 frames")) fail_msg("no summary: %s", out);
    assert_null(strchr(out, '\r'));
    rc = tu_run(out, sizeof out, "'%s' render '%s/bunny.ply' -o '%s/r.png' --size 64x48 --cache "
             "'%s/c2' 2>&1 >/dev/null", tu_splatd_bin(), f->data, f->root, f->root);
    if (rc != 0) fail_msg("splatd render failed (%d): %s", rc, out);
    if (!strstr(out, "100%")) fail_msg("no progress lines: %s", out);
    assert_null(strchr(out, '\r'));
}

/* The thin client needs no GL stack, kNN or EXR library: `splat` and libsplatclient.so record
 * only what they use (libssl for TLS, libcrypto for it and the token's HMAC) (checked on the binary under test, so the ASan build too, where the
 * linker keeps every library named on the command line). */
static void test_thin_client_links(void **state)
{
    (void)state;
    /* libSDL2 and libX11: the window of `splat view` is the separate binary splat-view. */
    static const char *const forbidden[] = {"libEGL", "libOpenGL", "libGL.", "libOSMesa",
                                            "libflann", "libOpenEXR", "libpng", "libGLX",
                                            "libSDL2", "libX11"};
    char lib[1024];
    snprintf(lib, sizeof lib, "%s", tu_splat_bin());
    char *slash = strrchr(lib, '/');
    assert_non_null(slash);
    *slash = 0; /* .../bin */
    slash = strrchr(lib, '/');
    assert_non_null(slash);
    snprintf(slash, sizeof lib - (size_t)(slash - lib), "/libsplatclient.so");
    const char *bins[2] = {tu_splat_bin(), lib};
    for (int b = 0; b < 2; b++) {
        if (b == 1 && access(lib, F_OK) != 0) continue; /* the ASan flavour builds no .so */
        char out[16384];
        int rc = tu_run(out, sizeof out, "readelf -d '%s' | grep NEEDED", bins[b]);
        if (rc != 0) fail_msg("readelf -d %s failed (%d): %s", bins[b], rc, out);
        assert_non_null(strstr(out, "libcrypto"));
        assert_non_null(strstr(out, "libssl"));
        for (size_t i = 0; i < sizeof forbidden / sizeof forbidden[0]; i++)
            if (strstr(out, forbidden[i]))
                fail_msg("%s needs %s:\n%s", bins[b], forbidden[i], out);
    }
}

/* render_raw: one 96x72 `points` frame of the client's cloud from its default camera, as raw
 * RGBA (malloc'd, *len bytes). */
static uint8_t *render_raw(spc_client *c, const spc_info *info, size_t *len)
{
    const char *kv[2] = {"pipeline=points", "format=raw"};
    assert_int_equal(spc_set_params(c, kv, 2), 0);
    spc_camera cam;
    spc_camera_frame(info, 96, 72, &cam);
    assert_int_equal(spc_set_camera(c, &cam, NULL), 0);
    spc_frame f;
    if (spc_render(c, &f, 0) < 0) fail_msg("render: %s", spc_errmsg(c));
    uint8_t *copy = malloc(f.data_len);
    assert_non_null(copy);
    memcpy(copy, f.data, f.data_len);
    *len = f.data_len;
    return copy;
}

/* --gpu-memory holds the daemon's cloud buffers to a budget: with room for one bunny (40256
 * points x 40 bytes = 1.6 MB; 2 MiB given), two clients rendering two clouds in turn each get
 * their frames, and a cloud pushed off the GPU and brought back renders the same frame. */
static void test_gpu_memory_budget(void **state)
{
    fx *f = *state;
    add_bunny(f, "a.ply");
    add_bunny(f, "b.ply");
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache,
                          "--gpu-memory", "2M", NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    spc_client *ca = connect_to(f), *cb = connect_to(f);
    spc_info ia, ib;
    assert_int_equal(spc_open(ca, "a", &ia, NULL, NULL), 0);
    assert_int_equal(spc_open(cb, "b", &ib, NULL, NULL), 0); /* pushes a off the GPU */
    size_t la, lb, la2;
    uint8_t *fa = render_raw(ca, &ia, &la);                  /* a back, b off */
    uint8_t *fb = render_raw(cb, &ib, &lb);                  /* and the other way */
    uint8_t *fa2 = render_raw(ca, &ia, &la2);
    assert_int_equal(la, la2);
    assert_memory_equal(fa, fa2, la);
    assert_int_equal(la, lb);
    assert_memory_equal(fa, fb, la); /* the same file, the same camera */
    int lit = 0;
    for (size_t i = 0; i + 3 < la; i += 4) lit += fa[i] || fa[i + 1] || fa[i + 2];
    assert_true(lit > 200);
    free(fa);
    free(fb);
    free(fa2);
    spc_close(ca);
    spc_close(cb);
    size_t ll;
    char *log = (char *)tu_read_file(f->d.log, &ll);
    assert_non_null(log);
    if (!strstr(log, "held to 2 MiB of GPU memory")) fail_msg("no budget in the log: %s", log);
    free(log);

    char out[4096];
    int rc = tu_run(out, sizeof out, "'%s' --data '%s' --gpu-memory 12Q 2>&1", tu_splatd_bin(), f->data);
    assert_int_equal(rc, 2);
    assert_non_null(strstr(out, "--gpu-memory '12Q'"));
}

/* ---- LAZ and COPC through the whole program ----
 * `splatd render` of a .laz gives the same image as of its uncompressed .las twin, and the
 * daemon lists and opens .laz and .copc.laz files (with and without their extension).
 * Tolerance: none. The decoder gives the twin's records byte for byte (test_io_laz), so both
 * files load into the same float positions and colours, the same prep (deterministic kNN on
 * identical input) and the same draw calls; llvmpipe is deterministic for identical input, so
 * the PNGs must be identical pixel for pixel. The image is checked to hold drawn points, so
 * two blank frames would not pass. */

/* render: `splatd render FILE -o OUT --size 160x120 --pipeline P` with the cache tag. */
static void render_file(const fx *f, const char *file, const char *pipeline, const char *tag,
                   const char *out)
{
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "'%s' render '%s' -o '%s' --size 160x120 --pipeline %s --cache "
             "'%s/c-%s' --quiet 2>&1", tu_splatd_bin(), file, out, pipeline, f->root, tag);
    int st = system(cmd);
    if (!WIFEXITED(st) || WEXITSTATUS(st) != 0) fail_msg("failed: %s", cmd);
}

static void test_render_laz_equals_las(void **state)
{
    fx *f = *state;
    char laz[1024], las[1024], pa[1200], pb[1200];
    tu_data("autzen_trim.laz", laz, sizeof laz);
    tu_data("autzen_trim.las", las, sizeof las);
    const char *pipes[] = {"points", "splat"};
    for (int p = 0; p < 2; p++) {
        snprintf(pa, sizeof pa, "%s/laz-%s.png", f->root, pipes[p]);
        snprintf(pb, sizeof pb, "%s/las-%s.png", f->root, pipes[p]);
        /* separate caches: nothing is shared but what the two files hold */
        render_file(f, laz, pipes[p], "laz", pa);
        render_file(f, las, pipes[p], "las", pb);
        uint32_t wa, ha, wb, hb;
        uint8_t *a, *b;
        assert_int_equal(tu_png_read(pa, 0, &wa, &ha, &a), 0);
        assert_int_equal(tu_png_read(pb, 0, &wb, &hb, &b), 0);
        assert_int_equal(wa, 160);
        assert_int_equal(ha, 120);
        assert_int_equal(wb, wa);
        assert_int_equal(hb, ha);
        size_t diff = 0, drawn = 0;
        for (size_t i = 0; i < (size_t)wa * ha; i++) {
            diff += memcmp(a + 4 * i, b + 4 * i, 4) != 0;
            drawn += memcmp(a + 4 * i, a, 4) != 0; /* differs from the corner (background) */
        }
        if (diff) fail_msg("%s: %zu of %u pixels differ between .laz and .las", pipes[p], diff,
                           wa * ha);
        if (drawn < (size_t)wa * ha / 10)
            fail_msg("%s: only %zu pixels drawn: the frame is (nearly) empty", pipes[p], drawn);
        free(a);
        free(b);
    }
}

static void test_daemon_lists_and_opens_laz(void **state)
{
    fx *f = *state;
    const char *names[] = {"point-color-time.las.laz", "ellipsoid.copc.laz"};
    for (int i = 0; i < 2; i++) {
        char src[1024], dst[1200];
        snprintf(dst, sizeof dst, "%s/%s", f->data, names[i]);
        assert_int_equal(tu_copy_file(tu_data(names[i], src, sizeof src), dst), 0);
    }
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    spc_client *c = connect_to(f);
    spc_cloud *l = NULL;
    int n = spc_list(c, &l);
    assert_int_equal(n, 2);
    int seen = 0;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 2; k++) seen += !strcmp(l[i].name, names[k]);
    assert_int_equal(seen, 2);
    spc_free_list(l);

    spc_info info;
    if (spc_open(c, "point-color-time.las.laz", &info, NULL, NULL) < 0)
        fail_msg("open: %s", spc_errmsg(c));
    assert_int_equal(info.points, 1065);
    assert_true(info.attrs & SPC_ATTR_RGB);
    assert_non_null(strstr(info.format, "LAZ 1.2 format 3"));
    /* ".copc.laz" counts as one extension: the bare name finds the file */
    if (spc_open(c, "ellipsoid", &info, NULL, NULL) < 0) fail_msg("open: %s", spc_errmsg(c));
    assert_string_equal(info.name, "ellipsoid.copc.laz");
    assert_int_equal(info.points, 100000);
    assert_non_null(strstr(info.format, "COPC LAZ 1.4 format 7"));
    spc_close(c);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_preload_several_names, setup, teardown),
        cmocka_unit_test_setup_teardown(test_list_prepared_counts, setup, teardown),
        cmocka_unit_test_setup_teardown(test_open_progress_and_failure, setup, teardown),
        cmocka_unit_test_setup_teardown(test_help_and_version, setup, teardown),
        cmocka_unit_test_setup_teardown(test_progress_lines_off_terminal, setup, teardown),
        cmocka_unit_test_setup_teardown(test_thin_client_links, setup, teardown),
        cmocka_unit_test_setup_teardown(test_gpu_memory_budget, setup, teardown),
        cmocka_unit_test_setup_teardown(test_render_laz_equals_las, setup, teardown),
        cmocka_unit_test_setup_teardown(test_daemon_lists_and_opens_laz, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
