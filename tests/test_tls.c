/* test_tls.c — TLS between splatd and libsplatclient (project issue 14, item 6): a round
 * trip with a self-signed certificate made here, with and without a token; the certificate
 * checks of the client (wrong CA, wrong name, the system store); a plaintext client on a TLS
 * listener and a TLS client on a plaintext one, each told what is wrong while the daemon keeps
 * serving; TLS required beyond loopback. The daemon runs as a child (daemonproc). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/daemonproc.h"
#include "common/testutil.h"
#include "common/tlscert.h"
#include "splat_client.h"
#include "testutil.h"

static const char TOKEN[] = "correct horse battery staple";

typedef struct fx {
    char root[512];
    char data[600], token[600];
    char cert[700], key[700];        /* the daemon's: CN splatd-test, IP 127.0.0.1, DNS localhost */
    char other[700], okey[700];      /* an unrelated self-signed certificate */
    tu_daemon d;
} fx;

static int setup(void **state)
{
    fx *f = calloc(1, sizeof *f);
    if (!f || !tu_tmpdir(f->root, sizeof f->root)) return -1;
    snprintf(f->data, sizeof f->data, "%s/data", f->root);
    snprintf(f->token, sizeof f->token, "%s/token", f->root);
    if (mkdir(f->data, 0755) != 0) return -1;
    char src[600], dst[700];
    tu_data("bun000.ply", src, sizeof src);
    snprintf(dst, sizeof dst, "%s/bunny.ply", f->data);
    if (tu_copy_file(src, dst) != 0) return -1;
    if (tu_write_file(f->token, TOKEN, strlen(TOKEN)) != 0 || chmod(f->token, 0600) != 0) return -1;
    if (tu_make_cert(f->root, "server", "splatd-test", "127.0.0.1", "localhost", f->cert, f->key,
                     sizeof f->cert) != 0 ||
        tu_make_cert(f->root, "other", "someone-else", "127.0.0.1", "localhost", f->other,
                     f->okey, sizeof f->other) != 0)
        return -1;
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

/* log_wait: 1 once the daemon's log holds needle, polling for up to 5 s (a line written when
 * a connection closes may come just after the client saw it close). */
static int log_wait(const tu_daemon *d, const char *needle)
{
    for (int i = 0; i < 100; i++) {
        if (tu_daemon_log_count(d, needle) > 0) return 1;
        usleep(50000);
    }
    return 0;
}

/* start_tls: the daemon on 127.0.0.1 with the fixture's certificate (and the token when
 * with_token). */
static void start_tls(fx *f, int with_token)
{
    const char *a[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->root,
                       "--tls-cert", f->cert, "--tls-key", f->key,
                       with_token ? "--token-file" : NULL, f->token, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, a), 0);
}

/* render_bunny: opens bunny.ply and renders one 96x72 raw frame of it from its default
 * camera; returns the frame's bytes (malloc'd, *len). */
static uint8_t *render_bunny(spc_client *c, size_t *len)
{
    spc_info info;
    if (spc_open(c, "bunny", &info, NULL, NULL) < 0) fail_msg("open: %s", spc_errmsg(c));
    assert_int_equal(info.points, 40256);
    const char *kv[2] = {"pipeline=points", "format=raw"};
    assert_int_equal(spc_set_params(c, kv, 2), 0);
    spc_camera cam;
    spc_camera_frame(&info, 96, 72, &cam);
    assert_int_equal(spc_set_camera(c, &cam, NULL), 0);
    spc_frame fr;
    if (spc_render(c, &fr, 0) < 0) fail_msg("render: %s", spc_errmsg(c));
    assert_int_equal(fr.width, 96);
    assert_int_equal(fr.height, 72);
    uint8_t *copy = malloc(fr.data_len);
    assert_non_null(copy);
    memcpy(copy, fr.data, fr.data_len);
    *len = fr.data_len;
    return copy;
}

/* A frame over TLS is the frame over plain TCP, byte for byte (the same renderer and camera);
 * with a token, a client without it or with a wrong one is refused inside TLS. */
