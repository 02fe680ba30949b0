/* test_cache.c — the prepared-cloud cache: hit after miss, rebuild on source/version/k change,
 * warnings and rebuilds (never a load) for truncated and corrupted caches. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "prep.h"
#include "testutil.h"

typedef struct fixture {
    char dir[512], src[600], cdir[600];
    int warnings;
    char last_warning[600];
} fixture;

static void on_warn(void *user, const char *msg)
{
    fixture *f = user;
    f->warnings++;
    snprintf(f->last_warning, sizeof f->last_warning, "%s", msg);
}

static int setup(void **state)
{
    fixture *f = calloc(1, sizeof *f);
    char data[512];
    if (!tu_tmpdir(f->dir, sizeof f->dir)) return -1;
    snprintf(f->src, sizeof f->src, "%s/bunny.pts", f->dir);
    snprintf(f->cdir, sizeof f->cdir, "%s/cache", f->dir);
    size_t len;
    uint8_t *b = tu_read_file(tu_data("bunnyData.pts", data, sizeof data), &len);
    if (!b || tu_write_file(f->src, b, len) != 0) return -1;
    free(b);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fixture *f = *state;
    tu_rm_rf(f->dir);
    free(f);
    return 0;
}

static int open_cloud(fixture *f, int k, pc_prepared *p, cache_result *r)
{
    cache_desc d = {.dir = f->cdir, .k = k, .warn = on_warn, .user = f};
    sd_err err = {0};
    int rc = cache_open_cloud(f->src, &d, p, r, &err);
    if (rc < 0) fprintf(stderr, "cache_open_cloud: %s\n", err.msg);
    return rc;
}

/* Compares everything a renderer would use of two prepared clouds. */
static void assert_same_cloud(const pc_prepared *a, const pc_prepared *b)
{
    assert_memory_equal(a->block, b->block, b->block_len);
    if (a->n == 0) return; /* a: a bare copy of a block (damage_and_check) */
    assert_int_equal(a->n, b->n);
    assert_int_equal(a->attrs, b->attrs);
    assert_int_equal(a->block_len, b->block_len);
    assert_memory_equal(a->block, b->block, a->block_len);
    assert_memory_equal(a->offset, b->offset, sizeof a->offset);
    assert_true(a->sigma == b->sigma);
    assert_string_equal(a->format, b->format);
}

static void test_miss_then_hit(void **state)
{
    fixture *f = *state;
    pc_prepared a, b;
    cache_result ra, rb;
    assert_int_equal(open_cloud(f, 24, &a, &ra), 0);
    assert_int_equal(ra.hit, 0);
    assert_string_equal(ra.why, "no cache");
    assert_int_equal(a.n, 30571); /* bunnyData.pts: SOURCES.md */
    assert_non_null(a.heap);
    assert_int_equal(open_cloud(f, 24, &b, &rb), 0);
    assert_int_equal(rb.hit, 1);
    assert_non_null(b.map);       /* mmapped, not re-prepared */
    assert_null(b.heap);
    assert_same_cloud(&a, &b);
    assert_int_equal(f->warnings, 0);
    pc_prepared_free(&a);
    pc_prepared_free(&b);
    pc_prepared_free(&b); /* safe twice */

    /* another k is another cache entry */
    assert_int_equal(open_cloud(f, 8, &a, &ra), 0);
    assert_int_equal(ra.hit, 0);
    assert_int_equal(a.k, 8);
    pc_prepared_free(&a);
}

static void test_source_changes_rebuild(void **state)
{
    fixture *f = *state;
    pc_prepared p;
    cache_result r;
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    pc_prepared_free(&p);

    /* mtime only */
    struct timespec ts[2] = {{.tv_sec = 1000000000, .tv_nsec = 0}, {.tv_sec = 1000000000, .tv_nsec = 0}};
    assert_int_equal(utimensat(AT_FDCWD, f->src, ts, 0), 0);
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    assert_non_null(strstr(r.why, "source changed"));
    pc_prepared_free(&p);
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 1);
    pc_prepared_free(&p);

    /* content only: same size, same mtime, one digit changed in the last row */
    size_t len;
    uint8_t *b = tu_read_file(f->src, &len);
    assert_non_null(b);
    size_t i = len - 1;
    while (i > 0 && !(b[i] >= '0' && b[i] <= '8')) i--;
    b[i]++;
    assert_int_equal(tu_write_file(f->src, b, len), 0);
    free(b);
    assert_int_equal(utimensat(AT_FDCWD, f->src, ts, 0), 0);
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    assert_non_null(strstr(r.why, "source changed"));
    assert_int_equal(f->warnings, 0); /* an out-of-date cache is not a warning */
    pc_prepared_free(&p);
}

/* Damages the cache file with fn, then checks the next open warns, rebuilds and is valid. */
static void damage_and_check(fixture *f, void (*fn)(const char *path, off_t size),
                             const char *expect)
{
    pc_prepared good, p;
    cache_result r;
    assert_int_equal(open_cloud(f, 24, &good, &r), 0);
    /* good may be a mapping of the very file damaged below: keep a heap copy to compare with.
     * (splatd itself only ever replaces cache files by rename, never in place.) */
    void *copy = malloc(good.block_len);
    assert_non_null(copy);
    memcpy(copy, good.block, good.block_len);
    pc_prepared_free(&good);
    good.block = copy;
    struct stat st;
    assert_int_equal(stat(r.path, &st), 0);
    fn(r.path, st.st_size);
    int before = f->warnings;
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    assert_int_equal(f->warnings, before + 1);
    assert_non_null(strstr(f->last_warning, expect));
    assert_non_null(strstr(f->last_warning, "rebuilding"));
    assert_same_cloud(&good, &p);
    pc_prepared_free(&p);
    /* and the rebuilt cache is used again */
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 1);
    assert_same_cloud(&good, &p);
    pc_prepared_free(&p);
    free(copy);
}

