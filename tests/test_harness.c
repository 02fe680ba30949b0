/* test_harness.c — tests/run.sh, the runner `make test` trusts: fed scripts that print what
 * cmocka prints, it must count tests (not binaries), fail a skip that names no reason, count a
 * skip with one and list the reason, fail a binary that dies before cmocka's summary, fail one
 * that hangs (under its time limit) and close with "LABEL: N passed, N failed, N skipped". */
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

/* run: sh tests/run.sh LABEL over the scripts; its output in out, its exit status returned. */
static int run(const char *logdir, char *out, size_t len, const char *env, const char *bins)
{
    char runsh[600], cmd[4096];
    snprintf(runsh, sizeof runsh, "%s/../run.sh", tu_env("SPLATD_TESTDATA", "tests/data"));
    /* the runner's logs go under the test's directory (TEST_LOGS), removed with it; its
     * counts stay out of the enclosing make test's total (TEST_TOTALS emptied) */
    snprintf(cmd, sizeof cmd, "TEST_TOTALS= TEST_LOGS='%s/logs' %s sh '%s' fake %s 2>&1", logdir,
             env, runsh, bins);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, len - 1, p);
    out[n] = 0;
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

#define OK_LINES(name) "echo '[ RUN      ] " name "'; echo '[       OK ] " name "'\n"
#define SUMMARY "echo '[==========] 3 test(s) run.'\n"

static void test_counts_and_skips(void **state)
{
    const char *dir = *state;
    char a[700], b[700], c[700], bins[2200], out[8192];
    fake(dir, "good", OK_LINES("t1") OK_LINES("t2")
         "echo '[ RUN      ] t3'; echo 'tu-skip-reason: no GPU here'; echo '[  SKIPPED ] t3'\n"
         SUMMARY "echo '[  SKIPPED ] 1 test(s), listed below:'; echo '[  SKIPPED ] t3'\nexit 0\n",
         a, sizeof a);
    assert_int_equal(run(dir, out, sizeof out, "", a), 0);
    if (!strstr(out, "fake: 2 passed, 0 failed, 1 skipped")) fail_msg("%s", out);
    assert_non_null(strstr(out, "good t3: no GPU here"));

    /* the same skip without its reason fails the run; a failed test counts once although
     * cmocka names it twice */
    fake(dir, "bad", OK_LINES("u1")
         "echo '[ RUN      ] u2'; echo '[  SKIPPED ] u2'\n"
         "echo '[ RUN      ] u3'; echo '[  ERROR   ] --- 0x1 != 0x2'; echo '[  FAILED  ] u3'\n"
         SUMMARY "echo '[  FAILED  ] 1 test(s), listed below:'; echo '[  FAILED  ] u3'\nexit 1\n",
         b, sizeof b);
    assert_int_not_equal(run(dir, out, sizeof out, "", b), 0);
    if (!strstr(out, "fake: 1 passed, 2 failed, 0 skipped")) fail_msg("%s", out);
    assert_non_null(strstr(out, "u2: skipped WITHOUT a reason"));

    /* dying before the summary, and hanging past the limit, are failures */
    fake(dir, "dies", OK_LINES("v1") "kill -ABRT $$\n", c, sizeof c);
    snprintf(bins, sizeof bins, "'%s' '%s'", a, c);
    assert_int_not_equal(run(dir, out, sizeof out, "", bins), 0);
    if (!strstr(out, "fake: 3 passed, 1 failed, 1 skipped") || !strstr(out, "DIED"))
        fail_msg("%s", out);
    fake(dir, "hangs", OK_LINES("w1") "sleep 30\n", c, sizeof c);
    assert_int_not_equal(run(dir, out, sizeof out, "TEST_TIMEOUT=1", c), 0);
    if (!strstr(out, "TIMEOUT") || !strstr(out, "fake: 1 passed, 1 failed, 0 skipped"))
        fail_msg("%s", out);
    /* a binary that runs no test at all is a failure, not a pass */
    fake(dir, "empty", "echo '[==========] 0 test(s) run.'\nexit 0\n", c, sizeof c);
    assert_int_not_equal(run(dir, out, sizeof out, "", c), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_counts_and_skips, tu_tmpdir_setup, tu_tmpdir_teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
