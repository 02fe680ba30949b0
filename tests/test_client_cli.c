/* test_client_cli.c — the testable parts of the `splat` command: argument parsing, camera-path
 * files, output patterns, resume planning, atomic writes, the progress line, the orbit and
 * framing cameras, and token-file checks. No network. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "campath.h"
#include "cli.h"
#include "spc_internal.h"
#include "splat_client.h"
#include "framing.h"
#include "testutil.h"

static int parse(cli_args *a, char *err, ...)
{
    char *argv[40];
    int argc = 0;
    argv[argc++] = "splat";
    va_list ap;
    va_start(ap, err);
    for (char *s; (s = va_arg(ap, char *)) != NULL;) argv[argc++] = s;
    va_end(ap);
    return cli_parse(argc, argv, a, err, 300);
}

static void test_cli_parse(void **state)
{
    (void)state;
    cli_args a;
    char err[300];
    assert_int_equal(parse(&a, err, "list", NULL), 0);
    assert_string_equal(a.command, "list");
    assert_string_equal(a.host, "127.0.0.1");
    assert_int_equal(a.port, 7878);
    assert_int_equal(a.inflight, 2);
    assert_int_equal(a.width, 1280);
    assert_int_equal(a.height, 720);

    /* global options after the command, both --opt v and --opt=v */
    assert_int_equal(parse(&a, err, "render", "bun000", "-o", "x.png", "--host=10.0.0.2",
                           "--port", "9000", "--set", "quality=90", "--set=pipeline=points",
                           "--eye", "-1,2.5,3e2", "--size", "640x480", "--fov", "30", NULL), 0);
    assert_string_equal(a.command, "render");
    assert_string_equal(a.name, "bun000");
    assert_string_equal(a.output, "x.png");
    assert_string_equal(a.host, "10.0.0.2");
    assert_int_equal(a.port, 9000);
    assert_int_equal(a.nsets, 2);
    assert_string_equal(a.sets[0], "quality=90");
    assert_string_equal(a.sets[1], "pipeline=points");
    assert_true(a.have_eye && a.eye[0] == -1 && a.eye[1] == 2.5 && a.eye[2] == 300);
    assert_int_equal(a.width, 640);
    assert_int_equal(a.height, 480);
    assert_true(a.have_fov && a.fov == 30.0f);

    assert_int_equal(parse(&a, err, "--token-file", "/t", "path", "g", "--orbit", "36", "-o",
                           "o/%05d.jpg", "--inflight", "4", "--force", NULL), 0);
    assert_int_equal(a.orbit, 36);
    assert_int_equal(a.inflight, 4);
    assert_int_equal(a.force, 1);
    assert_string_equal(a.token_file, "/t");

    /* --help anywhere answers before the rest is checked, and names the command for its help */
    assert_int_equal(parse(&a, err, "render", "--help", NULL), 0);
    assert_int_equal(a.help, 1);
    assert_string_equal(a.command, "render");
    assert_int_equal(parse(&a, err, "-h", "--bogus", "path", NULL), 0);
    assert_int_equal(a.help, 1);
    assert_string_equal(a.command, "path");
    assert_int_equal(parse(&a, err, "--help", NULL), 0);
    assert_null(a.command);
    assert_int_equal(parse(&a, err, "--version", NULL), 0);
    assert_int_equal(a.version, 1);
    assert_int_equal(a.help, 0);
    /* after "--" it is an operand, not an option */
    assert_int_equal(parse(&a, err, "info", "--", "--help", NULL), 0);
    assert_int_equal(a.help, 0);
    assert_string_equal(a.name, "--help");

    struct { const char *args[10]; const char *needle; } bad[] = {
        {{NULL}, "no command"},
        {{"frobnicate", NULL}, "unknown command"},
        {{"list", "extra", NULL}, "no operands"},
        {{"info", NULL}, "one cloud NAME"},
        {{"render", "x", NULL}, "-o FILE"},
        {{"path", "x", "-o", "a%d.jpg", NULL}, "exactly one of"},
        {{"path", "x", "-o", "a%d.jpg", "--orbit", "3", "--path", "p", NULL}, "exactly one of"},
        {{"list", "--port", "70000", NULL}, "1 to 65535"},
        {{"list", "--port", NULL}, "needs a value"},
        {{"list", "--bogus", NULL}, "unknown option"},
        {{"list", "--eye", "1,2", NULL}, "x,y,z"},
        {{"list", "--size", "0x5", NULL}, "WxH"},
        {{"list", "--size", "640*480", NULL}, "WxH"},
        {{"list", "--inflight", "0", NULL}, "1 to 64"},
        {{"list", "--fov", "180", NULL}, "(0, 180)"},
        {{"list", "--set", "novalue", NULL}, "key=value"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char *argv[12] = {"splat"};
        int argc = 1;
        for (int k = 0; bad[i].args[k]; k++) argv[argc++] = (char *)bad[i].args[k];
        err[0] = 0;
        if (cli_parse(argc, argv, &a, err, sizeof err) != -1 || !strstr(err, bad[i].needle))
            fail_msg("case %zu: expected an error with '%s', got '%s'", i, bad[i].needle, err);
    }
}

