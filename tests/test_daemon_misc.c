/* test_daemon_misc.c — unit tests of the daemon's small modules: data-directory name
 * resolution (including symlinks out of the directory), token file checks and HMAC proofs,
 * the timer heap's order, and listen-address parsing. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "auth.h"
#include "datadir.h"
#include "ev.h"
#include "net.h"
#include "common/testutil.h"
#include "testutil.h"

typedef struct dd_fixture {
    char root[512];   /* tmp root: data/ and outside/ below it */
    char data[600];
    char outside[600];
} dd_fixture;

static void touch(const char *dir, const char *name, const char *content)
{
    char p[1024];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    assert_int_equal(tu_write_file(p, content, strlen(content)), 0);
}

static void link_in(const char *dir, const char *name, const char *target)
{
    char p[1024];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    assert_int_equal(symlink(target, p), 0);
}

static int dd_setup(void **state)
{
    dd_fixture *f = calloc(1, sizeof *f);
    assert_non_null(tu_tmpdir(f->root, sizeof f->root));
    snprintf(f->data, sizeof f->data, "%s/data", f->root);
    snprintf(f->outside, sizeof f->outside, "%s/outside", f->root);
    assert_int_equal(mkdir(f->data, 0755), 0);
    assert_int_equal(mkdir(f->outside, 0755), 0);
    touch(f->data, "a.ply", "ply\n");
    touch(f->data, "b.las", "LASF");
    touch(f->data, "dup.ply", "ply\n");
    touch(f->data, "dup.pcd", "x");
    touch(f->data, "notes.txt.bak", "x");   /* unsupported extension: not listed */
    touch(f->outside, "secret.ply", "ply\n");
    char tgt[1024];
    snprintf(tgt, sizeof tgt, "%s/secret.ply", f->outside);
    link_in(f->data, "escape.ply", tgt);           /* absolute link out of the dir */
    link_in(f->data, "rel_escape.ply", "../outside/secret.ply"); /* relative link out */
    link_in(f->data, "alias.ply", "a.ply");        /* link inside: allowed */
    link_in(f->data, "dangling.ply", "nothere.ply");
    char sub[700];
    snprintf(sub, sizeof sub, "%s/dir.ply", f->data); /* a directory with a cloud's extension */
    assert_int_equal(mkdir(sub, 0755), 0);
    *state = f;
    return 0;
}

static int dd_teardown(void **state)
{
    dd_fixture *f = *state;
    tu_rm_rf(f->root);
    free(f);
    return 0;
}

static void expect_refused(const char *dir, const char *name, int code, dd_why why)
{
    char path[PATH_MAX];
    dd_why w = DD_OK;
    sd_err e = {0};
    int rc = dd_resolve(dir, name, path, sizeof path, &w, &e);
    if (rc != code || w != why)
        fail_msg("dd_resolve('%s') = %d why %d, want %d why %d (%s)", name, rc, (int)w, code, (int)why, e.msg);
    assert_true(strlen(e.msg) > 10);
}

static void test_resolve_accepts(void **state)
{
    dd_fixture *f = *state;
    char path[PATH_MAX], want[PATH_MAX + 16], rdata[PATH_MAX];
    dd_why w;
    assert_non_null(realpath(f->data, rdata));
    snprintf(want, sizeof want, "%s/a.ply", rdata);
    assert_int_equal(dd_resolve(f->data, "a.ply", path, sizeof path, &w, NULL), 0);
    assert_string_equal(path, want);
    /* A name without extension finds the unique NAME.ext. */
    assert_int_equal(dd_resolve(f->data, "a", path, sizeof path, &w, NULL), 0);
    assert_string_equal(path, want);
    /* A symlink that stays inside resolves to its target. */
    assert_int_equal(dd_resolve(f->data, "alias.ply", path, sizeof path, &w, NULL), 0);
    assert_string_equal(path, want);
    snprintf(want, sizeof want, "%s/b.las", rdata);
    assert_int_equal(dd_resolve(f->data, "b", path, sizeof path, &w, NULL), 0);
    assert_string_equal(path, want);
}

