/* test_client_lib.c — libsplatclient against a scripted in-process server (a thread speaking
 * the protocol through protocol/proto.c): handshake, token authentication, list, open with
 * progress, parameters (local and server-side validation), camera, render and decode,
 * pipelined frames matched by sequence, server errors, ping, timeouts. No daemon, no GL. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "params.h"
#include "proto.h"
#include "splat_client.h"
#include "testutil.h"

/* ---- the scripted server -------------------------------------------------------------------- */

typedef struct fake {
    int lfd, port;
    pthread_t th;
    const char *token;          /* NULL: no auth */
    int silent_ping;            /* 1: never answer PING (timeout test) */
    /* observations, read after the thread ended */
    int n_params, n_render, n_camera, authed, bye;
    uint32_t last_camera_seq;
    proto_camera last_camera;
    sp_params params;
} fake;

static void send_buf(int fd, proto_buf *b)
{
    size_t off = 0;
    while (off < b->len) {
        ssize_t n = send(fd, b->data + off, b->len - off, MSG_NOSIGNAL);
        if (n <= 0) break;
        off += (size_t)n;
    }
    b->len = 0;
}

/* serve: one connection, answering requests until BYE, EOF or a fatal error. */
static void *serve(void *arg)
{
    fake *f = arg;
    int fd = accept(f->lfd, NULL, NULL);
    if (fd < 0) return NULL;
    proto_decoder d;
    proto_decoder_init(&d, PROTO_C2S);
    d.preauth = 1;
    proto_buf out = {0};
    sp_params_defaults(&f->params);
    uint8_t chal[32];
    for (int i = 0; i < 32; i++) chal[i] = (uint8_t)(i * 31 + 7);
    uint8_t buf[4096];
    int done = 0;
    while (!done) {
        ssize_t n = recv(fd, buf, sizeof buf, 0);
        if (n <= 0) break;
        size_t off = 0;
        while (off < (size_t)n && !done) {
            size_t used;
            proto_msg m;
            proto_error e = {0};
            int rc = proto_decode(&d, buf + off, (size_t)n - off, &used, &m, &e);
            off += used;
            if (rc < 0) {
                proto_enc_error(&out, 0, (uint32_t)-rc, e.msg);
                send_buf(fd, &out);
                done = 1;
                break;
            }
            if (rc == PROTO_NEED_MORE) break;
            uint32_t seq = m.h.seq;
            switch (m.h.type) {
            case PROTO_MSG_HELLO: {
                proto_hello h;
                if (proto_parse_hello(m.payload, m.len, &h, &e) < 0) {
                    proto_enc_error(&out, seq, (uint32_t)e.code, e.msg);
                    done = 1;
                    break;
                }
                proto_welcome w = {.version = 1, .auth_required = f->token != NULL,
                                   .max_request = PROTO_MAX_REQUEST, .max_width = 4096,
                                   .max_height = 4096, .server = "fake 1", .backend = "null",
                                   .renderer = "none"};
                memcpy(w.challenge, chal, 32);
                if (!f->token) {
                    w.authenticated = 1;
                } else if (h.proof_len == 32) {
                    uint8_t want[32];
                    unsigned wl = 0;
                    HMAC(EVP_sha256(), f->token, (int)strlen(f->token), chal, 32, want, &wl);
                    if (memcmp(want, h.proof, 32) != 0) {
                        proto_enc_error(&out, seq, PROTO_E_AUTH_FAILED, "wrong proof");
                        done = 1;
                        break;
                    }
                    w.authenticated = 1;
                }
                if (w.authenticated) {
                    d.preauth = 0;
                    d.version = 1;
                    f->authed = 1;
                }
                proto_enc_welcome(&out, seq, &w);
                break;
            }
            case PROTO_MSG_LIST: {
                proto_cloud_entry it[2] = {{"bun000.ply", 1000, 40256, 1}, {"g.ply", 5, 0, 0}};
                proto_enc_clouds(&out, seq, it, 2);
                break;
            }
            case PROTO_MSG_OPEN: {
                char name[PROTO_MAX_NAME + 1];
                int prc = proto_parse_open(m.payload, m.len, name, &e);
                if (prc < 0) {
                    proto_enc_error(&out, seq, (uint32_t)e.code, e.msg);
                } else if (strcmp(name, "bun000") && strcmp(name, "bun000.ply")) {
                    proto_enc_error(&out, seq, PROTO_E_NOT_FOUND, "no cloud named that here");
                } else {
                    proto_progress p1 = {PROTO_PHASE_LOAD, 1.0f, "loaded"};
                    proto_progress p2 = {PROTO_PHASE_KNN, 0.5f, "half"};
                    proto_enc_progress(&out, seq, &p1);
                    proto_enc_progress(&out, seq, &p2);
                    proto_info in = {.name = "bun000.ply", .points = 40256, .dropped = 2,
                                     .bmin = {-1, -2, -3}, .bmax = {1, 2, 3},
                                     .offset = {0.5, 0, 0}, .attrs = 3, .sigma = 0.001f,
                                     .k = 24, .format = "PLY ascii 1.0"};
                    proto_enc_info(&out, seq, &in);
                }
                break;
            }
            case PROTO_MSG_PARAMS:
                f->n_params++;
                if (proto_parse_params(m.payload, m.len, &f->params, NULL, &e) < 0)
                    proto_enc_error(&out, seq, (uint32_t)e.code, e.msg);
                else
                    proto_enc_empty(&out, PROTO_MSG_OK, seq);
                break;
            case PROTO_MSG_CAMERA:
                f->n_camera++;
                if (proto_parse_camera(m.payload, m.len, &f->last_camera, &e) < 0) {
                    proto_enc_error(&out, seq, (uint32_t)e.code, e.msg);
                } else {
                    f->last_camera_seq = seq;
                }
                break;
            case PROTO_MSG_RENDER: {
                f->n_render++;
                /* a raw 3x2 frame whose pixels carry the camera sequence number */
                uint32_t w = 3, h = 2;
                uint8_t px[3 * 2 * 4];
                for (uint32_t i = 0; i < w * h; i++) {
                    px[4 * i + 0] = (uint8_t)f->last_camera_seq;
                    px[4 * i + 1] = (uint8_t)i;
                    px[4 * i + 2] = 200;
                    px[4 * i + 3] = 255;
                }
                proto_frame fr = {.camera_seq = f->last_camera_seq,
                                  .pipeline = (uint8_t)f->params.pipeline,
                                  .format = (uint8_t)f->params.format, .width = w, .height = h,
                                  .render_us = 1000 + seq, .readback_us = 10, .encode_us = 20,
                                  .points_drawn = 40256, .data = px, .data_len = sizeof px};
                if (f->params.format != SP_FMT_RAW) { /* pretend-encoded bytes */
                    fr.data = (const uint8_t *)"ENCODED";
                    fr.data_len = 7;
                }
                proto_enc_frame(&out, seq, &fr);
                break;
            }
            case PROTO_MSG_STREAM:
                proto_enc_empty(&out, PROTO_MSG_OK, seq);
                break;
            case PROTO_MSG_PING: {
                proto_ping p;
                proto_parse_ping(m.payload, m.len, &p, &e);
                proto_pong po = {p.token, 42};
                if (!f->silent_ping) proto_enc_pong(&out, seq, &po);
                break;
            }
            case PROTO_MSG_BYE:
                f->bye = 1;
                done = 1;
                break;
            }
            send_buf(fd, &out);
        }
    }
    proto_buf_free(&out);
    proto_decoder_free(&d);
    close(fd);
    return NULL;
}

