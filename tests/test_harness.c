/* test_harness.c — tests/run.sh, the runner `make test` trusts: fed scripts that print what
 * cmocka prints, it must count tests (not binaries), fail a skip that names no reason, count a
 * skip with one and list the reason, fail a binary that dies before cmocka's summary, fail one
 * that hangs (under its time limit) and close with "LABEL: N passed, N failed, N skipped"; take
 * the one list of programs, a pattern per program, and run programs side by side. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include "testutil.h"

/* fake: writes an executable script NAME in dir that prints body (cmocka's lines) and exits
 * with rc (body may also run commands); returns its path in buf. */
static const char *fake(const char *dir, const char *name, const char *body, char *buf, size_t len)
{
    snprintf(buf, len, "%s/%s", dir, name);
    char text[4096];
    snprintf(text, sizeof text, "#!/bin/sh\n%s", body);
    assert_int_equal(tu_write_file(buf, text, strlen(text)), 0);
    assert_int_equal(chmod(buf, 0755), 0);
    return buf;
}

/* run: bash tests/run.sh LABEL=fake over the scripts in dir, with dir/list as the program list
 * (written by the caller); its output in out, its exit status returned. */
static int run(const char *dir, char *out, size_t len, const char *env, const char *progs)
{
    char runsh[600], cmd[4096];
    snprintf(runsh, sizeof runsh, "%s/../run.sh", tu_env("SPLATD_TESTDATA", "tests/data"));
    /* the runner's logs go under the test's directory (TEST_LOGS), removed with it; its
     * counts stay out of the enclosing make test's total (TEST_TOTALS emptied) */
    snprintf(cmd, sizeof cmd, "TEST_TOTALS= TEST_LOGS='%s/logs' TEST_LIST='%s/list' %s bash '%s' fake '%s' %s 2>&1",
             dir, dir, env, runsh, dir, progs);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, len - 1, p);
    out[n] = 0;
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* list: writes dir/list (the runner's program list) from text. */
static void list(const char *dir, const char *text)
{
    char path[600];
    snprintf(path, sizeof path, "%s/list", dir);
    assert_int_equal(tu_write_file(path, text, strlen(text)), 0);
}

#define OK_LINES(name) "echo '[ RUN      ] " name "'; echo '[       OK ] " name "'\n"
#define SUMMARY "echo '[==========] 3 test(s) run.'\n"

static void test_counts_and_skips(void **state)
{
    const char *dir = *state;
    char a[700], b[700], c[700], out[8192];
    list(dir, "# name limit flags\ngood 20\nbad 20\ndies 20\nhangs 1\nempty 20\n");
    fake(dir, "good", OK_LINES("t1") OK_LINES("t2")
         "echo '[ RUN      ] t3'; echo 'tu-skip-reason: no GPU here'; echo '[  SKIPPED ] t3'\n"
         SUMMARY "echo '[  SKIPPED ] 1 test(s), listed below:'; echo '[  SKIPPED ] t3'\nexit 0\n",
         a, sizeof a);
    assert_int_equal(run(dir, out, sizeof out, "", "good"), 0);
    if (!strstr(out, "fake: 2 passed, 0 failed, 1 skipped")) fail_msg("%s", out);
    assert_non_null(strstr(out, "good t3: no GPU here"));

    /* the same skip without its reason fails the run; a failed test counts once although
     * cmocka names it twice */
    fake(dir, "bad", OK_LINES("u1")
         "echo '[ RUN      ] u2'; echo '[  SKIPPED ] u2'\n"
         "echo '[ RUN      ] u3'; echo '[  ERROR   ] --- 0x1 != 0x2'; echo '[  FAILED  ] u3'\n"
         SUMMARY "echo '[  FAILED  ] 1 test(s), listed below:'; echo '[  FAILED  ] u3'\nexit 1\n",
         b, sizeof b);
    assert_int_not_equal(run(dir, out, sizeof out, "", "bad"), 0);
    if (!strstr(out, "fake: 1 passed, 2 failed, 0 skipped")) fail_msg("%s", out);
    assert_non_null(strstr(out, "u2: skipped WITHOUT a reason"));

    /* dying before the summary, and hanging past the limit, are failures */
    fake(dir, "dies", OK_LINES("v1") "kill -ABRT $$\n", c, sizeof c);
    assert_int_not_equal(run(dir, out, sizeof out, "", "good dies"), 0);
    if (!strstr(out, "fake: 3 passed, 1 failed, 1 skipped") || !strstr(out, "DIED"))
        fail_msg("%s", out);
    fake(dir, "hangs", OK_LINES("w1") "sleep 30\n", c, sizeof c);
    assert_int_not_equal(run(dir, out, sizeof out, "", "hangs"), 0);
    if (!strstr(out, "TIMEOUT") || !strstr(out, "fake: 1 passed, 1 failed, 0 skipped"))
        fail_msg("%s", out);
    /* TEST_TIMEOUT_SCALE stretches every limit: 1 s x 40 outlasts a 2 s program */
    fake(dir, "hangs", OK_LINES("w1") "sleep 2\n" SUMMARY, c, sizeof c);
    assert_int_equal(run(dir, out, sizeof out, "TEST_TIMEOUT_SCALE=40", "hangs"), 0);
    /* a program that runs no test at all is a failure, not a pass */
    fake(dir, "empty", "echo '[==========] 0 test(s) run.'\nexit 0\n", c, sizeof c);
    assert_int_not_equal(run(dir, out, sizeof out, "", "empty"), 0);
}

/* The list is the one list: a program built but not listed fails the whole run (before any
 * program starts); a name not in the list is refused. */
static void test_list_is_complete(void **state)
{
    const char *dir = *state;
    char a[700], out[8192];
    fake(dir, "test_one", OK_LINES("t1") SUMMARY, a, sizeof a);
    fake(dir, "test_two", OK_LINES("t1") SUMMARY, a, sizeof a);
    list(dir, "test_one 20\n");
    assert_int_not_equal(run(dir, out, sizeof out, "", ""), 0);
    if (!strstr(out, "test_two is not in tests/list")) fail_msg("%s", out);
    assert_int_not_equal(run(dir, out, sizeof out, "", "test_two"), 0);
    list(dir, "test_one 20\ntest_two 20\n");
    assert_int_equal(run(dir, out, sizeof out, "", ""), 0);
    if (!strstr(out, "fake: 2 passed, 0 failed, 0 skipped")) fail_msg("%s", out);
}

/* PROGRAM:PATTERN hands the pattern to the program as its one argument (tu_args). */
static void test_pattern_reaches_program(void **state)
{
    const char *dir = *state;
    char a[700], out[8192];
    list(dir, "echoarg 20\n");
    fake(dir, "echoarg", "echo \"[ RUN      ] got_$1\"; echo \"[       OK ] got_$1\"\n" SUMMARY,
         a, sizeof a);
    assert_int_equal(run(dir, out, sizeof out, "", "'echoarg:lod*x'"), 0);
    char log[700];
    snprintf(log, sizeof log, "%s/logs/echoarg.log", dir);
    size_t n = 0;
    char *text = (char *)tu_read_file(log, &n);
    assert_non_null(text);
    if (!strstr(text, "got_lod*x")) fail_msg("%.*s", (int)n, text);
    free(text);
}

/* Programs run side by side: three that each sleep 2 s end in well under 6 s with TEST_JOBS=3,
 * while `alone` ones run one at a time (two alone programs of 2 s take at least 4 s). */
static void test_parallel_and_alone(void **state)
{
    const char *dir = *state;
    char a[700], out[8192];
    list(dir, "p1 20\np2 20\np3 20\n");
    for (int i = 1; i <= 3; i++) {
        char name[8];
        snprintf(name, sizeof name, "p%d", i);
        fake(dir, name, OK_LINES("t") "sleep 2\n" SUMMARY, a, sizeof a);
    }
    double t0 = tu_now_us();
    assert_int_equal(run(dir, out, sizeof out, "TEST_JOBS=3", ""), 0);
    double secs = (tu_now_us() - t0) / 1e6;
    if (!(secs < 5.0) || !strstr(out, "fake: 3 passed")) fail_msg("%.1f s\n%s", secs, out);
    list(dir, "p1 20 alone\np2 20 alone\np3 20\n");
    t0 = tu_now_us();
    assert_int_equal(run(dir, out, sizeof out, "TEST_JOBS=3", ""), 0);
    secs = (tu_now_us() - t0) / 1e6;
    if (!(secs >= 4.0)) fail_msg("alone programs overlapped: %.1f s\n%s", secs, out);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_counts_and_skips, tu_tmpdir_setup, tu_tmpdir_teardown),
        cmocka_unit_test_setup_teardown(test_list_is_complete, tu_tmpdir_setup, tu_tmpdir_teardown),
        cmocka_unit_test_setup_teardown(test_pattern_reaches_program, tu_tmpdir_setup, tu_tmpdir_teardown),
        cmocka_unit_test_setup_teardown(test_parallel_and_alone, tu_tmpdir_setup, tu_tmpdir_teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
