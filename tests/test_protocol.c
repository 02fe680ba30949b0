/* test_protocol.c — the wire format: byte layout, round trips of every message type, the
 * incremental decoder, rejection of malformed input, every limit on both sides of its boundary,
 * cloud-name validation, random input. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "params.h"
#include "proto.h"
#include "testutil.h"

/* decode_one: runs buf through a fresh decoder of direction dir; expects exactly one message
 * that uses all len bytes; copies the payload into *pl (malloc'd). */
static void decode_one(const proto_buf *b, uint8_t dir, proto_msg *m, uint8_t **pl)
{
    proto_decoder d;
    proto_decoder_init(&d, dir);
    d.max_payload = PROTO_MAX_FRAME;
    proto_error e = {0};
    size_t used = 0;
    int rc = proto_decode(&d, b->data, b->len, &used, m, &e);
    if (rc != PROTO_ONE_MSG) fail_msg("decode: %d %s", rc, e.msg);
    assert_int_equal(used, b->len);
    *pl = malloc(m->len + 1);
    if (m->len) memcpy(*pl, m->payload, m->len);
    m->payload = *pl;
    proto_decoder_free(&d);
}

static void test_le_helpers(void **state)
{
    (void)state;
    uint8_t b[8];
    proto_put_u32(b, 0x01020304u);
    assert_memory_equal(b, "\x04\x03\x02\x01", 4);
    proto_put_u16(b, 0xBEEF);
    assert_memory_equal(b, "\xEF\xBE", 2);
    proto_put_u64(b, 0x0102030405060708ull);
    assert_memory_equal(b, "\x08\x07\x06\x05\x04\x03\x02\x01", 8);
    assert_int_equal(proto_get_u64(b), 0x0102030405060708ull);
    proto_put_f64(b, 1.0); /* IEEE-754: 0x3FF0000000000000 */
    assert_memory_equal(b, "\0\0\0\0\0\0\xF0\x3F", 8);
    assert_true(proto_get_f64(b) == 1.0);
    proto_put_f32(b, -2.0f); /* 0xC0000000 */
    assert_memory_equal(b, "\0\0\0\xC0", 4);
    assert_true(proto_get_f32(b) == -2.0f);
    /* the magic is the four ASCII bytes S P L T on the wire */
    proto_header h = {PROTO_MAGIC, 1, PROTO_MSG_PING, 0x11223344u, 8};
    uint8_t hb[16];
    proto_put_header(hb, &h);
    assert_memory_equal(hb, "SPLT\x01\x00\x08\x00\x44\x33\x22\x11\x08\x00\x00\x00", 16);
    proto_header g;
    proto_get_header(hb, &g);
    assert_int_equal(g.magic, PROTO_MAGIC);
    assert_int_equal(g.seq, 0x11223344u);
    assert_int_equal(g.len, 8);
}

static void test_names_and_codes(void **state)
{
    (void)state;
    assert_string_equal(proto_msg_name(PROTO_MSG_CAMERA), "CAMERA");
    assert_string_equal(proto_msg_name(999), "?");
    assert_int_equal(proto_msg_dir(PROTO_MSG_FRAME), PROTO_S2C);
    assert_int_equal(proto_msg_dir(PROTO_MSG_HELLO), PROTO_C2S);
    assert_int_equal(proto_msg_dir(77), 0);
    assert_string_equal(proto_err_name(PROTO_E_TRUNCATED), "TRUNCATED");
    assert_string_equal(proto_err_name(-PROTO_E_BAD_NAME), "BAD_NAME");
    assert_int_equal(proto_err_from_name("AUTH_FAILED"), 13);
    assert_int_equal(proto_err_from_name("nope"), 0);
    assert_int_equal(proto_err_fatal(PROTO_E_BAD_MAGIC), 1);
    assert_int_equal(proto_err_fatal(PROTO_E_BAD_PARAM_VALUE), 0);
    assert_int_equal(proto_pick_version(1, 5, NULL), 1);
    proto_error e = {0};
    assert_int_equal(proto_pick_version(2, 3, &e), -PROTO_E_BAD_VERSION);
    assert_non_null(strstr(e.msg, "[2, 3]"));
}

/* ---- round trips ---------------------------------------------------------------------------- */

static void test_roundtrip_client_messages(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_msg m;
    uint8_t *pl;
    proto_error e = {0};

    proto_hello h = {.min_version = 1, .max_version = 3, .proof_len = 32};
    strcpy(h.client, "splat test");
    for (int i = 0; i < 32; i++) h.proof[i] = (uint8_t)(i * 7 + 1);
    assert_int_equal(proto_enc_hello(&b, 1, &h), 0);
    decode_one(&b, PROTO_C2S, &m, &pl);
    assert_int_equal(m.h.type, PROTO_MSG_HELLO);
    assert_int_equal(m.h.seq, 1);
    assert_int_equal(m.h.version, PROTO_VERSION);
    proto_hello h2;
    assert_int_equal(proto_parse_hello(m.payload, m.len, &h2, &e), 0);
    assert_int_equal(h2.min_version, 1);
    assert_int_equal(h2.max_version, 3);
    assert_string_equal(h2.client, "splat test");
    assert_int_equal(h2.proof_len, 32);
    assert_memory_equal(h2.proof, h.proof, 32);
    free(pl);
    b.len = 0;

    assert_int_equal(proto_enc_open(&b, 2, "bun000.ply"), 0);
    decode_one(&b, PROTO_C2S, &m, &pl);
    char name[PROTO_MAX_NAME + 1];
    assert_int_equal(m.h.type, PROTO_MSG_OPEN);
    assert_int_equal(proto_parse_open(m.payload, m.len, name, &e), 0);
    assert_string_equal(name, "bun000.ply");
    free(pl);
    b.len = 0;

    proto_camera c = {{1e6 + 0.125, -2.5, 3e-3}, {4, 5, 6.75}, {0, 0, 1}, 45.5f, 0.25f, 900.0f,
                      1280, 720};
    assert_int_equal(proto_enc_camera(&b, 3, &c), 0);
    assert_int_equal(b.len, PROTO_HEADER_LEN + 92); /* 9 f64 + 3 f32 + 2 u32 */
    decode_one(&b, PROTO_C2S, &m, &pl);
    proto_camera c2;
    assert_int_equal(proto_parse_camera(m.payload, m.len, &c2, &e), 0);
    /* doubles travel bit-exactly: compare with == */
    for (int i = 0; i < 3; i++) {
        assert_true(c2.eye[i] == c.eye[i]);
        assert_true(c2.target[i] == c.target[i]);
        assert_true(c2.up[i] == c.up[i]);
    }
    assert_true(c2.fov_deg == c.fov_deg && c2.znear == c.znear && c2.zfar == c.zfar);
    assert_int_equal(c2.width, 1280);
    assert_int_equal(c2.height, 720);
    free(pl);
    b.len = 0;

    sp_params p;
    sp_params_defaults(&p);
    char err[200];
    assert_int_equal(sp_param_set_kv(&p, "splat_scale=2.5", err, sizeof err), 0);
    assert_int_equal(sp_param_set_kv(&p, "pipeline=points", err, sizeof err), 0);
    assert_int_equal(sp_param_set_kv(&p, "quality=42", err, sizeof err), 0);
    assert_int_equal(sp_param_set_kv(&p, "light=0.5,-0.25,1", err, sizeof err), 0);
    proto_param_rec recs[4];
    int ids[4] = {SP_SPLAT_SCALE, SP_PIPELINE, SP_QUALITY, SP_LIGHT};
    for (int i = 0; i < 4; i++) proto_param_rec_from(&p, ids[i], &recs[i]);
    assert_int_equal(proto_enc_params(&b, 4, recs, 4), 0);
    decode_one(&b, PROTO_C2S, &m, &pl);
    sp_params q;
    sp_params_defaults(&q);
    uint64_t changed = 0;
    assert_int_equal(proto_parse_params(m.payload, m.len, &q, &changed, &e), 0);
    assert_true(q.splat_scale == 2.5f);
    assert_int_equal(q.pipeline, SP_PIPE_POINTS);
    assert_int_equal(q.quality, 42);
    assert_true(q.light[0] == 0.5f && q.light[1] == -0.25f && q.light[2] == 1.0f);
    assert_int_equal(changed, (1ull << SP_SPLAT_SCALE) | (1ull << SP_PIPELINE) |
                                  (1ull << SP_QUALITY) | (1ull << SP_LIGHT));
    assert_memory_equal(&p, &q, sizeof p); /* every other field still the default */
    free(pl);
    b.len = 0;

    proto_stream s = {1, 29.97f};
    assert_int_equal(proto_enc_stream(&b, 5, &s), 0);
    decode_one(&b, PROTO_C2S, &m, &pl);
    proto_stream s2;
    assert_int_equal(proto_parse_stream(m.payload, m.len, &s2, &e), 0);
    assert_int_equal(s2.on, 1);
    assert_true(s2.max_fps == 29.97f);
    free(pl);
    b.len = 0;

    proto_ping pg = {0xFEDCBA9876543210ull};
    assert_int_equal(proto_enc_ping(&b, 6, &pg), 0);
    decode_one(&b, PROTO_C2S, &m, &pl);
    proto_ping pg2;
    assert_int_equal(proto_parse_ping(m.payload, m.len, &pg2, &e), 0);
    assert_int_equal(pg2.token, pg.token);
    free(pl);
    b.len = 0;

    unsigned empties[3] = {PROTO_MSG_LIST, PROTO_MSG_RENDER, PROTO_MSG_BYE};
    for (int i = 0; i < 3; i++) {
        assert_int_equal(proto_enc_empty(&b, empties[i], 7u + (unsigned)i), 0);
        decode_one(&b, PROTO_C2S, &m, &pl);
        assert_int_equal(m.h.type, empties[i]);
        assert_int_equal(m.h.seq, 7u + (unsigned)i);
        assert_int_equal(proto_parse_empty(m.h.type, m.len, &e), 0);
        free(pl);
        b.len = 0;
    }
    assert_int_equal(proto_enc_empty(&b, PROTO_MSG_CAMERA, 1), -PROTO_E_INVALID_ARG);
    assert_int_equal(b.len, 0);
    proto_buf_free(&b);
}