static void fake_start(fake *f)
{
    f->lfd = socket(AF_INET, SOCK_STREAM, 0);
    assert_true(f->lfd >= 0);
    struct sockaddr_in a = {0};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(bind(f->lfd, (struct sockaddr *)&a, sizeof a), 0);
    assert_int_equal(listen(f->lfd, 4), 0);
    socklen_t l = sizeof a;
    getsockname(f->lfd, (struct sockaddr *)&a, &l);
    f->port = ntohs(a.sin_port);
    assert_int_equal(pthread_create(&f->th, NULL, serve, f), 0);
}

static void fake_join(fake *f)
{
    pthread_join(f->th, NULL);
    close(f->lfd);
}

/* ---- tests ------------------------------------------------------------------------------ */

static void count_progress(void *u, const char *phase, float frac, const char *text)
{
    int *n = u;
    (*n)++;
    assert_true(frac >= 0 && frac <= 1);
    assert_true(!strcmp(phase, "load") || !strcmp(phase, "knn"));
    assert_true(!strcmp(text, "loaded") || !strcmp(text, "half"));
}

static void test_session(void **state)
{
    (void)state;
    fake f = {0};
    fake_start(&f);
    spc_options o = {.port = f.port, .timeout_ms = 5000, .client_name = "test"};
    spc_client *c;
    char err[512];
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), 0);
    assert_string_equal(spc_server(c)->server, "fake 1");
    assert_string_equal(spc_server(c)->backend, "null");
    assert_int_equal(spc_server(c)->version, 1);
    assert_int_equal(spc_server(c)->max_width, 4096);

    spc_cloud *l;
    assert_int_equal(spc_list(c, &l), 2);
    assert_string_equal(l[0].name, "bun000.ply");
    assert_int_equal(l[0].points, 40256);
    assert_int_equal(l[1].bytes, 5);
    spc_free_list(l);

    /* NOT_FOUND surfaces with the server's text; the session goes on */
    spc_info in;
    assert_int_equal(spc_open(c, "nothere", &in, NULL, NULL), SPC_E_NOT_FOUND);
    assert_non_null(strstr(spc_errmsg(c), "NOT_FOUND"));
    assert_non_null(strstr(spc_errmsg(c), "no cloud named that here"));
    assert_true(spc_errseq(c) > 0);
    /* a path is refused locally, before sending */
    assert_int_equal(spc_open(c, "../etc/passwd", &in, NULL, NULL), SPC_E_BAD_NAME);

    int nprog = 0;
    assert_int_equal(spc_open(c, "bun000", &in, count_progress, &nprog), 0);
    assert_int_equal(nprog, 2);
    assert_string_equal(in.name, "bun000.ply");
    assert_int_equal(in.points, 40256);
    assert_int_equal(in.dropped, 2);
    assert_true(in.bmin[2] == -3 && in.bmax[1] == 2 && in.offset[0] == 0.5);
    assert_int_equal(in.attrs, SPC_ATTR_RGB | SPC_ATTR_NORMAL);
    assert_int_equal(in.k, 24);
    assert_string_equal(in.format, "PLY ascii 1.0");

    /* parameters: local validation sends nothing */
    assert_int_equal(spc_set_param(c, "splat_scale=500"), SPC_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(spc_errmsg(c), "[0.01, 100]"));
    assert_int_equal(spc_set_param(c, "nonsense=1"), SPC_E_BAD_PARAM_NAME);
    assert_int_equal(spc_set_param(c, "quality"), SPC_E_INVALID_ARG);
    assert_int_equal(spc_set_param_float(c, "quality", 3), SPC_E_BAD_PARAM_VALUE);
    const char *kv[2] = {"format=raw", "pipeline=points"};
    assert_int_equal(spc_set_params(c, kv, 2), 0);
    assert_int_equal(spc_set_param_float(c, "splat_scale", 0.01f), 0);
    assert_int_equal(spc_set_param_int(c, "quality", 77), 0);
    float light[3] = {0, 0.5f, -1};
    assert_int_equal(spc_set_param_vec3(c, "light", light), 0);
    assert_int_equal(spc_set_param_enum(c, "color", "normal"), 0);
    /* a text form that sets two parameters sends both (field=class and classes) */
    assert_int_equal(spc_set_param(c, "field=class:3,4,5"), 0);
    char val[64];
    assert_int_equal(spc_get_param(c, "quality", val, sizeof val), 0);
    assert_string_equal(val, "77");

    /* an invalid camera is refused locally with the protocol's message */
    spc_camera cam;
    spc_camera_frame(&in, 64, 48, &cam);
    spc_camera badcam = cam;
    badcam.fov_deg = 0;
    assert_int_equal(spc_set_camera(c, &badcam, NULL), SPC_E_BAD_CAMERA);
    assert_non_null(strstr(spc_errmsg(c), "fov"));
    badcam = cam;
    badcam.width = 5000; /* within the protocol's 16384, over this server's 4096 */
    assert_int_equal(spc_set_camera(c, &badcam, NULL), SPC_E_BAD_CAMERA);
    assert_non_null(strstr(spc_errmsg(c), "4096"));
    uint32_t cseq = 0;
    assert_int_equal(spc_set_camera(c, &cam, &cseq), 0);
    assert_true(cseq > 0);

    spc_frame fr;
    assert_int_equal(spc_render(c, &fr, 1), 0);
    assert_int_equal(fr.camera_seq, cseq);
    assert_string_equal(fr.format, "raw");
    assert_string_equal(fr.pipeline, "points");
    assert_int_equal(fr.width, 3);
    assert_int_equal(fr.height, 2);
    assert_int_equal(fr.points_drawn, 40256);
    assert_int_equal(fr.render_us, 1000 + fr.seq);
    assert_int_equal(fr.data_len, 24);
    assert_non_null(fr.rgba);
    for (int i = 0; i < 6; i++) {
        assert_int_equal(fr.rgba[4 * i + 0], (uint8_t)cseq);
        assert_int_equal(fr.rgba[4 * i + 1], i);
    }

    /* pipelined: 5 frames with 3 in flight, answers matched to their cameras */
    uint32_t rseq[5], camseq_expect[5];
    int sent = 0, got = 0;
    while (got < 5) {
        while (sent < 5 && sent - got < 3) {
            spc_camera_orbit(&in, NULL, sent, 5, 45, 64, 48, &cam);
            assert_int_equal(spc_send_render(c, &cam, &rseq[sent]), 0);
            camseq_expect[sent] = rseq[sent] - 1; /* CAMERA goes right before its RENDER */
            sent++;
        }
        assert_int_equal(spc_recv_frame(c, &fr, 0), 0);
        assert_int_equal(fr.seq, rseq[got]);
        assert_int_equal(fr.camera_seq, camseq_expect[got]);
        got++;
    }

    /* non-decodable formats: bytes as sent, decode refused */
    assert_int_equal(spc_set_param(c, "format=png"), 0);
    assert_int_equal(spc_render(c, &fr, 0), 0);
    assert_int_equal(fr.data_len, 7);
    assert_memory_equal(fr.data, "ENCODED", 7);
    assert_null(fr.rgba);
    assert_int_equal(spc_render(c, &fr, 1), SPC_E_DECODE);

    uint64_t rtt = 0;
    assert_int_equal(spc_ping(c, &rtt), 0);
    assert_true(rtt > 0 && rtt < 5000000);
    assert_int_equal(spc_stream(c, 1, 30), 0);
    assert_int_equal(spc_stream(c, 0, 2000), SPC_E_BAD_PARAM_VALUE);
    spc_close(c);
    fake_join(&f);
    assert_int_equal(f.bye, 1);
    /* what reached the server: only the 7 valid PARAMS, applied */
    assert_int_equal(f.n_params, 7);
    assert_int_equal(f.params.field, SP_FIELD_CLASS);
    assert_int_equal(f.params.classes, 56);
    assert_int_equal(f.params.quality, 77);
    assert_int_equal(f.params.color, SP_COLOR_NORMAL);
    assert_true(f.params.light[2] == -1.0f);
    assert_true(f.params.splat_scale == 0.01f);
    assert_int_equal(f.n_render, 8);
    assert_int_equal(f.n_camera, 6);
    spc_close(NULL);
}

