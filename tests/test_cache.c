/* test_cache.c — the prepared-cloud cache: hit after miss, rebuild on source/version/k change,
 * warnings and rebuilds (never a load) for truncated, grown and corrupted caches, and a sweep over
 * every byte of the cache header (damaged, or changed with a valid checksum). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "prep.h"
#include "sd_hash.h"
#include "testutil.h"

typedef struct fixture {
    char dir[512], src[600], cdir[600];
    char shm[64];       /* a directory in /dev/shm a test made, removed by the teardown */
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
    if (f->shm[0]) tu_rm_rf(f->shm);
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
static void grow_one(const char *path, off_t size) { assert_int_equal(truncate(path, size + 1), 0); }

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
    /* One byte longer than the header says is as wrong as one byte shorter. */
    damage_and_check(f, grow_one, "wrong size");
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

/* ---- every header byte, one at a time ---------------------------------------------------------
 *
 * The sweeps below do not copy the private cache_header layout of cache.c: they find the header's
 * own checksum in the file (the first 8-aligned u64 that equals sd_hash64 of every byte before
 * it, which is how cache.c defines header_hash) and then change each byte before it in turn. A
 * field added to the header later is swept without touching this test. */

/* write_tiny_ply: a 300-point ASCII PLY with a 'quality' scalar: it prepares in milliseconds (the
 * sweeps rebuild the cache hundreds of times), and its format and scalar names are non-empty
 * strings that can be found in the header by content. */
static void write_tiny_ply(const char *path)
{
    enum { N = 300 };
    char *b = malloc(80 * N + 256);
    assert_non_null(b);
    int o = sprintf(b, "ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\n"
                       "property float y\nproperty float z\nproperty float quality\nend_header\n", N);
    for (int i = 0; i < N; i++) {
        double x = 0.1 * (i % 20), y = 0.1 * (i / 20);
        o += sprintf(b + o, "%.4f %.4f %.4f %d\n", x, y, 0.05 * sin(3 * x) * cos(2 * y), i);
    }
    assert_int_equal(tu_write_file(path, b, (size_t)o), 0);
    free(b);
}

/* What a load returned, kept off the mapping (the sweeps rewrite the mapped file in place). */
typedef struct loaded {
    pc_prepared p;     /* the fields; pointers cleared */
    uint8_t *block;    /* a heap copy of the block */
} loaded;

static void keep(loaded *k, const pc_prepared *p)
{
    k->p = *p;
    k->p.pos = k->p.normal = k->p.radius = k->p.F = k->p.intensity = k->p.scalar = NULL;
    k->p.rgba = k->p.cls = NULL;
    k->p.batches = NULL;
    k->p.block = k->p.heap = k->p.map = NULL;
    k->block = malloc(p->block_len ? p->block_len : 1);
    assert_non_null(k->block);
    memcpy(k->block, p->block, p->block_len);
}

/* same_structure: the fields that say what the block is and how it was made (n, k, nbatches,
 * block_len) and the block bytes are equal. */
static int same_structure(const pc_prepared *p, const loaded *g)
{
    return p->n == g->p.n && p->k == g->p.k && p->nbatches == g->p.nbatches &&
           p->block_len == g->p.block_len && memcmp(p->block, g->block, g->p.block_len) == 0;
}

/* same_block: what was asked for (k) and the block bytes are what the real cache holds. */
static int same_block(const pc_prepared *p, const loaded *g)
{
    return p->k == g->p.k && p->block_len == g->p.block_len &&
           memcmp(p->block, g->block, g->p.block_len) == 0;
}

/* data_differs: a value the loader hands on to its caller differs: the counts, the attribute
 * bits or a summary value. A new summary field in pc_prepared must be added here (the re-hashed
 * sweep fails on it until it is). */