static void test_tls_round_trip(void **state)
{
    fx *f = *state;
    const char *plain[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->root, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, plain), 0);
    char err[1024];
    spc_client *c = NULL;
    spc_options o = {.port = f->d.port};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), 0);
    size_t plen;
    uint8_t *pframe = render_bunny(c, &plen);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);

    start_tls(f, 1);
    assert_true(log_wait(&f->d, "TLS only, certificate /CN=splatd-test"));
    o = (spc_options){.port = f->d.port, .tls_ca = f->cert, .token_file = f->token};
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("TLS connect: %s", err);
    assert_int_equal(spc_server(c)->auth_required, 1);
    size_t tlen;
    uint8_t *tframe = render_bunny(c, &tlen);
    assert_int_equal(tlen, 96 * 72 * 4);
    assert_int_equal(plen, tlen);
    assert_memory_equal(pframe, tframe, tlen);
    assert_int_equal(spc_ping(c, NULL), 0);
    spc_close(c);
    free(pframe);
    free(tframe);

    /* The command line: `splat --tls-ca` lists the clouds; without --tls it is told to use it. */
    char cmd[2400], out[4096];
    snprintf(cmd, sizeof cmd, "'%s' --port %d --tls-ca '%s' --token-file '%s' list 2>&1",
             tu_splat_bin(), f->d.port, f->cert, f->token);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, sizeof out - 1, p);
    out[n] = 0;
    int st = pclose(p);
    if (st != 0 || !strstr(out, "bunny")) fail_msg("splat --tls-ca list (%d): %s", st, out);
    snprintf(cmd, sizeof cmd, "'%s' --port %d --token-file '%s' list 2>&1", tu_splat_bin(),
             f->d.port, f->token);
    p = popen(cmd, "r");
    assert_non_null(p);
    n = fread(out, 1, sizeof out - 1, p);
    out[n] = 0;
    st = pclose(p);
    if (st == 0 || !strstr(out, "accepts TLS connections only")) fail_msg("splat list (%d): %s", st, out);

    /* The name "localhost" is in the certificate too (checked as the name asked for, over
     * 127.0.0.1: a machine without /etc/hosts cannot resolve "localhost"). */
    o = (spc_options){.host = "127.0.0.1", .port = f->d.port, .tls_ca = f->cert,
                      .tls_name = "localhost", .token_file = f->token};
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("TLS connect as localhost: %s", err);
    spc_close(c);

    /* Token checks still apply inside TLS. */
    o = (spc_options){.port = f->d.port, .tls_ca = f->cert};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_AUTH_REQUIRED);
    assert_null(c);
    char bad[700];
    snprintf(bad, sizeof bad, "%s/badtoken", f->root);
    assert_int_equal(tu_write_file(bad, "correct horse battery stapler", 29), 0);
    assert_int_equal(chmod(bad, 0600), 0);
    o.token_file = bad;
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_AUTH_FAILED);
    assert_int_equal(tu_daemon_stop(&f->d), 0);
}

/* The client checks the server's certificate: signed by the CA it trusts, naming the host. */
static void test_tls_verification(void **state)
{
    fx *f = *state;
    start_tls(f, 0);
    char err[1024];
    spc_client *c = NULL;
    spc_options o = {.port = f->d.port, .tls_ca = f->other};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_IO);
    assert_null(c);
    if (!strstr(err, "certificate was refused for '127.0.0.1'") || !strstr(err, f->other))
        fail_msg("wrong CA: %s", err);
    /* The right CA, a name the certificate does not carry. */
    o = (spc_options){.port = f->d.port, .tls_ca = f->cert, .tls_name = "splatd.example.org"};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_IO);
    if (!strstr(err, "refused for 'splatd.example.org'") || !strstr(err, "mismatch"))
        fail_msg("wrong name: %s", err);
    o.tls_name = "127.0.0.2";
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_IO);
    if (!strstr(err, "IP address mismatch")) fail_msg("wrong IP: %s", err);
    /* The system's store does not know a certificate made a moment ago. */
    o = (spc_options){.port = f->d.port, .tls = 1};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_IO);
    if (!strstr(err, "system's trusted certificates") || !strstr(err, "self-signed"))
        fail_msg("system store: %s", err);
    /* A CA file that is not one. */
    o = (spc_options){.port = f->d.port, .tls_ca = f->data};
    assert_true(spc_connect(&o, &c, err, sizeof err) < 0);
    if (!strstr(err, "cannot load the CA certificates")) fail_msg("bad CA file: %s", err);
    /* Refused clients left the daemon serving. */
    o = (spc_options){.port = f->d.port, .tls_ca = f->cert};
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("after refusals: %s", err);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);
}

/* A plaintext client on a TLS listener is told in plaintext to use TLS, and the daemon goes on
 * serving TLS clients; a TLS client on a plaintext listener is told the server has no TLS. */
static void test_tls_mismatch(void **state)
{
    fx *f = *state;
    start_tls(f, 1);
    char err[1024];
    spc_client *c = NULL;
    spc_options o = {.port = f->d.port, .token_file = f->token};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_AUTH_REQUIRED);
    if (!strstr(err, "accepts TLS connections only")) fail_msg("plaintext client: %s", err);
    assert_true(log_wait(&f->d, "not a TLS client (first byte 0x53)"));
    /* A connection that sends nothing of a handshake and goes: nothing breaks. */
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)f->d.port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
    assert_int_equal(send(fd, "\x16\x03\x01\x00", 4, 0), 4);
    close(fd);
    o.tls_ca = f->cert;
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("TLS after a plaintext client: %s", err);
    assert_int_equal(spc_ping(c, NULL), 0);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);

    const char *plain[] = {"--listen", "127.0.0.1:0", "--data", f->data, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, plain), 0);
    o = (spc_options){.port = f->d.port, .tls_ca = f->cert};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_IO);
    if (!strstr(err, "answered in plaintext, not TLS")) fail_msg("TLS client, plain server: %s", err);
    o = (spc_options){.port = f->d.port};
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("plain after TLS: %s", err);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);
}