static void test_resolve_refuses(void **state)
{
    dd_fixture *f = *state;
    expect_refused(f->data, "../outside/secret.ply", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "..", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, ".", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "/etc/passwd", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "sub/a.ply", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "a\nb.ply", SD_EINVAL, DD_BAD_NAME);
    expect_refused(f->data, "escape.ply", SD_EINVAL, DD_OUTSIDE);
    expect_refused(f->data, "rel_escape.ply", SD_EINVAL, DD_OUTSIDE);
    expect_refused(f->data, "escape", SD_EINVAL, DD_OUTSIDE);
    expect_refused(f->data, "missing.ply", SD_ENOTFOUND, DD_NOT_FOUND);
    expect_refused(f->data, "missing", SD_ENOTFOUND, DD_NOT_FOUND);
    expect_refused(f->data, "dangling.ply", SD_ENOTFOUND, DD_NOT_FOUND);
    expect_refused(f->data, "dup", SD_EINVAL, DD_AMBIGUOUS);
    expect_refused(f->data, "dir.ply", SD_EINVAL, DD_NOT_CLOUD);
    char longname[300];
    memset(longname, 'x', sizeof longname - 1);
    longname[sizeof longname - 1] = 0;
    expect_refused(f->data, longname, SD_EINVAL, DD_BAD_NAME);
}

static void test_list(void **state)
{
    dd_fixture *f = *state;
    dd_entry *v;
    size_t n;
    assert_int_equal(dd_list(f->data, &v, &n, NULL), 0);
    /* a.ply, alias.ply, b.las, dup.pcd, dup.ply: sorted; escapes, dangling, dir and .bak left out. */
    const char *want[] = {"a.ply", "alias.ply", "b.las", "dup.pcd", "dup.ply"};
    assert_int_equal(n, 5);
    for (size_t i = 0; i < n; i++) assert_string_equal(v[i].name, want[i]);
    assert_int_equal(v[0].size, 4);
    free(v);
    sd_err e = {0};
    assert_int_equal(dd_check_dir(f->data, &e), 0);
    char fpath[700];
    snprintf(fpath, sizeof fpath, "%s/a.ply", f->data);
    assert_int_equal(dd_check_dir(fpath, &e), SD_EINVAL);
    assert_non_null(strstr(e.msg, "not a directory"));
}

/* ---- auth ---- */

static void test_token_modes(void **state)
{
    (void)state;
    char dir[512], p[700];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    snprintf(p, sizeof p, "%s/token", dir);
    assert_int_equal(tu_write_file(p, "s3cret\n", 7), 0);
    auth_token t;
    sd_err e = {0};
    static const struct { mode_t mode; int ok; } cases[] = {
        {0600, 1}, {0400, 1}, {0700, 1}, {0640, 0}, {0604, 0}, {0644, 0}, {0660, 0}, {0610, 0},
        {0601, 0}, {0620, 0}, {0602, 0}, {0670, 0}, {0607, 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        assert_int_equal(chmod(p, cases[i].mode), 0);
        int rc = auth_token_load(p, &t, &e);
        if (cases[i].ok) {
            assert_int_equal(rc, 0);
            assert_int_equal(t.len, 6);        /* the newline is not part of the token */
            assert_memory_equal(t.bytes, "s3cret", 6);
        } else {
            assert_int_equal(rc, SD_EINVAL);
            assert_non_null(strstr(e.msg, "group or others"));
            assert_non_null(strstr(e.msg, p));
        }
    }
    /* Empty and missing files. */
    assert_int_equal(tu_write_file(p, "\n", 1), 0);
    assert_int_equal(chmod(p, 0600), 0);
    assert_int_equal(auth_token_load(p, &t, &e), SD_EEMPTY);
    snprintf(p, sizeof p, "%s/none", dir);
    assert_int_equal(auth_token_load(p, &t, &e), SD_EIO);
    tu_rm_rf(dir);
}

/* The token's edges: trailing CR and LF (any mix, as a Windows editor leaves them) are not part
 * of the token but a CR inside it is; a token of exactly AUTH_TOKEN_MAX bytes loads, with or
 * without a trailing CRLF, and one byte more is refused (SD_ELIMIT), as is a much larger file. */
static void test_token_edges(void **state)
{
    (void)state;
    char dir[512], p[700];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    snprintf(p, sizeof p, "%s/token", dir);
    auth_token t;
    sd_err e = {0};
    static const struct { const char *content; size_t len; } ends[] = {
        {"s3cret\r\n", 6}, {"s3cret\n\r\n", 6}, {"s3cret\r", 6}, {"s3cret", 6}, {"s3\rcret\n", 7},
    };
    for (size_t i = 0; i < sizeof ends / sizeof ends[0]; i++) {
        assert_int_equal(tu_write_file(p, ends[i].content, strlen(ends[i].content)), 0);
        assert_int_equal(chmod(p, 0600), 0);
        assert_int_equal(auth_token_load(p, &t, &e), 0);
        if (t.len != ends[i].len)
            fail_msg("token file case %zu: %zu bytes, want %zu", i, t.len, ends[i].len);
    }
    char *big = malloc(AUTH_TOKEN_MAX + 64);
    assert_non_null(big);
    memset(big, 'k', AUTH_TOKEN_MAX + 64);
    static const struct { size_t n; const char *tail; int rc; } sizes[] = {
        {AUTH_TOKEN_MAX, "", 0}, {AUTH_TOKEN_MAX, "\n", 0}, {AUTH_TOKEN_MAX, "\r\n", 0},
        {AUTH_TOKEN_MAX + 1, "", SD_ELIMIT}, {AUTH_TOKEN_MAX + 1, "\n", SD_ELIMIT},
        {AUTH_TOKEN_MAX + 40, "", SD_ELIMIT},
    };
    for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
        size_t tl = strlen(sizes[i].tail);
        memcpy(big + sizes[i].n, sizes[i].tail, tl);
        assert_int_equal(tu_write_file(p, big, sizes[i].n + tl), 0);
        memset(big + sizes[i].n, 'k', tl);
        assert_int_equal(chmod(p, 0600), 0);
        int rc = auth_token_load(p, &t, &e);
        if (rc != sizes[i].rc)
            fail_msg("a token of %zu bytes + %zu: rc %d, want %d (%s)", sizes[i].n, tl, rc,
                     sizes[i].rc, e.msg);
        if (rc == 0) assert_int_equal(t.len, AUTH_TOKEN_MAX);
    }
    free(big);
    tu_rm_rf(dir);
}