static void test_roundtrip_server_messages(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_msg m;
    uint8_t *pl;
    proto_error e = {0};

    proto_welcome w = {.version = 1, .auth_required = 1, .authenticated = 0,
                       .max_request = 65536, .max_width = 8192, .max_height = 4096};
    for (int i = 0; i < 32; i++) w.challenge[i] = (uint8_t)(255 - i);
    strcpy(w.server, "splatd 0.1");
    strcpy(w.backend, "egl");
    strcpy(w.renderer, "llvmpipe (LLVM 15.0.6, 256 bits)");
    assert_int_equal(proto_enc_welcome(&b, 1, &w), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_welcome w2;
    assert_int_equal(proto_parse_welcome(m.payload, m.len, &w2, &e), 0);
    assert_int_equal(w2.version, 1);
    assert_int_equal(w2.auth_required, 1);
    assert_int_equal(w2.authenticated, 0);
    assert_memory_equal(w2.challenge, w.challenge, 32);
    assert_int_equal(w2.max_request, 65536);
    assert_int_equal(w2.max_width, 8192);
    assert_int_equal(w2.max_height, 4096);
    assert_string_equal(w2.server, w.server);
    assert_string_equal(w2.backend, w.backend);
    assert_string_equal(w2.renderer, w.renderer);
    free(pl);
    b.len = 0;

    proto_cloud_entry items[3] = {{"bun000.ply", 1234567, 40256, PROTO_CLOUD_PREPARED},
                                  {"autzen_trim.las", 1ull << 33, 0, 0},
                                  {"scan with spaces.pcd", 1, 2, 3}};
    assert_int_equal(proto_enc_clouds(&b, 2, items, 3), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_clouds cl;
    assert_int_equal(proto_parse_clouds(m.payload, m.len, &cl, &e), 0);
    assert_int_equal(cl.count, 3);
    for (int i = 0; i < 3; i++) {
        assert_string_equal(cl.items[i].name, items[i].name);
        assert_int_equal(cl.items[i].bytes, items[i].bytes);
        assert_int_equal(cl.items[i].points, items[i].points);
        assert_int_equal(cl.items[i].flags, items[i].flags);
    }
    proto_clouds_free(&cl);
    proto_clouds_free(&cl); /* safe twice */
    free(pl);
    b.len = 0;
    assert_int_equal(proto_enc_clouds(&b, 2, NULL, 0), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    assert_int_equal(proto_parse_clouds(m.payload, m.len, &cl, &e), 0);
    assert_int_equal(cl.count, 0);
    assert_null(cl.items);
    free(pl);
    b.len = 0;

    proto_info in = {.points = 40256, .dropped = 3, .bmin = {637000.25, 851000.5, 400.125},
                     .bmax = {639000.75, 853000, 500}, .offset = {638000.5, 852000.25, 450.0625},
                     .attrs = 0x53, .sigma = 0.00125f, .k = 24};
    strcpy(in.name, "autzen_trim.las");
    strcpy(in.format, "LAS 1.2 format 3");
    assert_int_equal(proto_enc_info(&b, 3, &in), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_info in2;
    assert_int_equal(proto_parse_info(m.payload, m.len, &in2, &e), 0);
    assert_string_equal(in2.name, in.name);
    assert_string_equal(in2.format, in.format);
    assert_int_equal(in2.points, in.points);
    assert_int_equal(in2.dropped, in.dropped);
    for (int i = 0; i < 3; i++) {
        assert_true(in2.bmin[i] == in.bmin[i]);
        assert_true(in2.bmax[i] == in.bmax[i]);
        assert_true(in2.offset[i] == in.offset[i]);
    }
    assert_int_equal(in2.attrs, 0x53);
    assert_true(in2.sigma == in.sigma);
    assert_int_equal(in2.k, 24);
    free(pl);
    b.len = 0;

    proto_progress pr = {PROTO_PHASE_KNN, 0.375f, "kNN 37%"};
    assert_int_equal(proto_enc_progress(&b, 3, &pr), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_progress pr2;
    assert_int_equal(proto_parse_progress(m.payload, m.len, &pr2, &e), 0);
    assert_int_equal(pr2.phase, PROTO_PHASE_KNN);
    assert_true(pr2.fraction == 0.375f);
    assert_string_equal(pr2.text, "kNN 37%");
    free(pl);
    b.len = 0;

    uint8_t img[2 * 3 * 4];
    for (int i = 0; i < (int)sizeof img; i++) img[i] = (uint8_t)(i * 13);
    proto_frame f = {.camera_seq = 41, .pipeline = SP_PIPE_SPLAT, .format = SP_FMT_RAW,
                     .width = 2, .height = 3, .render_us = 12345, .readback_us = 300,
                     .encode_us = 2000, .points_drawn = 1ull << 34, .data = img,
                     .data_len = sizeof img};
    assert_int_equal(proto_enc_frame(&b, 42, &f), 0);
    /* the zero-copy head produces the same leading bytes */
    uint8_t head[PROTO_FRAME_HEAD_LEN];
    proto_frame_head(head, 0, 42, &f);
    assert_memory_equal(head, b.data, PROTO_FRAME_HEAD_LEN);
    assert_int_equal(b.len, PROTO_FRAME_HEAD_LEN + sizeof img);
    decode_one(&b, PROTO_S2C, &m, &pl);
    assert_int_equal(m.h.seq, 42);
    proto_frame f2;
    assert_int_equal(proto_parse_frame(m.payload, m.len, &f2, &e), 0);
    assert_int_equal(f2.camera_seq, 41);
    assert_int_equal(f2.pipeline, SP_PIPE_SPLAT);
    assert_int_equal(f2.format, SP_FMT_RAW);
    assert_int_equal(f2.flags, 0);
    assert_int_equal(f2.width, 2);
    assert_int_equal(f2.height, 3);
    assert_int_equal(f2.render_us, 12345);
    assert_int_equal(f2.readback_us, 300);
    assert_int_equal(f2.encode_us, 2000);
    assert_int_equal(f2.points_drawn, 1ull << 34);
    assert_int_equal(f2.data_len, sizeof img);
    assert_memory_equal(f2.data, img, sizeof img);
    free(pl);
    b.len = 0;

    proto_pong po = {77, 123456789012ull};
    assert_int_equal(proto_enc_pong(&b, 9, &po), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_pong po2;
    assert_int_equal(proto_parse_pong(m.payload, m.len, &po2, &e), 0);
    assert_int_equal(po2.token, 77);
    assert_int_equal(po2.server_us, 123456789012ull);
    free(pl);
    b.len = 0;

    assert_int_equal(proto_enc_error(&b, 10, PROTO_E_NOT_FOUND, "no cloud 'x' in /data"), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    proto_errmsg em;
    assert_int_equal(proto_parse_error(m.payload, m.len, &em, &e), 0);
    assert_int_equal(em.code, PROTO_E_NOT_FOUND);
    assert_string_equal(em.text, "no cloud 'x' in /data");
    free(pl);
    b.len = 0;

    assert_int_equal(proto_enc_empty(&b, PROTO_MSG_OK, 11), 0);
    decode_one(&b, PROTO_S2C, &m, &pl);
    assert_int_equal(m.h.type, PROTO_MSG_OK);
    assert_int_equal(m.len, 0);
    free(pl);
    proto_buf_free(&b);
    proto_buf_free(&b);
}

/* ---- incremental decoding ---------------------------------------------------------------- */

static void test_byte_at_a_time(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_camera c = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0, 0, 64, 48};
    assert_int_equal(proto_enc_camera(&b, 1, &c), 0);
    assert_int_equal(proto_enc_empty(&b, PROTO_MSG_RENDER, 2), 0);
    proto_decoder d;
    proto_decoder_init(&d, PROTO_C2S);
    proto_error e = {0};
    proto_msg m;
    size_t first_end = PROTO_HEADER_LEN + 92;
    int got = 0;
    for (size_t i = 0; i < b.len; i++) {
        size_t used = 99;
        int rc = proto_decode(&d, b.data + i, 1, &used, &m, &e);
        assert_int_equal(used, 1);
        if (i + 1 == first_end) {
            assert_int_equal(rc, PROTO_ONE_MSG);
            assert_int_equal(m.h.type, PROTO_MSG_CAMERA);
            proto_camera c2;
            assert_int_equal(proto_parse_camera(m.payload, m.len, &c2, &e), 0);
            assert_true(c2.eye[2] == 5.0 && c2.width == 64);
            got++;
        } else if (i + 1 == b.len) {
            assert_int_equal(rc, PROTO_ONE_MSG); /* RENDER: header only, completes on byte 16 */
            assert_int_equal(m.h.type, PROTO_MSG_RENDER);
            assert_int_equal(m.len, 0);
            got++;
        } else {
            assert_int_equal(rc, PROTO_NEED_MORE);
        }
    }
    assert_int_equal(got, 2);
    /* an empty feed is NEED_MORE and consumes nothing */
    size_t used = 5;
    assert_int_equal(proto_decode(&d, b.data, 0, &used, &m, &e), PROTO_NEED_MORE);
    assert_int_equal(used, 0);
    proto_decoder_free(&d);
    proto_decoder_free(&d);
    proto_buf_free(&b);
}

static void test_back_to_back(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_ping p1 = {1}, p2 = {2};
    assert_int_equal(proto_enc_ping(&b, 10, &p1), 0);
    assert_int_equal(proto_enc_ping(&b, 11, &p2), 0);
    assert_int_equal(proto_enc_open(&b, 12, "a.ply"), 0);
    proto_decoder d;
    proto_decoder_init(&d, PROTO_C2S);
    proto_error e = {0};
    proto_msg m;
    size_t off = 0, used;
    uint32_t seqs[3];
    uint64_t toks[2];
    for (int k = 0; k < 3; k++) {
        assert_int_equal(proto_decode(&d, b.data + off, b.len - off, &used, &m, &e),
                         PROTO_ONE_MSG);
        off += used;
        seqs[k] = m.h.seq;
        if (k < 2) {
            proto_ping pp;
            assert_int_equal(proto_parse_ping(m.payload, m.len, &pp, &e), 0);
            toks[k] = pp.token;
        }
    }
    assert_int_equal(off, b.len);
    assert_int_equal(seqs[0], 10);
    assert_int_equal(seqs[1], 11);
    assert_int_equal(seqs[2], 12);
    assert_int_equal(toks[0], 1);
    assert_int_equal(toks[1], 2);
    assert_int_equal(proto_decode(&d, b.data + off, 0, &used, &m, &e), PROTO_NEED_MORE);
    proto_decoder_free(&d);
    proto_buf_free(&b);
}

/* ---- malformed headers -------------------------------------------------------------------- */

/* header_rc: decodes one raw header (plus len zero payload bytes if complete) with decoder d. */
static int header_rc(proto_decoder *d, uint32_t magic, uint16_t ver, uint16_t type, uint32_t len,
                     proto_error *e)
{
    uint8_t hb[16];
    proto_header h = {magic, ver, type, 1, len};
    proto_put_header(hb, &h);
    size_t used;
    proto_msg m;
    return proto_decode(d, hb, sizeof hb, &used, &m, e);
}

static void test_bad_headers(void **state)
{
    (void)state;
    proto_decoder d;
    proto_error e = {0};

    proto_decoder_init(&d, PROTO_C2S);
    assert_int_equal(header_rc(&d, 0x54504C53u, 1, PROTO_MSG_PING, 8, &e), -PROTO_E_BAD_MAGIC);
    assert_int_equal(e.code, PROTO_E_BAD_MAGIC);
    assert_non_null(strstr(e.msg, "magic"));
    /* sticky: the stream cannot be resynchronised */
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_PING, 8, &e), -PROTO_E_BAD_MAGIC);
    proto_decoder_free(&d);

    proto_decoder_init(&d, PROTO_C2S);
    d.version = 1;
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 2, PROTO_MSG_PING, 8, &e), -PROTO_E_BAD_VERSION);
    assert_non_null(strstr(e.msg, "version 2"));
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_C2S); /* before negotiation: any version but 0 */
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 0, PROTO_MSG_HELLO, 8, &e), -PROTO_E_BAD_VERSION);
    proto_decoder_free(&d);

    proto_decoder_init(&d, PROTO_C2S);
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, 77, 0, &e), -PROTO_E_UNKNOWN_TYPE);
    assert_non_null(strstr(e.msg, "77"));
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_C2S); /* a server message sent to the server */
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_FRAME, 0, &e), -PROTO_E_UNKNOWN_TYPE);
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_S2C); /* a client message sent to the client */
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_CAMERA, 0, &e), -PROTO_E_UNKNOWN_TYPE);
    proto_decoder_free(&d);

    /* pre-auth: only HELLO, at most 1 KiB */
    proto_decoder_init(&d, PROTO_C2S);
    d.preauth = 1;
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_LIST, 0, &e), -PROTO_E_AUTH_REQUIRED);
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_C2S);
    d.preauth = 1;
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_HELLO, PROTO_MAX_PREAUTH + 1, &e),
                     -PROTO_E_TOO_LARGE);
    assert_non_null(strstr(e.msg, "1024"));
    assert_non_null(strstr(e.msg, "before authentication"));
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_C2S);
    d.preauth = 1; /* exactly at the limit: accepted, waits for the payload */
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_HELLO, PROTO_MAX_PREAUTH, &e),
                     PROTO_NEED_MORE);
    proto_decoder_free(&d);

    /* post-auth: 64 KiB */
    proto_decoder_init(&d, PROTO_C2S);
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_PARAMS, PROTO_MAX_REQUEST + 1, &e),
                     -PROTO_E_TOO_LARGE);
    assert_non_null(strstr(e.msg, "65536"));
    proto_decoder_free(&d);
    proto_decoder_init(&d, PROTO_C2S);
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_PARAMS, PROTO_MAX_REQUEST, &e),
                     PROTO_NEED_MORE);
    assert_int_equal(d.cap, 0); /* nothing allocated before payload bytes arrive */
    proto_decoder_free(&d);
    /* the client's frame limit; a huge claimed length is refused before any allocation */
    proto_decoder_init(&d, PROTO_S2C);
    d.max_payload = PROTO_MAX_FRAME;
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_FRAME, 0xFFFFFFFFu, &e),
                     -PROTO_E_TOO_LARGE);
    assert_int_equal(d.cap, 0);
    proto_decoder_free(&d);
}

