/* test_fuzz_regress.c — replays the fuzz corpus and every saved crash through the fuzz target
 * bodies (tests/common/fuzz_targets.c), so what the fuzzers found stays fixed without clang.
 *
 *   tests/fuzz/corpus/<target>/NAME   hand-made seeds: valid ones must be accepted (code 0),
 *                                     those named bad_* rejected (a negative code);
 *   tests/fuzz/crashes/<target>/NAME  inputs a fuzzer once crashed on: must not crash now.
 *
 * Each valid seed is also cut at every length and mutated a few hundred times with a fixed
 * random sequence, a small deterministic fuzz run that needs no libFuzzer. The fuzz directory
 * is $SPLATD_FUZZ_DIR, else $SPLATD_TESTDATA/../fuzz, else tests/fuzz. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fuzz_targets.h"
#include "testutil.h"

#define MAX_FILES 512
#define MUTATIONS 1000 /* per valid seed: about 0.5 s in all without ASan, 4 s with it */

static const char *const targets[] = {"proto", "ply", "pcd", "las", "xyz", "lzf", "params",
                                      "ws", "laz", "copc", "cache", "frame", "dispatch",
                                      "e57", "e57xml", "e57bits", "splod",
                                      "copclevels", "lodsrc", "campath", "shard", "token",
                                      "mpimsg"};

/* find: fuzz_target_find, and the dispatch target, which only binaries linking the whole
 * server have (this one does). */
static fuzz_fn find(const char *name)
{
    return strcmp(name, "dispatch") ? fuzz_target_find(name) : fuzz_one_dispatch;
}

/* The fuzz directory (see the file comment) into buf. */
static const char *fuzz_dir(char *buf, size_t len)
{
    const char *d = getenv("SPLATD_FUZZ_DIR");
    if (d && *d) snprintf(buf, len, "%s", d);
    else if ((d = getenv("SPLATD_TESTDATA")) && *d) snprintf(buf, len, "%s/../fuzz", d);
    else snprintf(buf, len, "tests/fuzz");
    return buf;
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* list_files: the names of the plain entries of dir, sorted, malloc'd into names; returns the
 * count, or -1 when dir cannot be opened. */
static int list_files(const char *dir, char **names, int max)
{
    DIR *d = opendir(dir);
    if (!d) return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL && n < max) {
        if (e->d_name[0] == '.') continue;
        names[n++] = strdup(e->d_name);
    }
    closedir(d);
    qsort(names, (size_t)n, sizeof *names, cmp_str);
    return n;
}

static void free_names(char **names, int n)
{
    for (int i = 0; i < n; i++) free(names[i]);
}

/* xorshift64: a fixed pseudo-random sequence, so that every run mutates the same way. */
static uint64_t next_rand(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s;
}

/* mutate_and_run: every prefix of data, then MUTATIONS copies with 1-4 random edits (byte
 * set, bit flip, interesting value, byte inserted or deleted), each through fn. Only a crash
 * or an oracle's abort() can fail this; the codes are not checked. */
static void mutate_and_run(fuzz_fn fn, const uint8_t *data, size_t len, uint64_t seed)
{
    for (size_t k = 0; k < len; k++) (void)fn(data, k);
    uint8_t *buf = malloc(len + 8);
    assert_non_null(buf);
    uint64_t s = seed | 1;
    static const uint8_t interesting[] = {0x00, 0x01, 0x7f, 0x80, 0xff, '\n', ' ', '-', '9'};
    for (int m = 0; m < MUTATIONS; m++) {
        size_t n = len;
        memcpy(buf, data, len);
        int edits = 1 + (int)(next_rand(&s) % 4);
        for (int k = 0; k < edits && n > 0; k++) {
            size_t at = (size_t)(next_rand(&s) % n);
            switch (next_rand(&s) % 5) {
            case 0: buf[at] = (uint8_t)next_rand(&s); break;
            case 1: buf[at] ^= (uint8_t)(1u << (next_rand(&s) % 8)); break;
            case 2: buf[at] = interesting[next_rand(&s) % sizeof interesting]; break;
            case 3:
                if (n < len + 8) {
                    memmove(buf + at + 1, buf + at, n - at);
                    buf[at] = interesting[next_rand(&s) % sizeof interesting];
                    n++;
                }
                break;
            default:
                memmove(buf + at, buf + at + 1, n - at - 1);
                n--;
                break;
            }
        }
        (void)fn(buf, n);
    }
    free(buf);
}