static void truncate_half(const char *path, off_t size) { assert_int_equal(truncate(path, size / 2), 0); }
static void truncate_one(const char *path, off_t size) { assert_int_equal(truncate(path, size - 1), 0); }
static void truncate_header(const char *path, off_t size) { assert_int_equal(truncate(path, 100), 0); }

static void flip_byte(const char *path, off_t at)
{
    int fd = open(path, O_RDWR);
    assert_true(fd >= 0);
    uint8_t c;
    assert_int_equal(pread(fd, &c, 1, at), 1);
    c ^= 0x40;
    assert_int_equal(pwrite(fd, &c, 1, at), 1);
    close(fd);
}
static void corrupt_data(const char *path, off_t size) { flip_byte(path, size - size / 3); }
static void corrupt_header(const char *path, off_t size) { flip_byte(path, 40); }

static void test_truncated_cache(void **state)
{
    fixture *f = *state;
    damage_and_check(f, truncate_half, "truncated");
    damage_and_check(f, truncate_one, "truncated");
    damage_and_check(f, truncate_header, "truncated");
}

static void test_corrupted_cache(void **state)
{
    fixture *f = *state;
    damage_and_check(f, corrupt_data, "corrupt");
    damage_and_check(f, corrupt_header, "corrupt");
}

static void test_version_change(void **state)
{
    fixture *f = *state;
    pc_prepared p;
    cache_result r;
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    pc_prepared_free(&p);
    /* a well-formed cache of another version is out of date: rebuilt without a warning */
    assert_int_equal(cache__set_version(r.path, 999), 0);
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    assert_non_null(strstr(r.why, "cache version 999"));
    assert_int_equal(f->warnings, 0);
    pc_prepared_free(&p);
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 1);
    pc_prepared_free(&p);
}

/* cache_probe (the daemon's LIST flag) says yes exactly when cache_open_cloud would load: no
 * cache, another k, a changed source, another version or a truncated file all say no. */
static void test_probe(void **state)
{
    fixture *f = *state;
    pc_prepared p;
    cache_result r;
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 0); /* no cache yet */
    assert_int_equal(open_cloud(f, 0, &p, &r), 0);        /* 0: the default k */
    pc_prepared_free(&p);
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 1);
    assert_int_equal(cache_probe(f->src, f->cdir, PREP_DEFAULT_K), 1);
    assert_int_equal(cache_probe(f->src, f->cdir, 8), 0);
    struct timespec ts[2] = {{.tv_sec = 1000000000, .tv_nsec = 0}, {.tv_sec = 1000000000, .tv_nsec = 0}};
    assert_int_equal(utimensat(AT_FDCWD, f->src, ts, 0), 0);
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 0); /* the source changed */
    assert_int_equal(open_cloud(f, 0, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    pc_prepared_free(&p);
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 1);
    assert_int_equal(cache__set_version(r.path, 999), 0);
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 0); /* another version */
    assert_int_equal(open_cloud(f, 0, &p, &r), 0);
    pc_prepared_free(&p);
    struct stat st;
    assert_int_equal(stat(r.path, &st), 0);
    truncate_one(r.path, st.st_size);
    assert_int_equal(cache_probe(f->src, f->cdir, 0), 0); /* truncated */
    char missing[700];
    snprintf(missing, sizeof missing, "%s/none.ply", f->dir);
    assert_int_equal(cache_probe(missing, f->cdir, 0), 0);
}

static void test_unwritable_cache_dir(void **state)
{
    fixture *f = *state;
    if (geteuid() == 0) {
        /* root ignores directory permissions: use a path under a regular file instead */
        snprintf(f->cdir, sizeof f->cdir, "%s/bunny.pts/cache", f->dir);
    } else {
        snprintf(f->cdir, sizeof f->cdir, "/proc/splatd-no-such-dir");
    }
    pc_prepared p;
    cache_result r;
    assert_int_equal(open_cloud(f, 24, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    assert_int_equal(p.n, 30571);
    assert_int_equal(f->warnings, 1);
    assert_non_null(strstr(f->last_warning, "continuing without a cache"));
    pc_prepared_free(&p);
}

static void test_missing_source(void **state)
{
    fixture *f = *state;
    snprintf(f->src, sizeof f->src, "%s/nope.ply", f->dir);
    pc_prepared p;
    cache_result r;
    cache_desc d = {.dir = f->cdir};
    sd_err err = {0};
    assert_int_equal(cache_open_cloud(f->src, &d, &p, &r, &err), SD_EIO);
    assert_non_null(strstr(err.msg, "nope.ply"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_miss_then_hit, setup, teardown),
        cmocka_unit_test_setup_teardown(test_source_changes_rebuild, setup, teardown),
        cmocka_unit_test_setup_teardown(test_truncated_cache, setup, teardown),
        cmocka_unit_test_setup_teardown(test_probe, setup, teardown),
        cmocka_unit_test_setup_teardown(test_corrupted_cache, setup, teardown),
        cmocka_unit_test_setup_teardown(test_version_change, setup, teardown),
        cmocka_unit_test_setup_teardown(test_unwritable_cache_dir, setup, teardown),
        cmocka_unit_test_setup_teardown(test_missing_source, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