/* A frame header may claim up to the client's limit (256 MiB): the decoder's buffer follows
 * the bytes that arrive, so a header and 100 KiB of payload allocate 100 KiB, not 200 MiB; a
 * 300 KiB frame fed in growing pieces decodes intact. */
static void test_payload_grows_with_data(void **state)
{
    (void)state;
    proto_decoder d;
    proto_error e = {0};
    proto_msg m;
    size_t used;
    proto_decoder_init(&d, PROTO_S2C);
    d.max_payload = PROTO_MAX_FRAME;
    assert_int_equal(header_rc(&d, PROTO_MAGIC, 1, PROTO_MSG_FRAME, 200u << 20, &e),
                     PROTO_NEED_MORE);
    assert_int_equal(d.cap, 0);
    static uint8_t chunk[100 * 1024];
    memset(chunk, 7, sizeof chunk);
    assert_int_equal(proto_decode(&d, chunk, sizeof chunk, &used, &m, &e), PROTO_NEED_MORE);
    assert_int_equal(used, sizeof chunk);
    assert_int_equal(d.cap, sizeof chunk); /* what arrived, not the 200 MiB claimed */
    proto_decoder_free(&d);

    enum { LEN = 300 * 1024 };
    uint8_t *msg = malloc(16 + LEN);
    assert_non_null(msg);
    proto_header h = {PROTO_MAGIC, 1, PROTO_MSG_FRAME, 9, LEN};
    proto_put_header(msg, &h);
    for (uint32_t i = 0; i < LEN; i++) msg[16 + i] = (uint8_t)(i * 31 + 7);
    proto_decoder_init(&d, PROTO_S2C);
    d.max_payload = PROTO_MAX_FRAME;
    size_t at = 0, step = 1000;
    int rc = PROTO_NEED_MORE;
    while (rc == PROTO_NEED_MORE && at < 16 + (size_t)LEN) {
        size_t n = 16 + (size_t)LEN - at < step ? 16 + (size_t)LEN - at : step;
        rc = proto_decode(&d, msg + at, n, &used, &m, &e);
        at += used;
        assert_true(d.cap <= LEN);
        step = step * 3 / 2;
    }
    assert_int_equal(rc, PROTO_ONE_MSG);
    assert_int_equal(at, 16 + (size_t)LEN);
    assert_int_equal(m.len, LEN);
    assert_int_equal(m.h.seq, 9);
    assert_memory_equal(m.payload, msg + 16, LEN);
    proto_decoder_free(&d);
    free(msg);
}

