/* test_copc_open.c — the first image of a COPC file through the real daemon and libsplatclient
 * (PROTOCOL.md, OPEN, provisional clouds): a client that sets provisional=1 gets a provisional
 * INFO of COPC's top levels and frames of it (drawn with `points`) while the full prep runs,
 * PROGRESS after that, then the full INFO; a second client opening mid-prep gets the provisional
 * cloud too and may leave without harm; after the swap, `splat` frames equal a render of the
 * prepared cache (another daemon on the same cache, lossless frames); a truncated COPC file is a
 * clear LOAD_FAILED and the daemon goes on serving.
 *
 * The expected point count comes from the file's own hierarchy (copc.h, read here directly):
 * the sum of the node counts of levels 0..L, L the deepest level whose running total fits the
 * daemon's --copc-preview budget. ellipsoid.copc.laz (100,000 points) is the only COPC file
 * the repository has; its full prep takes a few tenths of a second, the first frame tens of
 * milliseconds, so "mid-prep" holds by a wide margin (the test says so when it did not). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "cloud.h"
#include "copc.h"
#include "daemonproc.h"
#include "io_text.h"
#include "laz.h"
#include "splat_client.h"
#include "testutil.h"

enum { MAXLV = 32 };

/* level_sums: the points of each octree level of the COPC file path (sums[l]); the deepest
 * level in *depth. */
typedef struct sums_ctx {
    uint64_t sums[MAXLV];
    int depth;
} sums_ctx;

static int add_entry(void *ctx, const copc_entry *e)
{
    sums_ctx *s = ctx;
    if (e->level < 0 || e->level >= MAXLV) return 1;
    s->sums[e->level] += (uint64_t)e->count;
    if (e->level > s->depth) s->depth = e->level;
    return 0;
}

/* open_laz: path's bytes (malloc'd, *len of them) opened as LAZ into lf. */
static uint8_t *open_laz(const char *path, laz_file *lf, size_t *len)
{
    uint8_t *data = tu_read_file(path, len);
    assert_non_null(data);
    sd_err err = {0};
    if (laz_open(lf, path, data, *len, &err) != 0) fail_msg("%s", err.msg);
    return data;
}

static void level_sums(const char *path, sums_ctx *s)
{
    memset(s, 0, sizeof *s);
    size_t len = 0;
    laz_file lf;
    sd_err err = {0};
    uint8_t *data = open_laz(path, &lf, &len);
    if (copc_visit(&lf, INT32_MAX, add_entry, s, &err) != 0) fail_msg("%s", err.msg);
    laz_close(&lf);
    free(data);
}

typedef struct progress_count {
    int n;
    float last;
} progress_count;

static void on_progress(void *user, const char *phase, float fraction, const char *text)
{
    (void)phase;
    (void)text;
    progress_count *p = user;
    p->n++;
    p->last = fraction;
}

static spc_client *connect_to(const tu_daemon *d, const char *name)
{
    spc_options o = {.host = "127.0.0.1", .port = d->port, .client_name = name};
    spc_client *c = NULL;
    char err[256];
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("connect: %s", err);
    return c;
}

static void start(tu_daemon *d, const char *dir, const char *data, const char *cache,
                  const char *budget)
{
    const char *args[] = {"--listen", "127.0.0.1:0", "--data", data, "--cache", cache,
                          "--copc-preview", budget,
                          "--shader-dir", tu_env("SPLATD_SHADERS", "shaders"), NULL};
    if (tu_daemon_start(d, dir, NULL, args) != 0) fail_msg("splatd did not start (log %s)", d->log);
}

/* make_dirs: a test directory dir with data/ holding ellipsoid.copc.laz (copc) and cache/;
 * the file's level sums in *s and level 0's count as text in budget (the daemon's
 * --copc-preview that keeps exactly level 0). */