static void test_auth(void **state)
{
    (void)state;
    char dir[256], tok[300], err[512];
    tu_tmpdir(dir, sizeof dir);
    snprintf(tok, sizeof tok, "%s/token", dir);
    tu_write_file(tok, "hunter2\n", 8);
    chmod(tok, 0600);
    spc_client *c;

    /* right token */
    fake f = {.token = "hunter2"};
    fake_start(&f);
    spc_options o = {.port = f.port, .timeout_ms = 5000, .token_file = tok};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), 0);
    assert_int_equal(spc_server(c)->auth_required, 1);
    assert_int_equal(spc_ping(c, NULL), 0);
    spc_close(c);
    fake_join(&f);
    assert_int_equal(f.authed, 1);

    /* no token: AUTH_REQUIRED, locally, naming the option */
    fake g = {.token = "hunter2"};
    fake_start(&g);
    o.port = g.port;
    o.token_file = NULL;
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_AUTH_REQUIRED);
    assert_null(c);
    assert_non_null(strstr(err, "token"));
    fake_join(&g);
    assert_int_equal(g.authed, 0);

    /* wrong token: the server's AUTH_FAILED */
    fake h = {.token = "other"};
    fake_start(&h);
    o.port = h.port;
    o.token_file = tok;
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_AUTH_FAILED);
    assert_non_null(strstr(err, "wrong proof"));
    fake_join(&h);

    /* a token file readable by others is refused before anything is sent */
    chmod(tok, 0644);
    fake k = {.token = "hunter2"};
    fake_start(&k);
    o.port = k.port;
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), SPC_E_TOKEN);
    assert_non_null(strstr(err, "0644"));
    fake_join(&k);
    assert_int_equal(k.authed, 0);
    tu_rm_rf(dir);
}