/* run_corpus: every seed of one target; valid ones must give 0, bad_* ones a negative code. */
static void run_corpus(const char *target)
{
    fuzz_fn fn = find(target);
    assert_non_null(fn);
    char root[512], dir[600], path[1200];
    fuzz_dir(root, sizeof root);
    snprintf(dir, sizeof dir, "%s/corpus/%s", root, target);
    char *names[MAX_FILES];
    int n = list_files(dir, names, MAX_FILES);
    if (n < 0) fail_msg("cannot open the seed directory %s", dir);
    int good = 0, bad = 0;
    for (int i = 0; i < n; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        size_t len = 0;
        uint8_t *data = tu_read_file(path, &len);
        if (!data) fail_msg("cannot read %s", path);
        int rc = fn(data, len);
        if (!strncmp(names[i], "bad_", 4)) {
            if (rc >= 0) fail_msg("%s: a bad_ seed was accepted (code %d)", path, rc);
            bad++;
        } else {
            if (rc != 0) fail_msg("%s: a valid seed was rejected with code %d", path, rc);
            good++;
            /* The dispatch target serves each input for up to a second: its seeds are
             * replayed as they are (the fuzzer mutates them). */
            if (strcmp(target, "dispatch"))
                mutate_and_run(fn, data, len, 0x9E3779B97F4A7C15ull ^ (uint64_t)(i + 1) * 7919u);
        }
        free(data);
    }
    free_names(names, n);
    print_message("%s: %d valid and %d bad seeds\n", target, good, bad);
    /* Without seeds of both kinds this test would pass on an empty directory. */
    assert_true(good >= 3);
    assert_true(bad >= 1);
}

static void test_corpus_proto(void **state) { (void)state; run_corpus("proto"); }
static void test_corpus_ply(void **state) { (void)state; run_corpus("ply"); }
static void test_corpus_pcd(void **state) { (void)state; run_corpus("pcd"); }
static void test_corpus_las(void **state) { (void)state; run_corpus("las"); }
static void test_corpus_xyz(void **state) { (void)state; run_corpus("xyz"); }
static void test_corpus_lzf(void **state) { (void)state; run_corpus("lzf"); }
static void test_corpus_params(void **state) { (void)state; run_corpus("params"); }
static void test_corpus_ws(void **state) { (void)state; run_corpus("ws"); }
static void test_corpus_laz(void **state) { (void)state; run_corpus("laz"); }
static void test_corpus_copc(void **state) { (void)state; run_corpus("copc"); }
static void test_corpus_cache(void **state) { (void)state; run_corpus("cache"); }
static void test_corpus_splod(void **state) { (void)state; run_corpus("splod"); }
static void test_corpus_frame(void **state) { (void)state; run_corpus("frame"); }
static void test_corpus_dispatch(void **state) { (void)state; run_corpus("dispatch"); }
static void test_corpus_e57(void **state) { (void)state; run_corpus("e57"); }
static void test_corpus_e57xml(void **state) { (void)state; run_corpus("e57xml"); }
static void test_corpus_e57bits(void **state) { (void)state; run_corpus("e57bits"); }
static void test_corpus_copclevels(void **state) { (void)state; run_corpus("copclevels"); }
static void test_corpus_lodsrc(void **state) { (void)state; run_corpus("lodsrc"); }
static void test_corpus_campath(void **state) { (void)state; run_corpus("campath"); }
static void test_corpus_shard(void **state) { (void)state; run_corpus("shard"); }
static void test_corpus_token(void **state) { (void)state; run_corpus("token"); }
static void test_corpus_mpimsg(void **state) { (void)state; run_corpus("mpimsg"); }