static int data_differs(const pc_prepared *p, const loaded *g)
{
    const pc_prepared *q = &g->p;
    return p->n != q->n || p->nbatches != q->nbatches || p->attrs != q->attrs ||
           memcmp(p->offset, q->offset, sizeof p->offset) ||
           memcmp(p->bmin, q->bmin, sizeof p->bmin) || memcmp(p->bmax, q->bmax, sizeof p->bmax) ||
           memcmp(&p->sigma, &q->sigma, sizeof p->sigma) ||
           memcmp(&p->F_raw_p99, &q->F_raw_p99, sizeof p->F_raw_p99) ||
           memcmp(p->F_pct, q->F_pct, sizeof p->F_pct) ||
           memcmp(&p->radius_median, &q->radius_median, sizeof p->radius_median) ||
           p->n_dropped != q->n_dropped || memcmp(p->format, q->format, sizeof p->format) ||
           memcmp(p->scalar_name, q->scalar_name, sizeof p->scalar_name) ||
           memcmp(&p->stats, &q->stats, sizeof p->stats);
}

/* header_hash_offset: the offset of the header's checksum (see above), 0 when none is found. */
static size_t header_hash_offset(const uint8_t *file, size_t len)
{
    for (size_t o = 8; o + 8 <= len && o + 8 <= 4096; o += 8) {
        uint64_t v;
        memcpy(&v, file + o, 8);
        if (v == sd_hash64(file, o, 0)) return o;
    }
    return 0;
}

/* terminator_of: the offset of the last byte of the NUL-padded string field of `size` bytes that
 * holds s, found by content in the header (the loader forces that byte to 0). */
static size_t terminator_of(const uint8_t *hdr, size_t hlen, const char *s, size_t size)
{
    const uint8_t *at = memmem(hdr, hlen, s, strlen(s) + 1);
    assert_non_null(at);
    return (size_t)(at - hdr) + size - 1;
}

/* Every header byte damaged in turn (the file's checksum left as it was, as a disk error or a
 * torn write leaves it) must give a warning and a rebuild that equals the real cloud, never a
 * load; cache_probe must say no to each as well. Then every header byte before the checksum
 * changed in turn WITH a valid checksum (what a cache written by another build, for another
 * k, or for another version of the source looks like): the magic, version, byte order, the
 * source's size, mtime and content hash, k, the counts and the block length and hash must each
 * make the cache be rebuilt. The summary values (bounds, offset, sigma, names, timings) are the
 * cache's data: a consistent change to one of them is loaded, and the test then requires that the
 * changed value is what the load returns, so no byte of the header may be accepted and have no
 * effect, except the two string terminators the loader forces to 0. A field added later that
 * the loader forgets to check is accepted with no effect, and fails here. */