static void test_timeout_and_refused(void **state)
{
    (void)state;
    char err[512];
    spc_client *c;
    fake f = {.silent_ping = 1};
    fake_start(&f);
    spc_options o = {.port = f.port, .timeout_ms = 200};
    assert_int_equal(spc_connect(&o, &c, err, sizeof err), 0);
    assert_int_equal(spc_ping(c, NULL), SPC_E_TIMEOUT);
    assert_non_null(strstr(spc_errmsg(c), "200 ms"));
    /* a timeout is fatal: the connection is closed, later calls say so */
    assert_int_equal(spc_ping(c, NULL), SPC_E_CLOSED);
    assert_int_equal(spc_fd(c), -1);
    spc_close(c);
    fake_join(&f);

    /* nobody listening */
    int s = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {0};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    bind(s, (struct sockaddr *)&a, sizeof a);
    socklen_t l = sizeof a;
    getsockname(s, (struct sockaddr *)&a, &l);
    close(s); /* the port is now (very likely) closed */
    spc_options o2 = {.port = ntohs(a.sin_port), .timeout_ms = 2000};
    assert_int_equal(spc_connect(&o2, &c, err, sizeof err), SPC_E_IO);
    assert_non_null(strstr(err, "cannot connect"));
    spc_options o3 = {.port = 70000};
    assert_int_equal(spc_connect(&o3, &c, err, sizeof err), SPC_E_INVALID_ARG);
    assert_string_equal(spc_strerror(SPC_E_NOT_FOUND), "NOT_FOUND");
    assert_int_equal(spc_error_fatal(SPC_E_AUTH_FAILED), 1);
    assert_int_equal(spc_error_fatal(SPC_E_BAD_PARAM_VALUE), 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_session),
        cmocka_unit_test(test_auth),
        cmocka_unit_test(test_timeout_and_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
