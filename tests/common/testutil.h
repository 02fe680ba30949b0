/* testutil.h — small helpers shared by the tests (files, temporary directories, data paths). */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* tu_data: path of a file in tests/data (from $SPLATD_TESTDATA, else "tests/data"). Static buffer
 * per call site is not used: the result is written to buf. */
const char *tu_data(const char *name, char *buf, size_t len);

/* tu_read_file: whole file into a malloc'd buffer; *len set. NULL on failure. */
uint8_t *tu_read_file(const char *path, size_t *len);

/* tu_copy_file: copies the file src to dst; 0 on success. */
int tu_copy_file(const char *src, const char *dst);

/* tu_write_file: writes len bytes to path; 0 on success. */
int tu_write_file(const char *path, const void *data, size_t len);

/* tu_tmpdir: creates a fresh directory under $TMPDIR (or /tmp) and writes its path to buf. */
const char *tu_tmpdir(char *buf, size_t len);

/* tu_rm_rf: removes a directory tree made by tu_tmpdir. */
void tu_rm_rf(const char *path);

/* tu_env: getenv with a default. */
const char *tu_env(const char *name, const char *def);

/* tu_tmpdir_setup / tu_tmpdir_teardown: cmocka setup and teardown giving each test a fresh
 * directory (a malloc'd path) in *state, removed even when the test fails. */
int tu_tmpdir_setup(void **state);
int tu_tmpdir_teardown(void **state);

/* TU_SKIP: skips the current cmocka test, naming why the check is impossible on this machine.
 * tests/run.sh counts skips and fails `make test` on a skip that names no reason, so every skip
 * must go through this macro (the reason goes to stdout on a line of its own, which run.sh
 * pairs with the test it belongs to). Needs <cmocka.h> included before use. */
#define TU_SKIP(...)                                                   \
    do {                                                               \
        tu_skip_reason(__VA_ARGS__);                                   \
        skip();                                                        \
    } while (0)
void tu_skip_reason(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* tu_send_all, tu_recv_all: send or receive exactly n bytes on socket fd, retrying after
 * EINTR (send with MSG_NOSIGNAL). 0, or -1 on an error, EOF or the socket's timeout. */
int tu_send_all(int fd, const void *p, size_t n);
int tu_recv_all(int fd, void *p, size_t n);

/* tu_run: runs a shell command (printf-style), its stdout and stderr (as the command redirects
 * them) into out, NUL-terminated and truncated to len. Returns the exit status, or -1 when it
 * did not exit normally or could not start. */
int tu_run(char *out, size_t len, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* tu_data_dir: makes root/data holding tests/data/src as dst (a daemon's data directory with one
 * cloud), its path in buf. Returns 0, or -1 when it could not. */
int tu_data_dir(const char *root, const char *src, const char *dst, char *buf, size_t len);
/* tu_now_us: CLOCK_MONOTONIC in microseconds. */
double tu_now_us(void);

/* tu_median: the median of the n values v (reordered in place); the mean of the middle two
 * for even n; 0 when n is 0. */
double tu_median(double *v, int n);

/* tu_args: the command line every test program takes, called first in main:
 *   test_x [PATTERN]    runs the tests whose names match PATTERN (cmocka's filter: '*' and '?'
 *                       wildcards), all of them without one; --help prints this.
 * tests/run.sh passes a pattern given as PROGRAM:PATTERN (make test T=test_x:pattern). */
void tu_args(int argc, char **argv);
