/* test_laz_render.c — LAZ and COPC through the whole program: `splatd render` of a .laz gives
 * the same image as of its uncompressed .las twin, and the daemon lists and opens .laz and
 * .copc.laz files (with and without their extension).
 *
 * Tolerance: none. The decoder gives the twin's records byte for byte (test_io_laz), so both
 * files load into the same float positions and colours, the same prep (deterministic kNN on
 * identical input) and the same draw calls; llvmpipe is deterministic for identical input, so
 * the PNGs must be identical pixel for pixel. The image is checked to hold drawn points, so
 * two blank frames would not pass. */
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

#include "common/daemonproc.h"
#include "common/imgtest.h"
#include "common/testutil.h"
#include "splat_client.h"

typedef struct fx {
    char root[512], data[600], cache[600];
    tu_daemon d;
} fx;

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

/* render: `splatd render FILE -o OUT --size 160x120 --pipeline P` with the cache tag. */
static void render(const fx *f, const char *file, const char *pipeline, const char *tag,
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
        render(f, laz, pipes[p], "laz", pa);
        render(f, las, pipes[p], "las", pb);
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
    spc_options o = {.host = "127.0.0.1", .port = f->d.port, .timeout_ms = 60000,
                     .client_name = "test_laz_render"};
    spc_client *c = NULL;
    char err[300];
    if (spc_connect(&o, &c, err, sizeof err) < 0) fail_msg("connect: %s", err);
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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_render_laz_equals_las, setup, teardown),
        cmocka_unit_test_setup_teardown(test_daemon_lists_and_opens_laz, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