/* ---- truncated and over-long payloads ---------------------------------------------------- */

typedef int (*parse_fn)(const uint8_t *pl, uint32_t len, proto_error *e);

static int p_hello(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_hello m; return proto_parse_hello(pl, len, &m, e); }
static int p_open(const uint8_t *pl, uint32_t len, proto_error *e)
{ char n[PROTO_MAX_NAME + 1]; return proto_parse_open(pl, len, n, e); }
static int p_camera(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_camera m; return proto_parse_camera(pl, len, &m, e); }
static int p_params(const uint8_t *pl, uint32_t len, proto_error *e)
{ sp_params p; sp_params_defaults(&p); return proto_parse_params(pl, len, &p, NULL, e); }
static int p_prefetch(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_prefetch m; return proto_parse_prefetch(pl, len, &m, e); }
static int p_stream(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_stream m; return proto_parse_stream(pl, len, &m, e); }
static int p_ping(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_ping m; return proto_parse_ping(pl, len, &m, e); }
static int p_welcome(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_welcome m; return proto_parse_welcome(pl, len, &m, e); }
static int p_clouds(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_clouds m; int rc = proto_parse_clouds(pl, len, &m, e); proto_clouds_free(&m); return rc; }
static int p_info(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_info m; return proto_parse_info(pl, len, &m, e); }
static int p_progress(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_progress m; return proto_parse_progress(pl, len, &m, e); }
static int p_frame(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_frame m; return proto_parse_frame(pl, len, &m, e); }
static int p_pong(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_pong m; return proto_parse_pong(pl, len, &m, e); }
static int p_error(const uint8_t *pl, uint32_t len, proto_error *e)
{ proto_errmsg m; return proto_parse_error(pl, len, &m, e); }

/* check_cuts: the payload of the one message in b parses; every shorter prefix (each field
 * short by one byte and everything before) is TRUNCATED; one byte more is MALFORMED (unless
 * the last field is open-ended, as FRAME's data). Payloads go through a malloc'd copy of
 * exactly the cut length so ASan catches any read past it. */
static void check_cuts(const proto_buf *b, parse_fn fn, uint32_t min_cut, int open_ended)
{
    uint32_t len = (uint32_t)(b->len - PROTO_HEADER_LEN);
    proto_error e = {0};
    uint8_t *full = malloc(len + 1);
    memcpy(full, b->data + PROTO_HEADER_LEN, len);
    if (fn(full, len, &e) != 0) fail_msg("full payload rejected: %s", e.msg);
    for (uint32_t cut = min_cut; cut < len; cut++) {
        uint8_t *p = malloc(cut ? cut : 1);
        memcpy(p, full, cut);
        memset(&e, 0, sizeof e);
        int rc = fn(p, cut, &e);
        if (rc != -PROTO_E_TRUNCATED)
            fail_msg("cut at %u of %u: rc %d (%s), expected TRUNCATED", cut, len, rc, e.msg);
        assert_non_null(strstr(e.msg, "truncated") ? e.msg : strstr(e.msg, "needs"));
        free(p);
    }
    if (!open_ended) {
        full[len] = 0;
        assert_int_equal(fn(full, len + 1, &e), -PROTO_E_MALFORMED);
        assert_non_null(strstr(e.msg, "unexpected bytes"));
    }
    free(full);
}

static void test_truncated_payloads(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_hello h = {.min_version = 1, .max_version = 1, .client = "c", .proof_len = 32};
    proto_enc_hello(&b, 1, &h);
    check_cuts(&b, p_hello, 0, 0);
    b.len = 0;
    proto_enc_open(&b, 1, "bun000.ply");
    check_cuts(&b, p_open, 0, 0);
    b.len = 0;
    proto_camera c = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0, 0, 64, 48};
    proto_enc_camera(&b, 1, &c);
    check_cuts(&b, p_camera, 0, 0);
    b.len = 0;
    sp_params p;
    sp_params_defaults(&p);
    proto_param_rec recs[SP_PARAM_COUNT];
    for (int i = 0; i < SP_PARAM_COUNT; i++) proto_param_rec_from(&p, i, &recs[i]);
    proto_enc_params(&b, 1, recs, SP_PARAM_COUNT); /* every type: enum, float, int, vec3 */
    check_cuts(&b, p_params, 0, 0);
    b.len = 0;
    proto_stream s = {1, 30};
    proto_enc_stream(&b, 1, &s);
    check_cuts(&b, p_stream, 0, 0);
    b.len = 0;
    proto_ping pg = {5};
    proto_enc_ping(&b, 1, &pg);
    check_cuts(&b, p_ping, 0, 0);
    b.len = 0;
    proto_welcome w = {.version = 1, .server = "s", .backend = "egl", .renderer = "r"};
    proto_enc_welcome(&b, 1, &w);
    check_cuts(&b, p_welcome, 0, 0);
    b.len = 0;
    proto_cloud_entry items[2] = {{"a.ply", 1, 2, 0}, {"bb.las", 3, 4, 1}};
    proto_enc_clouds(&b, 1, items, 2);
    check_cuts(&b, p_clouds, 0, 0);
    b.len = 0;
    proto_info in = {.name = "a.ply", .points = 3, .format = "PLY ascii 1.0"};
    proto_enc_info(&b, 1, &in);
    check_cuts(&b, p_info, 0, 0);
    b.len = 0;
    proto_progress pr = {1, 0.5f, "half"};
    proto_enc_progress(&b, 1, &pr);
    check_cuts(&b, p_progress, 0, 0);
    b.len = 0;
    uint8_t jpg[10] = {0xFF, 0xD8};
    proto_frame f = {.camera_seq = 1, .format = SP_FMT_JPEG, .width = 4, .height = 4,
                     .data = jpg, .data_len = sizeof jpg};
    proto_enc_frame(&b, 1, &f);
    /* the data is the rest of the payload: cuts inside the fixed 48 bytes are TRUNCATED */
    b.len = PROTO_HEADER_LEN + PROTO_FRAME_FIXED;
    check_cuts(&b, p_frame, 0, 1);
    b.len = 0;
    proto_pong po = {1, 2};
    proto_enc_pong(&b, 1, &po);
    check_cuts(&b, p_pong, 0, 0);
    b.len = 0;
    proto_enc_error(&b, 1, PROTO_E_INTERNAL, "boom");
    check_cuts(&b, p_error, 0, 0);
    proto_buf_free(&b);
}