/* A client that starts a TLS handshake and stalls is closed at the handshake deadline, like
 * one that never sends HELLO. A connection over --max-per-addr is closed at once (a BUSY answer
 * would need the handshake first), and the client says what that may mean. */
static void test_tls_handshake_deadline(void **state)
{
    fx *f = *state;
    const char *a[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--tls-cert", f->cert,
                       "--tls-key", f->key, "--handshake-timeout", "1", "--max-per-addr", "1",
                       NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, a), 0);
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in sa = {.sin_family = AF_INET, .sin_port = htons((uint16_t)f->d.port)};
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    struct timeval tv = {10, 0};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    assert_int_equal(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    assert_int_equal(send(fd, "\x16\x03\x01\x00", 4, 0), 4); /* half a record header */
    char b;
    ssize_t r;
    while ((r = recv(fd, &b, 1, 0)) > 0) {}
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double secs = (double)(t1.tv_sec - t0.tv_sec) + (double)(t1.tv_nsec - t0.tv_nsec) * 1e-9;
    close(fd);
    printf("a stalled TLS handshake was closed after %.2f s (--handshake-timeout 1)\n", secs);
    assert_int_equal(r, 0); /* closed by the daemon, not our receive timeout */
    assert_true(secs > 0.8 && secs < 5);
    assert_true(log_wait(&f->d, "closed: no HELLO within 1 s"));
    char err[1024];
    spc_client *c1 = NULL, *c2 = NULL;
    spc_options o = {.port = f->d.port, .tls_ca = f->cert};
    if (spc_connect(&o, &c1, err, sizeof err) != 0) fail_msg("first client: %s", err);
    assert_int_equal(spc_connect(&o, &c2, err, sizeof err), SPC_E_IO);
    if (!strstr(err, "closed the connection during the TLS handshake") ||
        !strstr(err, "too many connections from your address"))
        fail_msg("second client: %s", err);
    assert_true(log_wait(&f->d, "(--max-per-addr)"));
    spc_close(c1);
    assert_int_equal(tu_daemon_stop(&f->d), 0);
}

/* Beyond loopback TLS is required; the key must be private; cert and key go together. */
static void test_tls_required(void **state)
{
    fx *f = *state;
    int st = 0;
    const char *a1[] = {"--listen", "0.0.0.0:0", "--data", f->data, "--token-file", f->token, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, &st, a1), -1);
    assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 1);
    assert_true(tu_daemon_log_count(&f->d, "refusing to listen on 0.0.0.0 without TLS"));
    const char *a2[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--tls-cert", f->cert, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, &st, a2), -1);
    assert_true(tu_daemon_log_count(&f->d, "--tls-cert and --tls-key go together"));
    assert_int_equal(chmod(f->key, 0644), 0);
    const char *a3[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--tls-cert", f->cert,
                        "--tls-key", f->key, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, &st, a3), -1);
    assert_true(tu_daemon_log_count(&f->d, "a private key must not be accessible to group or others"));
    assert_int_equal(chmod(f->key, 0600), 0);
    const char *a4[] = {"--listen", "127.0.0.1:0", "--data", f->data, "--tls-cert", f->cert,
                        "--tls-key", f->okey, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, &st, a4), -1);
    assert_true(tu_daemon_log_count(&f->d, "does not belong to the certificate"));
    const char *a5[] = {"--listen", "0.0.0.0:0", "--data", f->data, "--token-file", f->token,
                        "--tls-cert", f->cert, "--tls-key", f->key, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, a5), 0);
    char err[1024];
    spc_client *c = NULL;
    spc_options o = {.port = f->d.port, .tls_ca = f->cert, .token_file = f->token};
    if (spc_connect(&o, &c, err, sizeof err) != 0) fail_msg("0.0.0.0 with TLS: %s", err);
    spc_close(c);
    assert_int_equal(tu_daemon_stop(&f->d), 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_tls_round_trip, setup, teardown),
        cmocka_unit_test_setup_teardown(test_tls_verification, setup, teardown),
        cmocka_unit_test_setup_teardown(test_tls_mismatch, setup, teardown),
        cmocka_unit_test_setup_teardown(test_tls_required, setup, teardown),
        cmocka_unit_test_setup_teardown(test_tls_handshake_deadline, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