static void test_path_lines(void **state)
{
    (void)state;
    cp_cam c;
    char err[200];
    assert_int_equal(cp_parse_line("", &c, err, sizeof err), 0);
    assert_int_equal(cp_parse_line("   # a comment\n", &c, err, sizeof err), 0);
    assert_int_equal(cp_parse_line("1 2 3  4 5 6  0 0 1  45\n", &c, err, sizeof err), 1);
    assert_true(c.eye[0] == 1 && c.eye[2] == 3 && c.target[1] == 5 && c.up[2] == 1);
    assert_true(c.fov == 45.0f);
    assert_int_equal(cp_parse_line("637000.5,851000.25,500, 0,0,0, 0,0,1, 60 # hi", &c, err,
                                   sizeof err), 1);
    assert_true(c.eye[0] == 637000.5 && c.eye[1] == 851000.25 && c.fov == 60.0f);
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1", &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "missing fov"));
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 45 7", &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "more than 10"));
    assert_int_equal(cp_parse_line("1 2 x 4 5 6 0 0 1 45", &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "eye z"));
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 200", &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "fov"));
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 nan", &c, err, sizeof err), -1);
    /* The fov range is open at both ends, (0, 180): 0 and 180 are refused, values just inside
     * are taken. */
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 0", &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "fov 0 is out of range"));
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 180", &c, err, sizeof err), -1);
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 0.5", &c, err, sizeof err), 1);
    assert_true(c.fov == 0.5f);
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 179.5", &c, err, sizeof err), 1);
    assert_true(c.fov == 179.5f);
    assert_int_equal(cp_parse_line("1 2 3 4 5 6 0 0 1 45abc", &c, err, sizeof err), -1);

    char dir[256], path[300];
    tu_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/cams.txt", dir);
    const char *txt = "# orbit\n0 0 10 0 0 0 0 1 0 45\n\n1,1,1, 0,0,0, 0,0,1, 30\n";
    tu_write_file(path, txt, strlen(txt));
    cp_cam *cams;
    size_t n;
    assert_int_equal(cp_load(path, &cams, &n, err, sizeof err), 0);
    assert_int_equal(n, 2);
    assert_true(cams[0].eye[2] == 10 && cams[1].fov == 30.0f);
    free(cams);
    const char *bad = "0 0 10 0 0 0 0 1 0 45\n# two\n0 0 10 0 0 0 0 1 0\n";
    tu_write_file(path, bad, strlen(bad));
    assert_int_equal(cp_load(path, &cams, &n, err, sizeof err), -1);
    assert_non_null(strstr(err, ":3:")); /* the line number */
    assert_null(cams);
    tu_write_file(path, "# nothing\n", 10);
    assert_int_equal(cp_load(path, &cams, &n, err, sizeof err), -1);
    assert_non_null(strstr(err, "no cameras"));
    snprintf(path, sizeof path, "%s/missing.txt", dir);
    assert_int_equal(cp_load(path, &cams, &n, err, sizeof err), -1);
    assert_non_null(strstr(err, "missing.txt"));
    tu_rm_rf(dir);
}