static void test_malformed_payloads(void **state)
{
    (void)state;
    proto_error e = {0};
    uint8_t buf[64];
    /* NUL inside a string */
    uint8_t open_nul[] = {3, 'a', 0, 'b'};
    char name[PROTO_MAX_NAME + 1];
    assert_int_equal(proto_parse_open(open_nul, sizeof open_nul, name, &e), -PROTO_E_MALFORMED);
    assert_non_null(strstr(e.msg, "NUL"));
    /* HELLO proof_len other than 0 or 32 */
    uint8_t hello_bad[] = {1, 0, 1, 0, 0, 5, 1, 2, 3, 4, 5};
    proto_hello h;
    assert_int_equal(proto_parse_hello(hello_bad, sizeof hello_bad, &h, &e), -PROTO_E_MALFORMED);
    /* HELLO with min > max */
    uint8_t hello_rng[] = {3, 0, 1, 0, 0, 0};
    assert_int_equal(proto_parse_hello(hello_rng, sizeof hello_rng, &h, &e), -PROTO_E_MALFORMED);
    /* CLOUDS count far beyond the payload: refused before allocating */
    proto_put_u32(buf, 0xFFFFFFFFu);
    proto_clouds cl;
    assert_int_equal(proto_parse_clouds(buf, 4, &cl, &e), -PROTO_E_TRUNCATED);
    assert_null(cl.items);
    /* FRAME raw with the wrong data length, unknown format */
    proto_frame f = {.format = SP_FMT_RAW, .width = 2, .height = 2, .data = buf, .data_len = 15};
    proto_buf b = {0};
    proto_enc_frame(&b, 1, &f);
    proto_frame f2;
    assert_int_equal(proto_parse_frame(b.data + 16, (uint32_t)b.len - 16, &f2, &e),
                     -PROTO_E_MALFORMED);
    assert_non_null(strstr(e.msg, "needs 16"));
    b.len = 0;
    f.format = 200;
    proto_enc_frame(&b, 1, &f);
    assert_int_equal(proto_parse_frame(b.data + 16, (uint32_t)b.len - 16, &f2, &e),
                     -PROTO_E_MALFORMED);
    b.len = 0;
    /* STREAM */
    proto_stream s = {2, 0};
    proto_enc_stream(&b, 1, &s);
    proto_stream s2;
    assert_int_equal(proto_parse_stream(b.data + 16, 5, &s2, &e), -PROTO_E_MALFORMED);
    b.len = 0;
    s.on = 1;
    s.max_fps = -1;
    proto_enc_stream(&b, 1, &s);
    assert_int_equal(proto_parse_stream(b.data + 16, 5, &s2, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "max_fps"));
    b.len = 0;
    /* empty messages with a payload */
    assert_int_equal(proto_parse_empty(PROTO_MSG_LIST, 1, &e), -PROTO_E_MALFORMED);
    assert_non_null(strstr(e.msg, "LIST"));
    /* ERROR code 0, over-long text from the encoder is cut to the limit */
    uint8_t err0[] = {0, 0, 0, 0, 0, 0};
    proto_errmsg em;
    assert_int_equal(proto_parse_error(err0, sizeof err0, &em, &e), -PROTO_E_MALFORMED);
    char *longtext = malloc(5000);
    memset(longtext, 'x', 4999);
    longtext[4999] = 0;
    assert_int_equal(proto_enc_error(&b, 1, PROTO_E_INTERNAL, longtext), 0);
    assert_int_equal(proto_parse_error(b.data + 16, (uint32_t)b.len - 16, &em, &e), 0);
    assert_int_equal(strlen(em.text), PROTO_MAX_ERRTEXT);
    free(longtext);
    b.len = 0;
    /* encoders refuse strings over their limit and leave the buffer unchanged */
    char big[300];
    memset(big, 'a', 299);
    big[299] = 0;
    assert_int_equal(proto_enc_open(&b, 1, big), -PROTO_E_INVALID_ARG);
    assert_int_equal(b.len, 0);
    proto_hello hb = {.min_version = 1, .max_version = 1, .proof_len = 7};
    assert_int_equal(proto_enc_hello(&b, 1, &hb), -PROTO_E_INVALID_ARG);
    assert_int_equal(b.len, 0);
    proto_buf_free(&b);
}

/* PREFETCH: count, then CAMERA payloads: round trip; count 0, 17 and a count the payload does
 * not hold are refused; a bad camera is named by its index. */
static void test_prefetch(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_error e = {0};
    proto_camera good = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0.5f, 90, 64, 48};
    proto_prefetch in = {.count = 3}, out;
    for (int k = 0; k < 3; k++) {
        in.cams[k] = good;
        in.cams[k].eye[0] = k + 0.25;
        in.cams[k].width = 64 + (uint32_t)k;
    }
    assert_int_equal(proto_enc_prefetch(&b, 7, &in), 0);
    assert_int_equal(b.len, 16 + 1 + 3 * 92);
    assert_int_equal(b.data[16], 3);
    assert_int_equal(proto_parse_prefetch(b.data + 16, (uint32_t)b.len - 16, &out, &e), 0);
    assert_int_equal(out.count, 3);
    for (int k = 0; k < 3; k++) {
        assert_true(out.cams[k].eye[0] == k + 0.25);
        assert_int_equal(out.cams[k].width, 64 + k);
        assert_true(out.cams[k].zfar == 90);
    }
    /* the count claims 3 cameras, the payload holds 2 */
    assert_int_equal(proto_parse_prefetch(b.data + 16, 1 + 2 * 92, &out, &e), -PROTO_E_TRUNCATED);
    /* count 0 and 17 */
    uint8_t zero = 0;
    assert_int_equal(proto_parse_prefetch(&zero, 1, &out, &e), -PROTO_E_MALFORMED);
    assert_non_null(strstr(e.msg, "count 0"));
    uint8_t big[1 + 17 * 92] = {17};
    assert_int_equal(proto_parse_prefetch(big, sizeof big, &out, &e), -PROTO_E_MALFORMED);
    in.count = 17;
    assert_int_equal(proto_enc_prefetch(&b, 7, &in), -PROTO_E_INVALID_ARG);
    in.count = 0;
    assert_int_equal(proto_enc_prefetch(&b, 7, &in), -PROTO_E_INVALID_ARG);
    /* a bad camera is named by its index */
    in.count = 3;
    in.cams[2].fov_deg = 0;
    b.len = 0;
    assert_int_equal(proto_enc_prefetch(&b, 7, &in), 0);
    assert_int_equal(proto_parse_prefetch(b.data + 16, (uint32_t)b.len - 16, &out, &e),
                     -PROTO_E_BAD_CAMERA);
    assert_non_null(strstr(e.msg, "PREFETCH camera 2"));
    assert_non_null(strstr(e.msg, "fov"));
    proto_buf_free(&b);
}