static void make_dirs(char dir[512], char data[600], char cache[600], char copc[700],
                      sums_ctx *s, char budget[32])
{
    char src[600];
    assert_non_null(tu_tmpdir(dir, 512));
    snprintf(data, 600, "%s/data", dir);
    snprintf(cache, 600, "%s/cache", dir);
    assert_int_equal(mkdir(data, 0700), 0);
    snprintf(copc, 700, "%s/ellipsoid.copc.laz", data);
    assert_int_equal(tu_copy_file(tu_data("ellipsoid.copc.laz", src, sizeof src), copc), 0);
    level_sums(copc, s);
    snprintf(budget, 32, "%llu", (unsigned long long)s->sums[0]);
}

static void test_first_image(void **state)
{
    (void)state;
    char dir[512], data[600], cache[600], copc[700], budget[32];
    sums_ctx s;
    /* the budget: level 0's points exactly, so that the rule's edge (<=) is what is tested and
     * level 1 is left out (the file has two levels) */
    make_dirs(dir, data, cache, copc, &s, budget);
    uint64_t total = 0;
    for (int l = 0; l <= s.depth; l++) total += s.sums[l];
    assert_int_equal(total, 100000); /* the header's count (test_io_laz checks that too) */
    assert_true(s.depth >= 1);
    uint64_t expect = s.sums[0];
    print_message("hierarchy: level 0 %llu, level 1 %llu points, %d levels; budget %llu\n",
                  (unsigned long long)s.sums[0], (unsigned long long)s.sums[1], s.depth + 1,
                  (unsigned long long)expect);

    tu_daemon d;
    start(&d, dir, data, cache, budget);
    spc_client *a = connect_to(&d, "copc-a");
    progress_count pa = {0};
    assert_int_equal(spc_set_param(a, "provisional=1"), 0);
    spc_info ia;
    double t0 = tu_now_us();
    assert_int_equal(spc_open(a, "ellipsoid.copc.laz", &ia, on_progress, &pa), 0);
    assert_true(ia.attrs & SPC_INFO_PROVISIONAL);
    assert_int_equal(spc_open_provisional(a), 1);
    assert_int_equal(ia.points, expect);
    assert_int_equal(ia.k, 0);
    assert_false(ia.attrs & (SPC_ATTR_NORMAL | SPC_ATTR_RADIUS | SPC_ATTR_F));
    assert_true(ia.attrs & SPC_ATTR_RGB);
    /* a frame at once: the default pipeline (splat) falls back to points */
    spc_camera cam;
    spc_camera_frame(&ia, 320, 240, &cam);
    assert_int_equal(spc_set_camera(a, &cam, NULL), 0);
    spc_frame f;
    assert_int_equal(spc_render(a, &f, 0), 0);
    double first_ms = (tu_now_us() - t0) / 1e3;
    print_message("OPEN to first frame: %.1f ms (%llu points)\n", first_ms,
                  (unsigned long long)f.points_drawn);
    if (!f.provisional)
        fail_msg("the full prep finished before the first frame (%.0f ms): no provisional frame "
                 "to test (machine overloaded?)", first_ms);
    assert_string_equal(f.pipeline, "points");
    assert_int_equal(f.points_drawn, expect); /* the whole box is in view: nothing culled */
    /* a streams from here: a frame now (the current view), the next one after the swap */
    assert_int_equal(spc_set_param(a, "format=lz4"), 0);
    assert_int_equal(spc_stream(a, 1, 0), 0);
    assert_int_equal(spc_recv_frame(a, &f, 0), 0);
    if (!f.provisional) fail_msg("the full prep finished before the stream started (overloaded?)");
    assert_int_equal(f.points_drawn, expect);

    /* a second client mid-prep: the provisional cloud too, then it leaves */
    spc_client *b = connect_to(&d, "copc-b");
    assert_int_equal(spc_set_param(b, "provisional=1"), 0);
    spc_info ib;
    assert_int_equal(spc_open(b, "ellipsoid", &ib, NULL, NULL), 0);
    if (!(ib.attrs & SPC_INFO_PROVISIONAL))
        fail_msg("the full prep finished before the second OPEN (machine overloaded?)");
    assert_int_equal(ib.points, expect);
    assert_int_equal(spc_render(b, &f, 0), 0);
    assert_int_equal(f.provisional, 1);
    assert_int_equal(f.points_drawn, expect);
    spc_close(b); /* mid-prep: the prep goes on for a */

    /* a client without the parameter waits for the full cloud, as before */
    spc_client *w = connect_to(&d, "copc-wait");
    spc_info iw;
    assert_int_equal(spc_open(w, "ellipsoid.copc.laz", &iw, NULL, NULL), 0);
    assert_false(iw.attrs & SPC_INFO_PROVISIONAL);
    assert_int_equal(iw.points, 100000);
    spc_close(w);

    /* a's stream, with no new camera: the swap alone sends it a frame of the full cloud */
    assert_int_equal(spc_recv_frame(a, &f, 0), 0);
    assert_int_equal(f.provisional, 0);
    assert_string_equal(f.pipeline, "splat");
    assert_int_equal(f.points_drawn, 100000);
    assert_int_equal(spc_stream(a, 0, 0), 0);
    spc_info full;
    assert_int_equal(spc_wait_ready(a, &full, on_progress, &pa), 1);
    assert_int_equal(spc_open_provisional(a), 0);
    assert_false(full.attrs & SPC_INFO_PROVISIONAL);
    assert_int_equal(full.points, 100000);
    assert_int_equal(full.k, 24);
    assert_true(full.attrs & SPC_ATTR_NORMAL);
    assert_true(pa.n >= 2); /* at least a phase's start and end after the provisional INFO */
    print_message("%d PROGRESS after the provisional INFO\n", pa.n);

    /* after the swap: every pipeline works; splat is compared with the cache's render */
    const char *pipes[] = {"points", "kawata", "soft", "olt", "splat"};
    spc_frame g;
    uint8_t *mine = NULL;
    for (size_t i = 0; i < sizeof pipes / sizeof pipes[0]; i++) {
        char kv[64];
        snprintf(kv, sizeof kv, "pipeline=%s", pipes[i]);
        assert_int_equal(spc_set_param(a, kv), 0);
        assert_int_equal(spc_render(a, &g, 1), 0);
        assert_int_equal(g.provisional, 0);
        assert_string_equal(g.pipeline, pipes[i]);
    }
    mine = malloc((size_t)g.width * g.height * 4);
    assert_non_null(mine);
    memcpy(mine, g.rgba, (size_t)g.width * g.height * 4);
    spc_close(a);
    assert_int_equal(tu_daemon_log_count(&d, "cloud ellipsoid.copc.laz ready"), 1);
    assert_int_equal(tu_daemon_log_count(&d, "released: the full cloud replaces it"), 1);
    assert_int_equal(tu_daemon_stop(&d), 0);

    /* another daemon on the same cache: no provisional cloud (the cache opens fast) */
    tu_daemon d2;
    start(&d2, dir, data, cache, budget);
    spc_client *c = connect_to(&d2, "copc-cache");
    assert_int_equal(spc_set_param(c, "provisional=1"), 0);
    spc_info ic;
    assert_int_equal(spc_open(c, "ellipsoid.copc.laz", &ic, NULL, NULL), 0);
    assert_false(ic.attrs & SPC_INFO_PROVISIONAL);
    assert_int_equal(spc_set_param(c, "format=lz4"), 0);
    assert_int_equal(spc_set_camera(c, &cam, NULL), 0);
    assert_int_equal(spc_render(c, &g, 1), 0);
    size_t differ = 0;
    for (size_t i = 0; i < (size_t)g.width * g.height * 4; i++) differ += mine[i] != g.rgba[i];
    /* the same prepared bytes, renderer and camera: exactly the same image */
    assert_int_equal(differ, 0);
    free(mine);
    spc_close(c);
    assert_int_equal(tu_daemon_log_count(&d2, "first image of"), 0);
    assert_int_equal(tu_daemon_stop(&d2), 0);
    tu_rm_rf(dir);
}