static void test_hmac(void **state)
{
    (void)state;
    /* Expected value computed independently, by the openssl command line and Python's hmac
     * module (both give the same digest), recorded here. */
    auth_token t = {0};
    memcpy(t.bytes, "key", 3);
    t.len = 3;
    uint8_t c[AUTH_CHALLENGE_LEN];
    for (int i = 0; i < AUTH_CHALLENGE_LEN; i++) c[i] = (uint8_t)('a' + i % 26);
    /* printf 'abcdefghijklmnopqrstuvwxyzabcdef' | openssl dgst -sha256 -hmac key */
    static const char *hex = "482e641ea4f0b55599f4cd888e9c00abd772543e3773f68b27cead7d9541e292";
    uint8_t want[32], got[32];
    for (int i = 0; i < 32; i++) {
        unsigned v;
        sscanf(hex + 2 * i, "%2x", &v);
        want[i] = (uint8_t)v;
    }
    assert_int_equal(auth_proof(&t, c, got), 0);
    assert_memory_equal(got, want, 32);
    assert_int_equal(auth_verify(&t, c, want, 32), 1);
    want[31] ^= 1;
    assert_int_equal(auth_verify(&t, c, want, 32), 0);
    want[31] ^= 1;
    assert_int_equal(auth_verify(&t, c, want, 31), 0);
    /* Two challenges differ (32 random bytes colliding has probability 2^-256). */
    uint8_t c1[AUTH_CHALLENGE_LEN], c2[AUTH_CHALLENGE_LEN];
    assert_int_equal(auth_challenge(c1, NULL), 0);
    assert_int_equal(auth_challenge(c2, NULL), 0);
    assert_memory_not_equal(c1, c2, AUTH_CHALLENGE_LEN);
}

/* auth_verify refuses a proof damaged ANYWHERE, not only where one example happens to look: each
 * of the 32 bytes flipped in turn (with three different bit masks, so a comparison that ignores
 * some bits of a byte is caught too), every wrong length with the right bytes as a prefix, an
 * all-zero and an all-ones proof, and the right proof checked against a challenge or a token that
 * differs in one byte (each challenge byte in turn: a proof must bind the whole challenge). The
 * right proof is accepted before and after, so the refusals are not an always-0 verifier. */