static void test_camera_validation(void **state)
{
    (void)state;
    proto_buf b = {0};
    proto_error e = {0};
    proto_camera good = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0, 0, 64, 48};
    struct { const char *what; proto_camera c; const char *needle; } bad[] = {
        {"fov 0", good, "fov"}, {"fov 180", good, "fov"}, {"eye nan", good, "not finite"},
        {"near>far", good, "near"}, {"width 0", good, "size"}, {"height big", good, "size"},
        {"eye==target", good, "same point"}, {"up parallel", good, "parallel"},
        {"negative far", good, "near"},
    };
    bad[0].c.fov_deg = 0;
    bad[1].c.fov_deg = 180;
    bad[2].c.eye[1] = NAN;
    bad[3].c.znear = 10;
    bad[3].c.zfar = 5;
    bad[4].c.width = 0;
    bad[5].c.height = PROTO_MAX_DIM + 1;
    bad[6].c.eye[2] = 0;
    bad[7].c.up[0] = 0; bad[7].c.up[1] = 0; bad[7].c.up[2] = -2;
    bad[8].c.zfar = -1;
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        b.len = 0;
        assert_int_equal(proto_enc_camera(&b, 1, &bad[i].c), 0);
        proto_camera out;
        int rc = proto_parse_camera(b.data + 16, (uint32_t)b.len - 16, &out, &e);
        if (rc != -PROTO_E_BAD_CAMERA || !strstr(e.msg, bad[i].needle))
            fail_msg("%s: rc %d msg '%s'", bad[i].what, rc, e.msg);
    }
    /* near alone, far alone, and the largest size are fine */
    good.znear = 0.5f;
    good.width = PROTO_MAX_DIM;
    b.len = 0;
    proto_enc_camera(&b, 1, &good);
    proto_camera out;
    assert_int_equal(proto_parse_camera(b.data + 16, (uint32_t)b.len - 16, &out, &e), 0);
    proto_buf_free(&b);
}

/* ---- every limit at its boundary ----------------------------------------------------------- */

/* PAYLOAD: the payload of the one message encoded in proto_buf b, as (pointer, length). */
#define PAYLOAD(b) ((b).data + PROTO_HEADER_LEN), ((uint32_t)(b).len - PROTO_HEADER_LEN)

/* Each limit of PROTOCOL.md section 3 and section 5 is checked on both sides: the largest (or
 * smallest) value allowed parses, the next one is refused with its code. One side alone lets a
 * check that is off by one, or missing, pass; the limits below are each exercised in full, not
 * through one example field (width and height both, each flag of WELCOME, each end of a range). */
static void test_limits_at_the_boundary(void **state)
{
    (void)state;
    proto_error e = {0};
    uint8_t pl[2048];

    /* HELLO client name: 64 bytes parse, 65 are MALFORMED (written by hand: the struct cannot
     * hold a longer name for the encoder). */
    for (unsigned n = PROTO_MAX_CLIENT; n <= PROTO_MAX_CLIENT + 1; n++) {
        size_t o = 0;
        proto_put_u16(pl + o, 1); o += 2;
        proto_put_u16(pl + o, 1); o += 2;
        pl[o++] = (uint8_t)n;
        memset(pl + o, 'c', n); o += n;
        pl[o++] = 0; /* proof_len */
        proto_hello h;
        int rc = proto_parse_hello(pl, (uint32_t)o, &h, &e);
        if (n == PROTO_MAX_CLIENT) {
            assert_int_equal(rc, 0);
            assert_int_equal(strlen(h.client), PROTO_MAX_CLIENT);
        } else {
            assert_int_equal(rc, -PROTO_E_MALFORMED);
            assert_non_null(strstr(e.msg, "client"));
        }
    }
    proto_buf b = {0};
    proto_hello hl = {.min_version = 1, .max_version = 1};
    memset(hl.client, 'c', PROTO_MAX_CLIENT);
    assert_int_equal(proto_enc_hello(&b, 1, &hl), 0); /* the encoder takes the longest name */

    /* ERROR text: 1024 bytes parse, 1025 are MALFORMED. */
    for (unsigned n = PROTO_MAX_ERRTEXT; n <= PROTO_MAX_ERRTEXT + 1; n++) {
        uint8_t *ep = malloc(6 + n);
        proto_put_u32(ep, PROTO_E_INTERNAL);
        proto_put_u16(ep + 4, (uint16_t)n);
        memset(ep + 6, 't', n);
        proto_errmsg em;
        int rc = proto_parse_error(ep, 6 + n, &em, &e);
        if (n == PROTO_MAX_ERRTEXT) {
            assert_int_equal(rc, 0);
            assert_int_equal(strlen(em.text), PROTO_MAX_ERRTEXT);
        } else {
            assert_int_equal(rc, -PROTO_E_MALFORMED);
            assert_non_null(strstr(e.msg, "text_len"));
        }
        free(ep);
    }

    /* CAMERA width and height: each 1 and 16384 are fine, 0 and 16385 are BAD_CAMERA. */
    for (int which = 0; which < 2; which++) {
        static const uint32_t vals[] = {0, 1, PROTO_MAX_DIM, PROTO_MAX_DIM + 1};
        for (size_t k = 0; k < sizeof vals / sizeof vals[0]; k++) {
            proto_camera c = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0, 0, 64, 48};
            if (which) c.height = vals[k];
            else c.width = vals[k];
            b.len = 0;
            assert_int_equal(proto_enc_camera(&b, 1, &c), 0);
            proto_camera out;
            int rc = proto_parse_camera(PAYLOAD(b), &out, &e);
            int ok = vals[k] >= 1 && vals[k] <= PROTO_MAX_DIM;
            if (rc != (ok ? 0 : -PROTO_E_BAD_CAMERA))
                fail_msg("CAMERA %s %u: rc %d (%s)", which ? "height" : "width", vals[k], rc, e.msg);
        }
    }

    /* FRAME width and height: the same range, MALFORMED outside it. */
    for (int which = 0; which < 2; which++) {
        static const uint32_t vals[] = {0, 1, PROTO_MAX_DIM, PROTO_MAX_DIM + 1};
        for (size_t k = 0; k < sizeof vals / sizeof vals[0]; k++) {
            uint8_t jpg[4] = {0xFF, 0xD8, 0xFF, 0xD9};
            proto_frame f = {.format = SP_FMT_JPEG, .width = 8, .height = 8, .data = jpg, .data_len = 4};
            if (which) f.height = vals[k];
            else f.width = vals[k];
            b.len = 0;
            assert_int_equal(proto_enc_frame(&b, 1, &f), 0);
            proto_frame out;
            int rc = proto_parse_frame(PAYLOAD(b), &out, &e);
            int ok = vals[k] >= 1 && vals[k] <= PROTO_MAX_DIM;
            if (rc != (ok ? 0 : -PROTO_E_MALFORMED))
                fail_msg("FRAME %s %u: rc %d (%s)", which ? "height" : "width", vals[k], rc, e.msg);
        }
    }

    /* STREAM max_fps: 0 and 1000 are fine; just above 1000, below 0 and NaN are BAD_PARAM_VALUE. */
    {
        static const float fps[] = {0.0f, 1000.0f, 1000.0001f, -0.0001f, NAN, INFINITY};
        static const int ok[] = {1, 1, 0, 0, 0, 0};
        for (size_t k = 0; k < sizeof fps / sizeof fps[0]; k++) {
            b.len = 0;
            assert_int_equal(proto_enc_stream(&b, 1, &(proto_stream){.on = 1, .max_fps = fps[k]}), 0);
            proto_stream out;
            int rc = proto_parse_stream(PAYLOAD(b), &out, &e);
            if (rc != (ok[k] ? 0 : -PROTO_E_BAD_PARAM_VALUE))
                fail_msg("STREAM max_fps %g: rc %d (%s)", (double)fps[k], rc, e.msg);
        }
    }

    /* PROGRESS: the last phase and fractions 0 and 1 are fine; the phase after it, a fraction
     * below 0 or above 1, and NaN are MALFORMED. */
    {
        static const struct { uint8_t phase; float fraction; int ok; } cases[] = {
            {PROTO_PHASE_COUNT - 1, 1.0f, 1}, {0, 0.0f, 1}, {PROTO_PHASE_COUNT, 0.5f, 0},
            {0, 1.0001f, 0}, {0, -0.0001f, 0}, {0, NAN, 0},
        };
        for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
            b.len = 0;
            proto_progress pr = {.phase = cases[k].phase, .fraction = cases[k].fraction};
            assert_int_equal(proto_enc_progress(&b, 1, &pr), 0);
            proto_progress out;
            int rc = proto_parse_progress(PAYLOAD(b), &out, &e);
            if (rc != (cases[k].ok ? 0 : -PROTO_E_MALFORMED))
                fail_msg("PROGRESS phase %u fraction %g: rc %d (%s)", cases[k].phase,
                         (double)cases[k].fraction, rc, e.msg);
        }
    }

    /* WELCOME: auth_required and authenticated are each 0 or 1, the version is not 0. */
    {
        static const struct { uint16_t version; uint8_t req, authd; int ok; } cases[] = {
            {1, 0, 0, 1}, {1, 1, 1, 1}, {1, 2, 0, 0}, {1, 0, 2, 0}, {0, 0, 1, 0},
        };
        for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
            b.len = 0;
            proto_welcome w = {.version = cases[k].version, .auth_required = cases[k].req,
                               .authenticated = cases[k].authd, .server = "s", .backend = "b",
                               .renderer = "r"};
            assert_int_equal(proto_enc_welcome(&b, 1, &w), 0);
            proto_welcome out;
            int rc = proto_parse_welcome(PAYLOAD(b), &out, &e);
            if (rc != (cases[k].ok ? 0 : -PROTO_E_MALFORMED))
                fail_msg("WELCOME version %u auth_required %u authenticated %u: rc %d (%s)",
                         cases[k].version, cases[k].req, cases[k].authd, rc, e.msg);
        }
    }

    /* PARAMS count: 64 records parse, a count of 65 is MALFORMED before any record is read. */
    {
        sp_params p;
        sp_params_defaults(&p);
        proto_param_rec recs[PROTO_MAX_PARAMS];
        for (unsigned i = 0; i < PROTO_MAX_PARAMS; i++)
            proto_param_rec_from(&p, sp_param_find("quality"), &recs[i]);
        b.len = 0;
        assert_int_equal(proto_enc_params(&b, 1, recs, PROTO_MAX_PARAMS), 0);
        assert_int_equal(proto_parse_params(PAYLOAD(b), &p, NULL, &e), 0);
        proto_put_u16(b.data + PROTO_HEADER_LEN, PROTO_MAX_PARAMS + 1);
        assert_int_equal(proto_parse_params(PAYLOAD(b), &p, NULL, &e),
                         -PROTO_E_MALFORMED);
    }
    proto_buf_free(&b);
}