static void test_every_header_byte(void **state)
{
    fixture *f = *state;
    snprintf(f->src, sizeof f->src, "%s/tiny.ply", f->dir);
    write_tiny_ply(f->src);
    /* The sweeps rebuild the cache ~350 times, each write fsynced: on a disk that is seconds, in
     * memory (/dev/shm, where there is one) it is milliseconds. What is checked is the same. */
    snprintf(f->shm, sizeof f->shm, "/dev/shm/splatd-test-XXXXXX");
    if (mkdtemp(f->shm)) snprintf(f->cdir, sizeof f->cdir, "%s/cache", f->shm);
    else f->shm[0] = 0;
    pc_prepared p;
    cache_result r;
    assert_int_equal(open_cloud(f, 8, &p, &r), 0);
    assert_int_equal(r.hit, 0);
    pc_prepared_free(&p);
    assert_int_equal(open_cloud(f, 8, &p, &r), 0);
    assert_int_equal(r.hit, 1);
    assert_string_equal(p.scalar_name, "quality");
    loaded good;
    keep(&good, &p);
    pc_prepared_free(&p);

    size_t flen;
    uint8_t *pristine = tu_read_file(r.path, &flen);
    assert_non_null(pristine);
    assert_true(flen > good.p.block_len);
    size_t hoff = header_hash_offset(pristine, flen - good.p.block_len);
    assert_true(hoff >= 64);
    size_t fmt_end = terminator_of(pristine, hoff, good.p.format, sizeof good.p.format);
    size_t sc_end = terminator_of(pristine, hoff, good.p.scalar_name, sizeof good.p.scalar_name);
    uint8_t *buf = malloc(flen);
    assert_non_null(buf);

    /* Damage: bytes [0, hoff + 8), the checksum itself included. */
    for (size_t i = 0; i < hoff + 8; i++) {
        memcpy(buf, pristine, flen);
        buf[i] ^= (uint8_t)(1u << (i % 8));
        assert_int_equal(tu_write_file(r.path, buf, flen), 0);
        if (cache_probe(f->src, f->cdir, 8) != 0)
            fail_msg("cache_probe accepts a cache with header byte %zu damaged", i);
        int before = f->warnings;
        assert_int_equal(open_cloud(f, 8, &p, &r), 0);
        if (r.hit || f->warnings != before + 1 || !strstr(f->last_warning, "rebuilding"))
            fail_msg("header byte %zu damaged: hit %d, %d warnings (%s)", i, r.hit,
                     f->warnings - before, f->last_warning);
        /* The rebuild is the real cloud (its timings differ, so not data_differs). */
        assert_true(same_structure(&p, &good));
        assert_int_equal(p.attrs, good.p.attrs);
        assert_string_equal(p.format, good.p.format);
        pc_prepared_free(&p);
    }

    /* Changed with a valid checksum: bytes [0, hoff). Re-hashing the unchanged header gives the
     * file's own checksum back, so a rejection below comes from the changed byte alone. */
    memcpy(buf, pristine, flen);
    uint64_t hh = sd_hash64(buf, hoff, 0);
    memcpy(buf + hoff, &hh, 8);
    assert_memory_equal(buf, pristine, flen);
    int accepted = 0, rejected = 0, counts_off = 0;
    for (size_t i = 0; i < hoff; i++) {
        memcpy(buf, pristine, flen);
        buf[i] ^= (uint8_t)(1u << (i % 8));
        hh = sd_hash64(buf, hoff, 0);
        memcpy(buf + hoff, &hh, 8);
        assert_int_equal(tu_write_file(r.path, buf, flen), 0);
        assert_int_equal(open_cloud(f, 8, &p, &r), 0);
        if (!r.hit) {
            rejected++;
            if (!same_structure(&p, &good))
                fail_msg("header byte %zu changed: the rebuilt cloud differs from the real one", i);
        } else {
            accepted++;
            if (!same_block(&p, &good))
                fail_msg("header byte %zu changed with a valid checksum: the cache was loaded with "
                         "another k or another block (k %u, asked 8)", i, p.k);
            /* The point and batch counts are bounded by the file and checked against the
             * batches, which tile [0, n): a count a little off (300 -> 301, inside a section's
             * alignment padding) or with its top bit set (the block length it implies wraps
             * around to the same value) must not be loaded as it is. */
            if (p.n != good.p.n || p.nbatches != good.p.nbatches) {
                counts_off++;
                fail_msg("cache header byte %zu changed with a valid checksum was loaded with "
                         "n = %llu, nbatches = %llu (real: %llu, %llu)", i,
                         (unsigned long long)p.n, (unsigned long long)p.nbatches,
                         (unsigned long long)good.p.n, (unsigned long long)good.p.nbatches);
            }
            if (!data_differs(&p, &good) && i != fmt_end && i != sc_end)
                fail_msg("header byte %zu changed with a valid checksum: the cache was loaded and "
                         "the change shows nowhere in what it returned, so the byte is a field the "
                         "loader neither checks nor uses (a key like the source's size, mtime or "
                         "hash, the version, k, the magic or byte order; or a new summary field "
                         "data_differs does not compare yet)", i);
        }
        pc_prepared_free(&p);
    }
    print_message("cache header: %zu bytes; re-hashed one-byte changes: %d rebuilt, %d loaded "
                  "as data (%d of them a point or batch count)\n", hoff, rejected, accepted, counts_off);
    assert_true(rejected > 0 && accepted > 0);
    free(buf);
    free(pristine);
    free(good.block);
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

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_miss_then_hit, setup, teardown),
        cmocka_unit_test_setup_teardown(test_source_changes_rebuild, setup, teardown),
        cmocka_unit_test_setup_teardown(test_truncated_cache, setup, teardown),
        cmocka_unit_test_setup_teardown(test_probe, setup, teardown),
        cmocka_unit_test_setup_teardown(test_corrupted_cache, setup, teardown),
        cmocka_unit_test_setup_teardown(test_version_change, setup, teardown),
        cmocka_unit_test_setup_teardown(test_every_header_byte, setup, teardown),
        cmocka_unit_test_setup_teardown(test_unwritable_cache_dir, setup, teardown),
        cmocka_unit_test_setup_teardown(test_missing_source, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