/* A truncated COPC file: no first image, LOAD_FAILED naming the file; the daemon serves on. */
static void test_truncated(void **state)
{
    (void)state;
    char dir[512], data[600], cache[600], bad[700], src[600];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    snprintf(data, sizeof data, "%s/data", dir);
    snprintf(cache, sizeof cache, "%s/cache", dir);
    assert_int_equal(mkdir(data, 0700), 0);
    size_t len = 0;
    uint8_t *all = tu_read_file(tu_data("ellipsoid.copc.laz", src, sizeof src), &len);
    assert_non_null(all);
    snprintf(bad, sizeof bad, "%s/cut.copc.laz", data);
    assert_int_equal(tu_write_file(bad, all, len / 2), 0);
    free(all);
    tu_daemon d;
    start(&d, dir, data, cache, "1000000");
    spc_client *c = connect_to(&d, "copc-bad");
    assert_int_equal(spc_set_param(c, "provisional=1"), 0);
    spc_info in;
    int rc = spc_open(c, "cut.copc.laz", &in, NULL, NULL);
    assert_int_equal(rc, SPC_E_LOAD_FAILED);
    assert_non_null(strstr(spc_errmsg(c), "cut.copc.laz"));
    print_message("%s\n", spc_errmsg(c));
    assert_int_equal(spc_open_provisional(c), 0);
    assert_int_equal(spc_ping(c, NULL), 0); /* still served */
    spc_frame f;
    assert_int_equal(spc_render(c, &f, 0), SPC_E_NOT_OPEN);
    spc_close(c);
    assert_int_equal(tu_daemon_log_count(&d, "no first image of"), 1);
    assert_int_equal(tu_daemon_stop(&d), 0);
    tu_rm_rf(dir);
}