/* ---- PARAMS validation --------------------------------------------------------------------- */

static int params_rc(const proto_param_rec *recs, unsigned n, sp_params *p, proto_error *e)
{
    proto_buf b = {0};
    assert_int_equal(proto_enc_params(&b, 1, recs, n), 0);
    int rc = proto_parse_params(b.data + 16, (uint32_t)b.len - 16, p, NULL, e);
    proto_buf_free(&b);
    return rc;
}

static void test_params_validation(void **state)
{
    (void)state;
    sp_params p, def;
    sp_params_defaults(&def);
    proto_error e = {0};
    proto_param_rec r[2];
    memset(r, 0, sizeof r);

    /* a good record first, then an unknown one: nothing is applied */
    p = def;
    proto_param_rec_from(&p, SP_QUALITY, &r[0]);
    r[0].u.i = 10;
    strcpy(r[1].name, "splat_scael");
    r[1].type = SP_T_FLOAT;
    r[1].u.f = 1;
    assert_int_equal(params_rc(r, 2, &p, &e), -PROTO_E_BAD_PARAM_NAME);
    assert_int_equal(e.code, PROTO_E_BAD_PARAM_NAME);
    assert_non_null(strstr(e.msg, "'splat_scael'"));
    assert_memory_equal(&p, &def, sizeof p);

    /* float out of range names the parameter and the range */
    proto_param_rec_from(&p, SP_SPLAT_SCALE, &r[0]);
    r[0].u.f = 500;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "'splat_scale'"));
    assert_non_null(strstr(e.msg, "[0.01, 100]"));
    assert_memory_equal(&p, &def, sizeof p);
    r[0].u.f = NAN;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);

    /* int out of range */
    proto_param_rec_from(&p, SP_QUALITY, &r[0]);
    r[0].u.i = 101;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "'quality'"));
    assert_non_null(strstr(e.msg, "[1, 100]"));

    /* enum index past the list names the values */
    proto_param_rec_from(&p, SP_PIPELINE, &r[0]);
    int npipes = 1; /* one past the last value of the list, however long it grows */
    for (const char *s = sp_param_table[SP_PIPELINE].values; *s; s++) npipes += *s == '|';
    r[0].u.e = npipes;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "'pipeline'"));
    assert_non_null(strstr(e.msg, sp_param_table[SP_PIPELINE].values));
    r[0].u.e = -1;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);

    /* vec3 component out of range */
    proto_param_rec_from(&p, SP_BACKGROUND, &r[0]);
    r[0].u.v[2] = 1.5f;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "'background'"));
    assert_non_null(strstr(e.msg, "component 2"));

    /* type mismatch: quality sent as a float */
    memset(&r[0], 0, sizeof r[0]);
    strcpy(r[0].name, "quality");
    r[0].type = SP_T_FLOAT;
    r[0].u.f = 50;
    assert_int_equal(params_rc(r, 1, &p, &e), -PROTO_E_BAD_PARAM_VALUE);
    assert_non_null(strstr(e.msg, "is a int"));
    assert_memory_equal(&p, &def, sizeof p);

    /* an unknown value type byte breaks the structure: MALFORMED */
    uint8_t raw[] = {1, 0, 7, 'q', 'u', 'a', 'l', 'i', 't', 'y', 9, 0, 0, 0, 0};
    assert_int_equal(proto_parse_params(raw, sizeof raw, &p, NULL, &e), -PROTO_E_MALFORMED);
    /* count over the limit */
    uint8_t many[] = {65, 0};
    assert_int_equal(proto_parse_params(many, sizeof many, &p, NULL, &e), -PROTO_E_MALFORMED);
    /* zero records: valid, nothing changes */
    uint8_t none[] = {0, 0};
    uint64_t ch = 99;
    assert_int_equal(proto_parse_params(none, sizeof none, &p, &ch, &e), 0);
    assert_int_equal(ch, 0);
    /* edges of a range are inside it */
    proto_param_rec_from(&p, SP_QUALITY, &r[0]);
    r[0].u.i = 100;
    proto_param_rec_from(&p, SP_SPLAT_SCALE, &r[1]);
    r[1].u.f = 0.01f; /* the float nearest 0.01 is 0.0099999998, below the double 0.01 */
    assert_int_equal(params_rc(r, 2, &p, &e), 0);
    assert_int_equal(p.quality, 100);
    assert_true(p.splat_scale == 0.01f);
}

/* ---- cloud names --------------------------------------------------------------------------- */

static void test_cloud_names(void **state)
{
    (void)state;
    proto_error e = {0};
    const char *good[] = {"bun000.ply", "bun000", "Guanyin.ply", "scan 2024 (1).las", "a..b",
                          "x~", "données.pcd"};
    for (size_t i = 0; i < sizeof good / sizeof good[0]; i++)
        if (proto_name_check(good[i], &e) != 0) fail_msg("'%s' refused: %s", good[i], e.msg);
    const char *bad[] = {"", "..", ".", "/etc/passwd", "a/b", "../x", "a/../b", "..\\x",
                         "C:x", ".hidden", " lead", "trail ", "tab\tname", "del\x7f"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        memset(&e, 0, sizeof e);
        if (proto_name_check(bad[i], &e) != -PROTO_E_BAD_NAME)
            fail_msg("'%s' accepted", bad[i]);
        assert_int_equal(e.code, PROTO_E_BAD_NAME);
        assert_true(strlen(e.msg) > 10);
    }
    char longname[300];
    memset(longname, 'a', 256);
    longname[256] = 0;
    assert_int_equal(proto_name_check(longname, &e), -PROTO_E_BAD_NAME);
    /* OPEN applies the check */
    proto_buf b = {0};
    proto_enc_open(&b, 1, "../../etc/shadow");
    char name[PROTO_MAX_NAME + 1];
    assert_int_equal(proto_parse_open(b.data + 16, (uint32_t)b.len - 16, name, &e),
                     -PROTO_E_BAD_NAME);
    b.len = 0;
    proto_enc_open(&b, 1, "/abs/path.ply");
    assert_int_equal(proto_parse_open(b.data + 16, (uint32_t)b.len - 16, name, &e),
                     -PROTO_E_BAD_NAME);
    proto_buf_free(&b);
}