static void test_hmac_refuses_every_damage(void **state)
{
    (void)state;
    auth_token t = {0};
    memcpy(t.bytes, "correct horse battery staple", 28);
    t.len = 28;
    uint8_t c[AUTH_CHALLENGE_LEN];
    for (int i = 0; i < AUTH_CHALLENGE_LEN; i++) c[i] = (uint8_t)(i * 37 + 11);
    uint8_t good[AUTH_PROOF_LEN];
    assert_int_equal(auth_proof(&t, c, good), 0);
    assert_int_equal(auth_verify(&t, c, good, AUTH_PROOF_LEN), 1);

    static const uint8_t masks[] = {0x01, 0x80, 0xff};
    for (int i = 0; i < AUTH_PROOF_LEN; i++) {
        for (size_t k = 0; k < sizeof masks; k++) {
            uint8_t p[AUTH_PROOF_LEN];
            memcpy(p, good, sizeof p);
            p[i] ^= masks[k];
            if (auth_verify(&t, c, p, sizeof p) != 0)
                fail_msg("a proof with byte %d flipped (mask 0x%02x) was accepted", i, masks[k]);
        }
    }

    /* Every wrong length, from 0 to twice the right one, over a buffer that starts with the
     * right proof (so a verifier that compares only min(len, 32) bytes is caught). */
    uint8_t longp[2 * AUTH_PROOF_LEN + 1];
    memcpy(longp, good, AUTH_PROOF_LEN);
    memcpy(longp + AUTH_PROOF_LEN, good, AUTH_PROOF_LEN);
    longp[2 * AUTH_PROOF_LEN] = 0;
    for (size_t len = 0; len <= sizeof longp; len++) {
        if (len == AUTH_PROOF_LEN) continue;
        if (auth_verify(&t, c, longp, len) != 0)
            fail_msg("a proof of %zu bytes (the right bytes first) was accepted", len);
    }
    assert_int_equal(auth_verify(&t, c, NULL, 0), 0);

    uint8_t zero[AUTH_PROOF_LEN] = {0}, ones[AUTH_PROOF_LEN];
    memset(ones, 0xff, sizeof ones);
    assert_int_equal(auth_verify(&t, c, zero, sizeof zero), 0);
    assert_int_equal(auth_verify(&t, c, ones, sizeof ones), 0);

    /* The right proof for another challenge (one byte different, at each position) or for a
     * token that differs in its last byte, or is one byte shorter, is refused. */
    for (int i = 0; i < AUTH_CHALLENGE_LEN; i++) {
        uint8_t c2[AUTH_CHALLENGE_LEN];
        memcpy(c2, c, sizeof c2);
        c2[i] ^= 0x01;
        if (auth_verify(&t, c2, good, AUTH_PROOF_LEN) != 0)
            fail_msg("a proof was accepted for a challenge that differs in byte %d", i);
    }
    auth_token t2 = t;
    t2.bytes[t2.len - 1] ^= 0x01;
    assert_int_equal(auth_verify(&t2, c, good, AUTH_PROOF_LEN), 0);
    t2 = t;
    t2.len--;
    assert_int_equal(auth_verify(&t2, c, good, AUTH_PROOF_LEN), 0);

    assert_int_equal(auth_verify(&t, c, good, AUTH_PROOF_LEN), 1);
}

/* ---- timer heap ---- */

static void test_theap_order(void **state)
{
    (void)state;
    enum { N = 500 };
    ev_theap h = {0};
    ev_timer *t = calloc(N, sizeof *t);
    uint32_t x = 12345;
    for (int i = 0; i < N; i++) {
        ev_timer_init(&t[i]);
        x = x * 1103515245u + 12345u;
        t[i].due_ms = (x >> 16) % 50; /* many equal due times: insertion order must break ties */
        assert_int_equal(ev__theap_push(&h, &t[i]), 0);
    }
    /* Remove every third timer from the middle of the heap. */
    for (int i = 0; i < N; i += 3) ev__theap_remove(&h, &t[i]);
    for (int i = 0; i < N; i += 3) assert_false(ev_timer_armed(&t[i]));
    ev__theap_remove(&h, &t[0]); /* removing twice is a no-op */
    size_t left = h.n;
    assert_int_equal(left, N - (N + 2) / 3);
    uint64_t last_due = 0, last_order = 0;
    size_t popped = 0;
    ev_timer *top;
    while ((top = ev__theap_top(&h))) {
        if (popped) {
            assert_true(top->due_ms > last_due || (top->due_ms == last_due && top->order > last_order));
        }
        last_due = top->due_ms;
        last_order = top->order;
        ev__theap_remove(&h, top);
        assert_false(ev_timer_armed(top));
        assert_int_not_equal((top - t) % 3, 0);
        popped++;
    }
    assert_int_equal(popped, left);
    ev__theap_free(&h);
    free(t);
}