/* check_budget: pc_read_copc_budget(path, budget) reads levels 0..level, points points. */
static void check_budget(const char *path, uint64_t budget, int level, uint64_t points)
{
    pc_raw r = {0};
    sd_err e = {0};
    int got = -1;
    if (pc_read_copc_budget(path, budget, &r, &got, &e) != 0) fail_msg("%s", e.msg);
    assert_int_equal(got, level);
    assert_int_equal(r.n, points);
    pc_raw_free(&r);
}

/* The level rule of pc_read_copc_budget on its own: levels 0..L, L the deepest whose running
 * total fits the budget, at least the root. */
static void test_budget_rule(void **state)
{
    (void)state;
    char src[600];
    const char *path = tu_data("ellipsoid.copc.laz", src, sizeof src);
    sums_ctx s;
    level_sums(path, &s);
    const struct { uint64_t budget; int level; uint64_t points; } cases[] = {
        {1, 0, s.sums[0]},                       /* the root alone is over: still the root */
        {s.sums[0] - 1, 0, s.sums[0]},
        {s.sums[0], 0, s.sums[0]},
        {s.sums[0] + s.sums[1] - 1, 0, s.sums[0]},
        {s.sums[0] + s.sums[1], 1, s.sums[0] + s.sums[1]},
        {10000000, 1, s.sums[0] + s.sums[1]},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        check_budget(path, cases[i].budget, cases[i].level, cases[i].points);
}

/* first_level1: the byte offset of the first level-1 node's chunk (copc_visit's order). */
typedef struct find_ctx {
    uint64_t off;
} find_ctx;

static int find_level1(void *ctx, const copc_entry *e)
{
    find_ctx *f = ctx;
    if (e->level != 1 || e->count <= 0) return 0;
    f->off = e->off;
    return 1;
}

/* A prep that fails after the first image: the file's level-1 chunk says it holds 2^32 - 1
 * points (the count a layered chunk repeats after its first point), so the full decode fails
 * while level 0 reads fine. The client sees the provisional INFO, then LOAD_FAILED for the
 * OPEN naming the file (not where the server keeps it), and no open cloud after it. */
static void test_fail_after_first_image(void **state)
{
    (void)state;
    char dir[512], data[600], cache[600], copc[700], budget[32];
    sums_ctx s;
    make_dirs(dir, data, cache, copc, &s, budget);
    size_t len = 0;
    laz_file lf;
    sd_err err = {0};
    find_ctx fc = {0};
    uint8_t *bytes = open_laz(copc, &lf, &len);
    assert_int_equal(copc_visit(&lf, 1, find_level1, &fc, &err), 1);
    uint64_t at = fc.off + lf.h.rec_len;
    laz_close(&lf);
    assert_true(at + 4 <= len);
    memset(bytes + at, 0xff, 4);
    assert_int_equal(tu_write_file(copc, bytes, len), 0);
    free(bytes);
    tu_daemon d;
    start(&d, dir, data, cache, budget);
    spc_client *c = connect_to(&d, "copc-fail");
    assert_int_equal(spc_set_param(c, "provisional=1"), 0);
    spc_info in;
    assert_int_equal(spc_open(c, "ellipsoid.copc.laz", &in, NULL, NULL), 0);
    assert_true(in.attrs & SPC_INFO_PROVISIONAL);
    assert_int_equal(in.points, s.sums[0]);
    assert_int_equal(spc_wait_ready(c, &in, NULL, NULL), SPC_E_LOAD_FAILED);
    print_message("%s\n", spc_errmsg(c));
    assert_non_null(strstr(spc_errmsg(c), "ellipsoid.copc.laz"));
    assert_null(strstr(spc_errmsg(c), data));
    assert_int_equal(spc_open_provisional(c), 0);
    spc_frame f;
    assert_int_equal(spc_render(c, &f, 0), SPC_E_NOT_OPEN);
    assert_int_equal(spc_ping(c, NULL), 0);
    spc_close(c);
    assert_int_equal(tu_daemon_log_count(&d, "cloud ellipsoid.copc.laz failed"), 1);
    assert_int_equal(tu_daemon_log_count(&d, "released: the prep failed"), 1);
    assert_int_equal(tu_daemon_stop(&d), 0);
    tu_rm_rf(dir);
}

/* splat render: the first image with --set provisional=1 (level 0's points, points, said so);
 * without it, the full cloud as before (then from memory: no provisional cloud any more). */
static void test_cli(void **state)
{
    (void)state;
    char dir[512], data[600], cache[600], copc[700], out[4096], budget[32], want[64];
    sums_ctx s;
    make_dirs(dir, data, cache, copc, &s, budget);
    tu_daemon d;
    start(&d, dir, data, cache, budget);
    assert_int_equal(tu_run(out, sizeof out, "%s --port %d render ellipsoid.copc.laz --size 160x120 "
                            "--set provisional=1 -o %s/first.jpg 2>&1", tu_splat_bin(), d.port,
                            dir), 0);
    snprintf(want, sizeof want, "points jpeg");
    assert_non_null(strstr(out, want));
    snprintf(want, sizeof want, "%llu points (provisional", (unsigned long long)s.sums[0]);
    if (!strstr(out, want)) fail_msg("splat render said: %s", out);
    assert_int_equal(tu_run(out, sizeof out, "%s --port %d render ellipsoid.copc.laz --size 160x120 "
                            "-o %s/full.jpg 2>&1", tu_splat_bin(), d.port, dir), 0);
    if (!strstr(out, "splat jpeg") || !strstr(out, "100000 points") || strstr(out, "provisional"))
        fail_msg("splat render said: %s", out);
    assert_int_equal(tu_daemon_stop(&d), 0);
    tu_rm_rf(dir);
}

/* make_dup: the file copc with a new root hierarchy page (copc_dup.py's construction, in C):
 * its level-0 node, then n1 level-1 and n2 level-2 nodes all referencing the root's chunk, the
 * info VLR pointed at the page; written to dst. */
static void make_dup(const char *copc, const char *dst, int n1, int n2)
{
    size_t len = 0;
    laz_file lf;
    sd_err err = {0};
    uint8_t *in = open_laz(copc, &lf, &len);
    assert_non_null(lf.copc_info);
    size_t info = (size_t)(lf.copc_info - in);
    copc_info ci;
    assert_int_equal(copc_info_read(&lf, &ci, &err), 0);
    copc_entry *e = NULL;
    size_t n = 0;
    assert_int_equal(copc_page_read(&lf, ci.root_off, ci.root_size, &e, &n, &err), 0);
    laz_close(&lf);
    const copc_entry *root = NULL;
    for (size_t i = 0; i < n; i++)
        if (e[i].level == 0) root = &e[i];
    assert_non_null(root);
    size_t np = 1 + (size_t)n1 + (size_t)n2, out_len = len + 32 * np;
    uint8_t *out = malloc(out_len);
    assert_non_null(out);
    memcpy(out, in, len);
    for (size_t k = 0; k < np; k++) {
        int lv = k == 0 ? 0 : k <= (size_t)n1 ? 1 : 2;
        size_t j = k == 0 ? 0 : lv == 1 ? k - 1 : k - 1 - (size_t)n1;
        int32_t key[4] = {lv, (int32_t)(j % 2 + (lv == 2 ? 2 * (j / 8 % 2) : 0)),
                          (int32_t)(j / 2 % 2), (int32_t)(j / 4 % 2)};
        uint8_t *q = out + len + 32 * k;
        memcpy(q, key, 16); /* little-endian host, as the tests assume elsewhere */
        memcpy(q + 16, &root->off, 8);
        memcpy(q + 24, &root->bytes, 4);
        memcpy(q + 28, &root->count, 4);
    }
    uint64_t page[2] = {len, 32 * np};
    memcpy(out + info + 40, page, 16);
    assert_int_equal(tu_write_file(dst, out, out_len), 0);
    free(out);
    free(e);
    free(in);
}

/* A hierarchy with several nodes per level (make_dup): the budget keeps whole levels only,
 * and the counts add up from the file's own hierarchy. */
static void test_budget_levels_of_many_nodes(void **state)
{
    (void)state;
    char dir[512], data[600], cache[600], copc[700], budget[32], dup[800];
    sums_ctx s;
    make_dirs(dir, data, cache, copc, &s, budget);
    snprintf(dup, sizeof dup, "%s/dup.copc.laz", dir);
    make_dup(copc, dup, 6, 8);
    sums_ctx d;
    level_sums(dup, &d);
    assert_int_equal(d.depth, 2);
    assert_int_equal(d.sums[0], s.sums[0]);
    assert_int_equal(d.sums[1], 6 * s.sums[0]);
    assert_int_equal(d.sums[2], 8 * s.sums[0]);
    const struct { uint64_t budget; int level; uint64_t points; } cases[] = {
        {500000, 1, 7 * s.sums[0]},             /* 463,904: level 2 would make 994,080 */
        {7 * s.sums[0] - 1, 0, s.sums[0]},
        {15 * s.sums[0], 2, 15 * s.sums[0]},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        check_budget(dup, cases[i].budget, cases[i].level, cases[i].points);
    tu_rm_rf(dir);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_budget_rule),
        cmocka_unit_test(test_budget_levels_of_many_nodes),
        cmocka_unit_test(test_first_image),
        cmocka_unit_test(test_truncated),
        cmocka_unit_test(test_cli),
        cmocka_unit_test(test_fail_after_first_image),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