static void test_patterns(void **state)
{
    (void)state;
    char out[64], err[200];
    assert_int_equal(cp_expand("out/%05d.jpg", 7, out, sizeof out), 0);
    assert_string_equal(out, "out/00007.jpg");
    assert_int_equal(cp_expand("f%d.png", 123456, out, sizeof out), 0);
    assert_string_equal(out, "f123456.png");
    assert_int_equal(cp_expand("100%%_%3d.exr", 5, out, sizeof out), 0);
    assert_string_equal(out, "100%_  5.exr");
    assert_int_equal(cp_expand("a%05d", 123456, out, sizeof out), 0); /* wider than 5: all digits */
    assert_string_equal(out, "a123456");
    assert_int_equal(cp_expand("%05d", 1, out, 5), -1);  /* needs 6 bytes */
    assert_int_equal(cp_expand("%05d", 1, out, 6), 0);
    assert_int_equal(cp_expand("%05d", -1, out, sizeof out), -1);
    assert_int_equal(cp_pattern_check("x.jpg", err, sizeof err), -1);
    assert_non_null(strstr(err, "has 0"));
    assert_int_equal(cp_pattern_check("%d_%d.jpg", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("%s.jpg", err, sizeof err), -1); /* never handed to printf */
    assert_int_equal(cp_pattern_check("%n%d.jpg", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("%-5d.jpg", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("%99d.jpg", err, sizeof err), -1);
    /* campath.h: a width N < 20; 19 is the widest taken, 20 the narrowest refused. */
    assert_int_equal(cp_pattern_check("%19d.jpg", err, sizeof err), 0);
    assert_int_equal(cp_pattern_check("%019d.jpg", err, sizeof err), 0);
    assert_int_equal(cp_pattern_check("%20d.jpg", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("%020d.jpg", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("%", err, sizeof err), -1);
    assert_int_equal(cp_pattern_check("d/%05d.jpg", err, sizeof err), 0);

    assert_string_equal(cp_ext_format("a/b.JPG"), "jpeg");
    assert_string_equal(cp_ext_format("b.jpeg"), "jpeg");
    assert_string_equal(cp_ext_format("b.png"), "png");
    assert_string_equal(cp_ext_format("b.exr"), "exr");
    assert_string_equal(cp_ext_format("%05d.raw"), "raw");
    assert_null(cp_ext_format("b.gif"));
    assert_null(cp_ext_format("dir.jpg/b"));
}

static void test_resume_and_write(void **state)
{
    (void)state;
    char dir[256], pat[300], name[320], err[300];
    tu_tmpdir(dir, sizeof dir);
    snprintf(pat, sizeof pat, "%s/sub/deeper/%%04d.jpg", dir);
    snprintf(name, sizeof name, "%s/sub/deeper/0000.jpg", dir);
    assert_int_equal(cp_mkdirs(name, err, sizeof err), 0);
    /* frames 1 and 3 done, frame 2 an empty file (not done) */
    for (int i = 1; i <= 3; i += 2) {
        cp_expand(pat, i, name, sizeof name);
        assert_int_equal(cp_write_file(name, "JPEG", 4, err, sizeof err), 0);
    }
    cp_expand(pat, 2, name, sizeof name);
    tu_write_file(name, "", 0);
    long todo[6];
    assert_int_equal(cp_todo(pat, 6, 0, todo), 4);
    assert_int_equal(todo[0], 0);
    assert_int_equal(todo[1], 2);
    assert_int_equal(todo[2], 4);
    assert_int_equal(todo[3], 5);
    assert_int_equal(cp_todo(pat, 6, 1, todo), 6);
    /* the written file holds exactly the bytes; no temporary file is left behind */
    cp_expand(pat, 1, name, sizeof name);
    size_t len;
    uint8_t *b = tu_read_file(name, &len);
    assert_int_equal(len, 4);
    assert_memory_equal(b, "JPEG", 4);
    free(b);
    char tmp[400];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", name, (long)getpid());
    assert_int_equal(cp_frame_done(tmp), 0);
    snprintf(name, sizeof name, "%s/no/such/dir/x.jpg", dir);
    assert_int_equal(cp_write_file(name, "x", 1, err, sizeof err), -1);
    assert_non_null(strstr(err, "x.jpg"));
    tu_rm_rf(dir);
}

static void test_progress_line(void **state)
{
    (void)state;
    char buf[200];
    /* 25 of 100 frames in 10 s: 2.5 frames/s, 75 left -> 30 s */
    cp_progress_line(buf, sizeof buf, 25, 100, 10.0, 20);
    assert_string_equal(buf, "[#####---------------]  25/100  2.5 frames/s  ETA 0:30");
    cp_progress_line(buf, sizeof buf, 0, 10, 0.0, 0);
    assert_string_equal(buf, " 0/10  0.0 frames/s  ETA --:--");
    /* 1 of 10000 in 1 s: 9999 s left = 2:46:39 */
    cp_progress_line(buf, sizeof buf, 1, 10000, 1.0, 0);
    assert_non_null(strstr(buf, "ETA 2:46:39"));
    /* Nothing to do (every frame already on disk) is complete: a full bar, not an empty one. */
    cp_progress_line(buf, sizeof buf, 0, 0, 0.0, 4);
    assert_string_equal(buf, "[####] 0/0  0.0 frames/s  ETA --:--");
}

/* The library's cameras are framing.h's on INFO's view: spc_camera_frame = sp_frame_fit and
 * spc_camera_orbit = sp_frame_orbit, at fov 45; an info filled by hand with bounds only gets
 * the z-up view of its bounds. */
static void test_cameras(void **state)
{
    (void)state;
    spc_info in = {.bmin = {-1, -2, -3}, .bmax = {1, 2, 3}};
    sp_view v;
    const double q[4] = {0, 1, 0, 0};
    sp_view_default(in.bmin, in.bmax, SP_UP_SENSOR, q, &v);
    const double hull[3][3] = {{-1, -2, 0}, {1, 0.5, 3}, {0, 2, -3}};
    sp_view_hull(&v, &hull[0][0], 3);
    in.view_npts = v.npts;
    memcpy(in.view_pts, v.pts, sizeof in.view_pts);
    memcpy(in.up, v.up, sizeof in.up);
    memcpy(in.view_dir, v.dir, sizeof in.view_dir);
    memcpy(in.view_bmin, v.bmin, sizeof in.view_bmin);
    memcpy(in.view_bmax, v.bmax, sizeof in.view_bmax);
    spc_camera cam;
    double eye[3], target[3], up[3];
    spc_camera_frame(&in, 1000, 500, &cam);
    sp_frame_fit(&v, 1000, 500, 45, eye, target, up);
    assert_memory_equal(cam.eye, eye, sizeof eye);
    assert_memory_equal(cam.target, target, sizeof target);
    assert_memory_equal(cam.up, up, sizeof up);
    assert_true(cam.fov_deg == 45.0f && cam.width == 1000 && cam.height == 500);
    for (int i = 0; i < 8; i++) {
        spc_camera_orbit(&in, NULL, i, 8, 0, 1000, 500, &cam);
        sp_frame_orbit(&v, NULL, i, 8, 1000, 500, 45, eye, target, up);
        assert_memory_equal(cam.eye, eye, sizeof eye);
        assert_memory_equal(cam.up, up, sizeof up);
    }
    const double upx[3] = {3, 0, 0};
    spc_camera_orbit(&in, upx, 1, 4, 30, 100, 100, &cam);
    sp_frame_orbit(&v, upx, 1, 4, 100, 100, 30, eye, target, up);
    assert_memory_equal(cam.eye, eye, sizeof eye);
    assert_true(cam.fov_deg == 30.0f);
    /* bounds only: z up */
    spc_info bare = {.bmin = {10, 20, 30}, .bmax = {12, 24, 36}};
    spc_camera_frame(&bare, 1280, 720, &cam);
    sp_view_default(bare.bmin, bare.bmax, SP_UP_Z, NULL, &v);
    sp_frame_fit(&v, 1280, 720, 45, eye, target, up);
    assert_memory_equal(cam.eye, eye, sizeof eye);
    assert_true(cam.up[2] == 1);
}

static void test_token_file(void **state)
{
    (void)state;
    char dir[256], path[300], err[600];
    uint8_t buf[64];
    tu_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/token", dir);
    tu_write_file(path, "s3cret\r\n", 8);
    chmod(path, 0600);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), 6);
    assert_memory_equal(buf, "s3cret", 6);
    chmod(path, 0640);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "0640"));
    assert_non_null(strstr(err, "chmod 600"));
    chmod(path, 0604);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    tu_write_file(path, "\n", 1);
    chmod(path, 0600);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "empty"));
    /* the daemon's limits (auth_token_load), at each boundary: a token of exactly the room,
     * with its line end too; one byte more; a file over the room and two bytes */
    char big[100];
    memset(big, 'k', sizeof big);
    tu_write_file(path, big, sizeof buf);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), 64);
    memcpy(big + 64, "\r\n", 2);
    tu_write_file(path, big, 66);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), 64);
    assert_memory_equal(buf, big, 64);
    big[64] = 'k';
    tu_write_file(path, big, 65);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "longer than 64"));
    memcpy(big + 64, "\n\n\n", 3);
    tu_write_file(path, big, 67);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "more than 66 bytes"));
    tu_write_file(path, big, sizeof big);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_int_equal(spc__read_token(dir, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    /* a FIFO without a writer is refused at once, not waited on */
    snprintf(path, sizeof path, "%s/fifo", dir);
    assert_int_equal(mkfifo(path, 0600), 0);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "not a regular file"));
    snprintf(path, sizeof path, "%s/none", dir);
    assert_int_equal(spc__read_token(path, buf, sizeof buf, err, sizeof err), SPC_E_TOKEN);
    tu_rm_rf(dir);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cli_parse),
        cmocka_unit_test(test_path_lines),
        cmocka_unit_test(test_patterns),
        cmocka_unit_test(test_resume_and_write),
        cmocka_unit_test(test_progress_line),
        cmocka_unit_test(test_cameras),
        cmocka_unit_test(test_token_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