typedef struct loop_rec {
    int fired[4];
    int n;
    ev_timer t[4];
} loop_rec;

static void on_timer(ev_loop *l, ev_timer *t, void *data)
{
    loop_rec *r = data;
    r->fired[r->n++] = (int)(t - r->t);
    if (r->n == 3) ev_stop(l);
}

static void test_loop_timers(void **state)
{
    (void)state;
    sd_err e = {0};
    ev_loop *l = ev_create(64, &e);
    assert_non_null(l);
    loop_rec r = {0};
    for (int i = 0; i < 4; i++) ev_timer_init(&r.t[i]);
    uint64_t t0 = ev_now_ms();
    assert_int_equal(ev_timer_start(l, &r.t[0], 60, on_timer, &r), 0);
    assert_int_equal(ev_timer_start(l, &r.t[1], 20, on_timer, &r), 0);
    assert_int_equal(ev_timer_start(l, &r.t[2], 40, on_timer, &r), 0);
    assert_int_equal(ev_timer_start(l, &r.t[3], 30, on_timer, &r), 0);
    ev_timer_stop(l, &r.t[3]);
    assert_int_equal(ev_run(l), 0);
    uint64_t dt = ev_now_ms() - t0;
    assert_int_equal(r.n, 3);
    assert_int_equal(r.fired[0], 1);
    assert_int_equal(r.fired[1], 2);
    assert_int_equal(r.fired[2], 0);
    assert_true(dt >= 60);          /* the last timer was due at 60 ms */
    assert_true(dt < 2000);         /* generous: a loaded 2-core machine */
    ev_destroy(l);
}

/* ---- addresses ---- */

static void test_hostport(void **state)
{
    (void)state;
    char h[64];
    int port;
    sd_err e;
    assert_int_equal(net_parse_hostport("127.0.0.1:7878", h, sizeof h, &port, &e), 0);
    assert_string_equal(h, "127.0.0.1");
    assert_int_equal(port, 7878);
    assert_int_equal(net_parse_hostport("[::1]:0", h, sizeof h, &port, &e), 0);
    assert_string_equal(h, "::1");
    assert_int_equal(port, 0);
    assert_int_equal(net_parse_hostport("127.0.0.1", h, sizeof h, &port, &e), SD_EINVAL);
    assert_int_equal(net_parse_hostport("127.0.0.1:70000", h, sizeof h, &port, &e), SD_EINVAL);
    assert_int_equal(net_parse_hostport(":80", h, sizeof h, &port, &e), SD_EINVAL);
    assert_true(net_host_is_loopback("127.0.0.1"));
    assert_true(net_host_is_loopback("127.1.2.3"));
    assert_true(net_host_is_loopback("::1"));
    assert_true(net_host_is_loopback("localhost"));
    assert_false(net_host_is_loopback("0.0.0.0"));
    assert_false(net_host_is_loopback("::"));
    assert_false(net_host_is_loopback("10.0.0.1"));
    assert_false(net_host_is_loopback("128.0.0.1"));
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_resolve_accepts, dd_setup, dd_teardown),
        cmocka_unit_test_setup_teardown(test_resolve_refuses, dd_setup, dd_teardown),
        cmocka_unit_test_setup_teardown(test_list, dd_setup, dd_teardown),
        cmocka_unit_test(test_token_modes),
        cmocka_unit_test(test_token_edges),
        cmocka_unit_test(test_hmac),
        cmocka_unit_test(test_hmac_refuses_every_damage),
        cmocka_unit_test(test_theap_order),
        cmocka_unit_test(test_loop_timers),
        cmocka_unit_test(test_hostport),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