/* ---- random input -------------------------------------------------------------------------- */

static uint64_t rng_next(uint64_t *s)
{
    /* xorshift64*: deterministic, so a failure reproduces */
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    return *s * 2685821657736338717ull;
}

/* parse_any: runs the parser of m's type; returns its result. */
static int parse_any(const proto_msg *m, proto_error *e)
{
    switch (m->h.type) {
    case PROTO_MSG_HELLO: return p_hello(m->payload, m->len, e);
    case PROTO_MSG_OPEN: return p_open(m->payload, m->len, e);
    case PROTO_MSG_CAMERA: return p_camera(m->payload, m->len, e);
    case PROTO_MSG_PARAMS: return p_params(m->payload, m->len, e);
    case PROTO_MSG_STREAM: return p_stream(m->payload, m->len, e);
    case PROTO_MSG_PREFETCH: return p_prefetch(m->payload, m->len, e);
    case PROTO_MSG_PING: return p_ping(m->payload, m->len, e);
    case PROTO_MSG_WELCOME: return p_welcome(m->payload, m->len, e);
    case PROTO_MSG_CLOUDS: return p_clouds(m->payload, m->len, e);
    case PROTO_MSG_INFO: return p_info(m->payload, m->len, e);
    case PROTO_MSG_PROGRESS: return p_progress(m->payload, m->len, e);
    case PROTO_MSG_FRAME: return p_frame(m->payload, m->len, e);
    case PROTO_MSG_PONG: return p_pong(m->payload, m->len, e);
    case PROTO_MSG_ERROR: return p_error(m->payload, m->len, e);
    default: return proto_parse_empty(m->h.type, m->len, e);
    }
}

static void test_fuzz(void **state)
{
    (void)state;
    /* Seeds: one valid message of every type; each round mutates one (or makes pure noise)
     * and runs it through a decoder with random settings and the matching parser. The test
     * asserts only that results are in the documented set; ASan/UBSan catch the rest. */
    proto_buf seeds = {0};
    proto_hello h = {.min_version = 1, .max_version = 1, .client = "f", .proof_len = 32};
    proto_enc_hello(&seeds, 1, &h);
    proto_enc_open(&seeds, 2, "bun000.ply");
    proto_camera c = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 60, 0, 0, 64, 48};
    proto_enc_camera(&seeds, 3, &c);
    sp_params p;
    sp_params_defaults(&p);
    proto_param_rec recs[SP_PARAM_COUNT];
    for (int i = 0; i < SP_PARAM_COUNT; i++) proto_param_rec_from(&p, i, &recs[i]);
    proto_enc_params(&seeds, 4, recs, SP_PARAM_COUNT);
    proto_stream s = {1, 30};
    proto_enc_stream(&seeds, 5, &s);
    proto_prefetch pf = {.count = 2, .cams = {c, c}};
    pf.cams[1].eye[0] = 3;
    proto_enc_prefetch(&seeds, 13, &pf);
    proto_welcome w = {.version = 1, .server = "s", .backend = "egl", .renderer = "r"};
    proto_enc_welcome(&seeds, 6, &w);
    proto_cloud_entry items[2] = {{"a.ply", 1, 2, 0}, {"bb.las", 3, 4, 1}};
    proto_enc_clouds(&seeds, 7, items, 2);
    proto_info in = {.name = "a.ply", .points = 3, .format = "PLY ascii 1.0"};
    proto_enc_info(&seeds, 8, &in);
    proto_progress pr = {1, 0.5f, "half"};
    proto_enc_progress(&seeds, 9, &pr);
    uint8_t px[16] = {1};
    proto_frame f = {.format = SP_FMT_RAW, .width = 2, .height = 2, .data = px, .data_len = 16};
    proto_enc_frame(&seeds, 10, &f);
    proto_enc_error(&seeds, 11, 5, "x");
    proto_pong po = {1, 2};
    proto_enc_pong(&seeds, 12, &po);
    /* split the seed stream into messages */
    size_t starts[32], nseed = 0, off = 0;
    while (off < seeds.len && nseed < 32) {
        starts[nseed++] = off;
        off += PROTO_HEADER_LEN + proto_get_u32(seeds.data + off + 12);
    }
    starts[nseed] = seeds.len;

    uint64_t rng = 0x9E3779B97F4A7C15ull;
    uint8_t *buf = malloc(4096);
    long msgs = 0, errs = 0;
    for (int round = 0; round < 100000; round++) {
        size_t len;
        uint64_t r = rng_next(&rng);
        if (r % 8 == 0) { /* pure noise, sometimes with a valid magic */
            len = (size_t)(rng_next(&rng) % 200);
            for (size_t i = 0; i < len; i++) buf[i] = (uint8_t)rng_next(&rng);
            if (len >= 4 && (r & 16)) proto_put_u32(buf, PROTO_MAGIC);
        } else {
            size_t k = (size_t)(rng_next(&rng) % nseed);
            len = starts[k + 1] - starts[k];
            memcpy(buf, seeds.data + starts[k], len);
            int flips = 1 + (int)(rng_next(&rng) % 4);
            for (int i = 0; i < flips; i++) {
                size_t at = (size_t)(rng_next(&rng) % len);
                if (rng_next(&rng) & 1) buf[at] ^= (uint8_t)(1u << (rng_next(&rng) % 8));
                else buf[at] = (uint8_t)rng_next(&rng);
            }
            if (r & 32) len = (size_t)(rng_next(&rng) % (len + 1)); /* cut */
        }
        proto_decoder d;
        /* mostly either direction, sometimes one; pre-auth one time in eight */
        proto_decoder_init(&d, ((r >> 40) & 3) == 3 ? (uint8_t)(1 + ((r >> 42) & 1)) : 0);
        d.preauth = ((r >> 50) & 7) == 0;
        d.version = (r >> 51) & 1;
        size_t pos = 0, used;
        proto_msg m;
        proto_error e;
        while (pos <= len) {
            /* feed in random chunks to exercise the partial paths */
            size_t chunk = 1 + (size_t)(rng_next(&rng) % 64);
            if (chunk > len - pos) chunk = len - pos;
            int rc = proto_decode(&d, buf + pos, chunk, &used, &m, &e);
            assert_true(used <= chunk);
            pos += used;
            if (rc == PROTO_ONE_MSG) {
                msgs++;
                int prc = parse_any(&m, &e);
                assert_true(prc == 0 || (prc < 0 && e.code == -prc && e.msg[0]));
                continue;
            }
            if (rc < 0) {
                errs++;
                assert_int_equal(e.code, -rc);
                break;
            }
            if (pos == len) break;
        }
        proto_decoder_free(&d);
    }
    /* the mutations must reach both sides: messages that decode and headers that fail */
    print_message("fuzz: %ld messages decoded, %ld decoder errors\n", msgs, errs);
    assert_true(msgs > 10000);
    assert_true(errs > 10000);
    free(buf);
    proto_buf_free(&seeds);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_le_helpers),
        cmocka_unit_test(test_names_and_codes),
        cmocka_unit_test(test_roundtrip_client_messages),
        cmocka_unit_test(test_roundtrip_server_messages),
        cmocka_unit_test(test_byte_at_a_time),
        cmocka_unit_test(test_back_to_back),
        cmocka_unit_test(test_bad_headers),
        cmocka_unit_test(test_payload_grows_with_data),
        cmocka_unit_test(test_truncated_payloads),
        cmocka_unit_test(test_malformed_payloads),
        cmocka_unit_test(test_camera_validation),
        cmocka_unit_test(test_prefetch),
        cmocka_unit_test(test_limits_at_the_boundary),
        cmocka_unit_test(test_params_validation),
        cmocka_unit_test(test_cloud_names),
        cmocka_unit_test(test_fuzz),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