/* Every saved crash input, through its target: must return (any code) without crashing. */
static void test_crashes(void **state)
{
    (void)state;
    char root[512], dir[600], path[1200];
    fuzz_dir(root, sizeof root);
    /* The directory is part of the tree (its README says what goes there): when it is missing
     * the replay would pass having replayed nothing, so that is a failure. A target's own
     * subdirectory appears with its first saved crash. */
    snprintf(dir, sizeof dir, "%s/crashes/README.md", root);
    if (access(dir, R_OK) != 0) fail_msg("%s is missing: the crash replay would test nothing", dir);
    int total = 0;
    for (size_t t = 0; t < sizeof targets / sizeof targets[0]; t++) {
        snprintf(dir, sizeof dir, "%s/crashes/%s", root, targets[t]);
        char *names[MAX_FILES];
        int n = list_files(dir, names, MAX_FILES);
        for (int i = 0; i < n; i++) {
            snprintf(path, sizeof path, "%s/%s", dir, names[i]);
            size_t len = 0;
            uint8_t *data = tu_read_file(path, &len);
            if (!data) fail_msg("cannot read %s", path);
            print_message("replaying %s\n", path);
            (void)find(targets[t])(data, len);
            free(data);
            total++;
        }
        if (n > 0) free_names(names, n);
    }
    print_message("%d saved crash inputs replayed\n", total);
}

/* The oracles themselves: a few inputs with known answers, so that a target that accepted or
 * rejected everything would be caught. */
static void test_known_answers(void **state)
{
    (void)state;
    /* LZF: "abc" + back reference (len 3+2... here 1+2 = 3 bytes, 3 back) = "abcabc". */
    static const uint8_t lzf_ok[] = {6, 0, 0, 0x02, 'a', 'b', 'c', 0x20, 0x02};
    static const uint8_t lzf_short[] = {7, 0, 0, 0x02, 'a', 'b', 'c', 0x20, 0x02};
    assert_int_equal(fuzz_one_lzf(lzf_ok, sizeof lzf_ok), 0);
    assert_true(fuzz_one_lzf(lzf_short, sizeof lzf_short) < 0);
    /* params: valid, out of range, unknown. */
    assert_int_equal(fuzz_one_params((const uint8_t *)"quality=1", 9), 0);
    assert_int_equal(fuzz_one_params((const uint8_t *)"quality=0", 9), -1);
    assert_int_equal(fuzz_one_params((const uint8_t *)"qualitx=1", 9), -1);
    /* xyz: one finite point is a cloud; only a NaN point is SD_EEMPTY after pc_finalize. */
    assert_int_equal(fuzz_one_xyz((const uint8_t *)"1 2 3\n", 6), 0);
    assert_true(fuzz_one_xyz((const uint8_t *)"nan 2 3\n", 8) < 0);
    /* proto: an empty stream is fine; 16 zero bytes are a bad magic. */
    static const uint8_t zeros[17] = {1};
    assert_int_equal(fuzz_one_proto(zeros, 1), 0);
    assert_true(fuzz_one_proto(zeros, sizeof zeros) < 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_known_answers), cmocka_unit_test(test_corpus_proto),
        cmocka_unit_test(test_corpus_ply),    cmocka_unit_test(test_corpus_pcd),
        cmocka_unit_test(test_corpus_las),    cmocka_unit_test(test_corpus_xyz),
        cmocka_unit_test(test_corpus_lzf),    cmocka_unit_test(test_corpus_params),
        cmocka_unit_test(test_corpus_ws),     cmocka_unit_test(test_corpus_laz),
        cmocka_unit_test(test_corpus_copc),
        cmocka_unit_test(test_corpus_cache),  cmocka_unit_test(test_corpus_frame),
        cmocka_unit_test(test_corpus_dispatch),
        cmocka_unit_test(test_corpus_e57),    cmocka_unit_test(test_corpus_e57xml),
        cmocka_unit_test(test_corpus_e57bits),
        cmocka_unit_test(test_corpus_splod),
        cmocka_unit_test(test_corpus_copclevels), cmocka_unit_test(test_corpus_lodsrc),
        cmocka_unit_test(test_corpus_campath), cmocka_unit_test(test_corpus_shard),
        cmocka_unit_test(test_corpus_token),  cmocka_unit_test(test_corpus_mpimsg),
        cmocka_unit_test(test_crashes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
