/* testutil.c — see testutil.h. */
#include "testutil.h"

#include <errno.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <cmocka.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

const char *tu_env(const char *name, const char *def)
{
    const char *v = getenv(name);
    return v && *v ? v : def;
}

const char *tu_data(const char *name, char *buf, size_t len)
{
    snprintf(buf, len, "%s/%s", tu_env("SPLATD_TESTDATA", "tests/data"), name);
    return buf;
}

uint8_t *tu_read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) != 0) { fclose(f); return NULL; }
    long sz = ftell(f);
    if (sz < 0) { fclose(f); return NULL; }
    rewind(f);
    uint8_t *b = malloc((size_t)sz + 1);
    if (b && fread(b, 1, (size_t)sz, f) != (size_t)sz) { free(b); b = NULL; }
    fclose(f);
    if (b) { b[sz] = 0; *len = (size_t)sz; }
    return b;
}

int tu_write_file(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    if (!f) return -1;
    size_t w = fwrite(data, 1, len, f);
    return (fclose(f) == 0 && w == len) ? 0 : -1;
}

const char *tu_tmpdir(char *buf, size_t len)
{
    snprintf(buf, len, "%s/splatd-test-XXXXXX", tu_env("TMPDIR", "/tmp"));
    return mkdtemp(buf);
}

void tu_rm_rf(const char *path)
{
    if (!path || !*path || strstr(path, "splatd-test-") == NULL) return; /* only our own dirs */
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", path);
    if (system(cmd) != 0) fprintf(stderr, "testutil: could not remove %s\n", path);
}

int tu_tmpdir_setup(void **state)
{
    char *d = malloc(512);
    if (!d || !tu_tmpdir(d, 512)) {
        free(d);
        return -1;
    }
    *state = d;
    return 0;
}

int tu_tmpdir_teardown(void **state)
{
    tu_rm_rf(*state);
    free(*state);
    return 0;
}

void tu_skip_reason(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    printf("tu-skip-reason: ");
    vprintf(fmt, ap);
    printf("\n");
    fflush(stdout);
    va_end(ap);
}

int tu_copy_file(const char *src, const char *dst)
{
    size_t len;
    uint8_t *b = tu_read_file(src, &len);
    if (!b) return -1;
    int rc = tu_write_file(dst, b, len);
    free(b);
    return rc;
}

int tu_send_all(int fd, const void *p, size_t n)
{
    const uint8_t *b = p;
    while (n) {
        ssize_t w = send(fd, b, n, MSG_NOSIGNAL);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        b += w;
        n -= (size_t)w;
    }
    return 0;
}

int tu_recv_all(int fd, void *p, size_t n)
{
    uint8_t *b = p;
    while (n) {
        ssize_t g = recv(fd, b, n, 0);
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0) return -1;
        b += g;
        n -= (size_t)g;
    }
    return 0;
}

int tu_run(char *out, size_t len, const char *fmt, ...)
{
    char cmd[8192];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    out[0] = 0;
    if (n < 0 || (size_t)n >= sizeof cmd) return -1;
    FILE *p = popen(cmd, "r");
    if (!p) return -1;
    size_t got = fread(out, 1, len - 1, p);
    out[got] = 0;
    while (fgetc(p) != EOF) {}
    int st = pclose(p);
    return st != -1 && WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

int tu_data_dir(const char *root, const char *src, const char *dst, char *buf, size_t len)
{
    char from[1024], to[1024];
    snprintf(buf, len, "%s/data", root);
    if (mkdir(buf, 0755) != 0) return -1;
    tu_data(src, from, sizeof from);
    snprintf(to, sizeof to, "%s/%s", buf, dst);
    return tu_copy_file(from, to);
}

double tu_now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e6 + (double)ts.tv_nsec * 1e-3;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

double tu_median(double *v, int n)
{
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

void tu_args(int argc, char **argv)
{
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (argc > 2 || (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")))) {
        fprintf(stderr, "usage: %s [PATTERN]   run the tests whose names match PATTERN "
                        "('*' and '?' wildcards); all of them without one\n", argv[0]);
        exit(argc == 2 ? 0 : 2);
    }
    if (argc == 2 && argv[1][0]) cmocka_set_test_filter(argv[1]);
}
