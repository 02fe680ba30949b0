/* test_ws.c — WebSocket framing (server/net/ws.c) against RFC 6455's own examples (section 1.3
 * accept key, section 5.7 frames), 16- and 64-bit lengths, fragments, close codes, every
 * malformed-header rule with the close code it must give, byte-at-a-time input, and the HTTP
 * request-head parser (server/net/http.c). Pure functions over buffers: no sockets. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "http.h"
#include "ws.h"
#include "testutil.h"

static const uint8_t rfc_mask[4] = {0x37, 0xfa, 0x21, 0x3d};
#define OUTCAP sizeof out

/* run: decodes all of in with d in pieces of step bytes; collects the produced bytes into out
 * (cap bytes) and the events into evs (ERROR ends it, *last holds its details). Returns the
 * number of events. */
static int run(ws_decoder *d, const uint8_t *in, size_t n, size_t step, uint8_t *out,
               size_t cap, size_t *outlen, int *evs, ws_event *last)
{
    size_t off = 0, o = 0;
    int ne = 0;
    while (off < n) {
        size_t lim = n - off < step ? n - off : step, used = 0, prod = 0;
        int rc = ws_decode(d, in + off, lim, &used, out + o, cap - o, &prod, last);
        off += used;
        o += prod;
        if (rc != WS_EV_NONE) evs[ne++] = rc;
        if (rc == WS_EV_ERROR) break;
        if (rc == WS_EV_NONE && used == 0 && prod == 0) break;
    }
    *outlen = o;
    return ne;
}

static void test_accept_key(void **st)
{
    (void)st;
    char out[WS_ACCEPT_LEN + 1];
    /* RFC 6455 section 1.3. */
    assert_int_equal(ws_accept_key("dGhlIHNhbXBsZSBub25jZQ==", 24, out), 0);
    assert_string_equal(out, "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
    /* Not 16 bytes of base64: wrong length, no padding, a character outside the alphabet. */
    assert_int_equal(ws_accept_key("dGhlIHNhbXBsZSBub25jZQ=", 23, out), -1);
    assert_int_equal(ws_accept_key("dGhlIHNhbXBsZSBub25jZQAA", 24, out), -1);
    assert_int_equal(ws_accept_key("dGhlIHNhbXBsZSBub2*jZQ==", 24, out), -1);
}

static void test_rfc_examples(void **st)
{
    (void)st;
    uint8_t out[256];
    size_t ol;
    int evs[8];
    ws_event ev;
    /* A single-frame masked text message "Hello" (5.7). */
    const uint8_t masked[] = {0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58};
    ws_decoder d = {.require_mask = 1};
    for (size_t step = 1; step <= sizeof masked; step++) {
        memset(&d, 0, sizeof d);
        d.require_mask = 1;
        int ne = run(&d, masked, sizeof masked, step, out, OUTCAP, &ol, evs, &ev);
        assert_int_equal(ne, 1);
        assert_int_equal(evs[0], WS_EV_END);
        assert_int_equal(ol, 5);
        assert_memory_equal(out, "Hello", 5);
        assert_false(ws_decoder_midway(&d));
    }
    /* The same frame on a binary-only endpoint: 1003. */
    memset(&d, 0, sizeof d);
    d.require_mask = 1;
    d.binary_only = 1;
    assert_int_equal(run(&d, masked, sizeof masked, 64, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_ERROR);
    assert_int_equal(ev.code, WS_CLOSE_UNSUPPORTED);
    /* The unmasked "Hello" (a server's frame): refused by a server with 1002, read by a client. */
    const uint8_t unmasked[] = {0x81, 0x05, 0x48, 0x65, 0x6c, 0x6c, 0x6f};
    memset(&d, 0, sizeof d);
    d.require_mask = 1;
    assert_int_equal(run(&d, unmasked, sizeof unmasked, 64, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_ERROR);
    assert_int_equal(ev.code, WS_CLOSE_PROTOCOL);
    assert_non_null(strstr(ev.why, "unmasked"));
    memset(&d, 0, sizeof d);
    assert_int_equal(run(&d, unmasked, sizeof unmasked, 64, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_END);
    assert_memory_equal(out, "Hello", 5);
    /* A fragmented unmasked text message: "Hel" + "lo". */
    const uint8_t frag[] = {0x01, 0x03, 0x48, 0x65, 0x6c, 0x80, 0x02, 0x6c, 0x6f};
    memset(&d, 0, sizeof d);
    assert_int_equal(run(&d, frag, sizeof frag, 4, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_END);
    assert_int_equal(ol, 5);
    assert_memory_equal(out, "Hello", 5);
    /* Unmasked ping "Hello" and masked pong "Hello". */
    const uint8_t ping[] = {0x89, 0x05, 0x48, 0x65, 0x6c, 0x6c, 0x6f};
    memset(&d, 0, sizeof d);
    assert_int_equal(run(&d, ping, sizeof ping, 64, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_PING);
    assert_int_equal(ev.len, 5);
    assert_memory_equal(ev.payload, "Hello", 5);
    const uint8_t pong[] = {0x8a, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58};
    memset(&d, 0, sizeof d);
    d.require_mask = 1;
    assert_int_equal(run(&d, pong, sizeof pong, 3, out, OUTCAP, &ol, evs, &ev), 1);
    assert_int_equal(evs[0], WS_EV_PONG);
    assert_memory_equal(ev.payload, "Hello", 5);
    assert_int_equal(ol, 0);
}

/* frame: a masked binary frame of len bytes (value i & 0xff at i) built with ws_frame_header. */
static uint8_t *frame(size_t len, int fin, int op, size_t *n)
{
    uint8_t *f = malloc(WS_MAX_HEADER + len);
    size_t h = ws_frame_header(f, fin, op, len, rfc_mask);
    for (size_t i = 0; i < len; i++) f[h + i] = (uint8_t)i;
    ws_mask(f + h, len, rfc_mask, 0);
    *n = h + len;
    return f;
}

static void test_lengths(void **st)
{
    (void)st;
    /* RFC 5.7: 256 bytes in one unmasked binary frame: 0x82 0x7E 0x0100; 64 KiB: 0x82 0x7F
     * 0x0000000000010000. The header writer gives those bytes. */
    uint8_t h[WS_MAX_HEADER];
    assert_int_equal(ws_frame_header(h, 1, WS_OP_BINARY, 256, NULL), 4);
    assert_memory_equal(h, ((uint8_t[]){0x82, 0x7e, 0x01, 0x00}), 4);
    assert_int_equal(ws_frame_header(h, 1, WS_OP_BINARY, 65536, NULL), 10);
    assert_memory_equal(h, ((uint8_t[]){0x82, 0x7f, 0, 0, 0, 0, 0, 1, 0, 0}), 10);
    assert_int_equal(ws_frame_header(h, 1, WS_OP_BINARY, 125, NULL), 2);
    assert_int_equal(h[1], 125);
    assert_int_equal(ws_frame_header(h, 1, WS_OP_BINARY, 126, rfc_mask), 8);
    assert_int_equal(h[1], 0x80 | 126);
    /* Both decode, at the edges of each encoding, unmasked into place. */
    const size_t lens[] = {0, 1, 125, 126, 65535, 65536, 200000};
    uint8_t out[1 << 18];
    for (size_t k = 0; k < sizeof lens / sizeof lens[0]; k++) {
        size_t n, ol;
        uint8_t *f = frame(lens[k], 1, WS_OP_BINARY, &n);
        ws_decoder d = {.require_mask = 1, .binary_only = 1};
        int evs[4];
        ws_event ev;
        assert_int_equal(run(&d, f, n, 7000, out, OUTCAP, &ol, evs, &ev), 1);
        assert_int_equal(evs[0], WS_EV_END);
        assert_int_equal(ol, lens[k]);
        for (size_t i = 0; i < lens[k]; i++)
            if (out[i] != (uint8_t)i) fail_msg("length %zu: byte %zu is %u", lens[k], i, out[i]);
        free(f);
    }
}

static void test_fragments_and_control_between(void **st)
{
    (void)st;
    /* A binary message in three fragments with a ping between the first two: the ping is
     * reported by itself and the payload continues. */
    size_t n1, n2, n3;
    uint8_t *a = frame(300, 0, WS_OP_BINARY, &n1);
    uint8_t *c = frame(10, 1, WS_OP_CONT, &n3);
    uint8_t *b = frame(70000, 0, WS_OP_CONT, &n2);
    uint8_t ping[WS_MAX_HEADER + 3];
    size_t hp = ws_frame_header(ping, 1, WS_OP_PING, 3, rfc_mask);
    memcpy(ping + hp, "abc", 3);
    ws_mask(ping + hp, 3, rfc_mask, 0);
    size_t np = hp + 3, n = n1 + np + n2 + n3;
    uint8_t *all = malloc(n);
    memcpy(all, a, n1);
    memcpy(all + n1, ping, np);
    memcpy(all + n1 + np, b, n2);
    memcpy(all + n1 + np + n2, c, n3);
    uint8_t out[1 << 18];
    size_t ol;
    int evs[8];
    ws_event ev;
    ws_decoder d = {.require_mask = 1, .binary_only = 1, .max_message = 70310};
    int ne = run(&d, all, n, 1000, out, OUTCAP, &ol, evs, &ev);
    assert_int_equal(ne, 2);
    assert_int_equal(evs[0], WS_EV_PING);
    assert_int_equal(evs[1], WS_EV_END);
    assert_int_equal(ol, 70310);
    assert_int_equal(out[299], 299 & 0xff);
    assert_int_equal(out[300], 0);
    assert_int_equal(out[300 + 69999], 69999 & 0xff);
    assert_int_equal(out[70300 + 9], 9);
    /* One byte less allowed: the third fragment's header already goes over: 1009 before any
     * of its payload is taken. */
    memset(&d, 0, sizeof d);
    d.require_mask = 1;
    d.max_message = 70309;
    ne = run(&d, all, n, 1 << 20, out, OUTCAP, &ol, evs, &ev);
    assert_int_equal(evs[ne - 1], WS_EV_ERROR);
    assert_int_equal(ev.code, WS_CLOSE_TOO_BIG);
    assert_int_equal(ol, 70300);
    free(a); free(b); free(c); free(all);
}

static void test_close_frames(void **st)
{
    (void)st;
    uint8_t f[4 + WS_REASON_MAX], m[4 + WS_REASON_MAX + 4];
    size_t n = ws_close_frame(f, 1001, "bye");
    assert_int_equal(n, 7);
    assert_memory_equal(f, ((uint8_t[]){0x88, 0x05, 0x03, 0xe9, 'b', 'y', 'e'}), 7);
    /* A long reason is cut to fit a control frame. */
    char longr[300];
    memset(longr, 'x', sizeof longr - 1);
    longr[sizeof longr - 1] = 0;
    assert_int_equal(ws_close_frame(f, 1000, longr), 4 + WS_REASON_MAX);
    assert_int_equal(f[1], 2 + WS_REASON_MAX);
    /* A masked close with code 1000 and a reason decodes to that code and reason. */
    const uint16_t codes[] = {1000, 1001, 1003, 1011, 3000, 4999};
    for (size_t k = 0; k < sizeof codes / sizeof codes[0]; k++) {
        size_t h = ws_frame_header(m, 1, WS_OP_CLOSE, 5, rfc_mask);
        m[h] = (uint8_t)(codes[k] >> 8);
        m[h + 1] = (uint8_t)codes[k];
        memcpy(m + h + 2, "end", 3);
        ws_mask(m + h, 5, rfc_mask, 0);
        ws_decoder d = {.require_mask = 1};
        ws_event ev;
        uint8_t out[8];
        size_t used, prod;
        assert_int_equal(ws_decode(&d, m, h + 5, &used, out, sizeof out, &prod, &ev), WS_EV_CLOSE);
        assert_int_equal(used, h + 5);
        assert_int_equal(ev.code, codes[k]);
        assert_int_equal(ev.len, 3);
        assert_memory_equal(ev.payload, "end", 3);
    }
    /* An empty close: no status (1005). */
    ws_decoder d = {.require_mask = 1};
    ws_event ev;
    uint8_t out[8];
    size_t used, prod, h = ws_frame_header(m, 1, WS_OP_CLOSE, 0, rfc_mask);
    assert_int_equal(ws_decode(&d, m, h, &used, out, sizeof out, &prod, &ev), WS_EV_CLOSE);
    assert_int_equal(ev.code, WS_CLOSE_NO_STATUS);
    /* Codes a peer must not send: 999, 1004, 1005, 1006, 1015, 2999, 5000: 1002. */
    const uint16_t bad[] = {999, 1004, 1005, 1006, 1015, 2999, 5000};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        h = ws_frame_header(m, 1, WS_OP_CLOSE, 2, rfc_mask);
        m[h] = (uint8_t)(bad[k] >> 8);
        m[h + 1] = (uint8_t)bad[k];
        ws_mask(m + h, 2, rfc_mask, 0);
        memset(&d, 0, sizeof d);
        d.require_mask = 1;
        assert_int_equal(ws_decode(&d, m, h + 2, &used, out, sizeof out, &prod, &ev), WS_EV_ERROR);
        assert_int_equal(ev.code, WS_CLOSE_PROTOCOL);
        assert_non_null(strstr(ev.why, "invalid code"));
    }
}

/* expect_error: hdr (a frame's first bytes) must fail with code, the message naming what. */
static void expect_error(const uint8_t *in, size_t n, uint16_t code, const char *words,
                         uint64_t max_message)
{
    ws_decoder d = {.require_mask = 1, .binary_only = 1, .max_message = max_message};
    ws_event ev;
    uint8_t out[16];
    size_t used, prod;
    int rc = ws_decode(&d, in, n, &used, out, sizeof out, &prod, &ev);
    if (rc != WS_EV_ERROR) fail_msg("expected an error naming '%s', got event %d", words, rc);
    assert_int_equal(ev.code, code);
    if (!strstr(ev.why, words)) fail_msg("'%s' does not say '%s'", ev.why, words);
    assert_int_equal(prod, 0);
    /* Once failed, it stays failed. */
    assert_int_equal(ws_decode(&d, in, n, &used, out, sizeof out, &prod, &ev), WS_EV_ERROR);
}

static void test_malformed(void **st)
{
    (void)st;
    const uint8_t K[4] = {1, 2, 3, 4};
    (void)K;
#define M 0x80
    expect_error((uint8_t[]){0x82 | 0x40, M | 1, 1, 2, 3, 4, 0}, 7, 1002, "reserved bits", 0);
    expect_error((uint8_t[]){0x83, M | 0}, 2, 1002, "reserved opcode 3", 0);
    expect_error((uint8_t[]){0x8b, M | 0}, 2, 1002, "reserved opcode 11", 0);
    expect_error((uint8_t[]){0x82, 0}, 2, 1002, "unmasked", 0);
    expect_error((uint8_t[]){0x09, M | 0}, 2, 1002, "fragmented control", 0);
    expect_error((uint8_t[]){0x89, M | 126, 0, 126}, 4, 1002, "longer than 125", 0);
    expect_error((uint8_t[]){0x80, M | 1, 1, 2, 3, 4, 0}, 7, 1002, "continuation frame without", 0);
    expect_error((uint8_t[]){0x81, M | 0}, 2, 1003, "text message", 0);
    expect_error((uint8_t[]){0x82, M | 126, 0, 125, 1, 2, 3, 4}, 8, 1002, "minimal", 0);
    expect_error((uint8_t[]){0x82, M | 127, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 1, 2, 3, 4}, 14, 1002,
                 "minimal", 0);
    expect_error((uint8_t[]){0x82, M | 127, 0x80, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 4}, 14, 1002,
                 "most significant bit", 0);
    expect_error((uint8_t[]){0x88, M | 1, 1, 2, 3, 4, 0}, 7, 1002, "1-byte payload", 0);
    /* A header claiming 2^62 bytes, or just over the cap: 1009 from the header alone. */
    expect_error((uint8_t[]){0x82, M | 127, 0x40, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 4}, 14, 1009,
                 "the limit is 65552", 65552);
    expect_error((uint8_t[]){0x82, M | 127, 0, 0, 0, 0, 0, 1, 0, 0x11, 1, 2, 3, 4}, 14, 1009,
                 "65553 bytes", 65552);
    /* A new data frame inside a fragmented message. */
    {
        ws_decoder d = {.require_mask = 1, .binary_only = 1};
        ws_event ev;
        uint8_t out[16];
        size_t used, prod;
        const uint8_t two[] = {0x02, M | 1, 0, 0, 0, 0, 7, 0x82, M | 0, 0, 0, 0, 0};
        assert_int_equal(ws_decode(&d, two, sizeof two, &used, out, sizeof out, &prod, &ev),
                         WS_EV_ERROR);
        assert_int_equal(ev.code, 1002);
        assert_non_null(strstr(ev.why, "inside a fragmented message"));
        assert_int_equal(prod, 1);
    }
#undef M
}

/* Random bytes never crash the decoder, and every error carries a valid close code. */
static void test_random_input(void **st)
{
    (void)st;
    uint32_t x = 12345;
    uint8_t in[512], out[256];
    int errors = 0;
    for (int it = 0; it < 20000; it++) {
        size_t n = 1 + (x % sizeof in);
        for (size_t i = 0; i < n; i++) {
            x = x * 1664525u + 1013904223u;
            in[i] = (uint8_t)(x >> 24);
        }
        if (it & 1) in[1] |= 0x80; /* half of them masked, to get past that check */
        ws_decoder d = {.require_mask = 1, .binary_only = 1, .max_message = 1000};
        size_t off = 0;
        for (int k = 0; k < 1000 && off < n; k++) {
            ws_event ev;
            size_t used, prod;
            int rc = ws_decode(&d, in + off, n - off, &used, out, sizeof out, &prod, &ev);
            assert_true(used <= n - off);
            assert_true(prod <= sizeof out);
            off += used;
            if (rc == WS_EV_ERROR) {
                assert_true(ev.code == 1002 || ev.code == 1003 || ev.code == 1009);
                assert_true(ev.why[0] != 0);
                errors++;
                break;
            }
            if (rc == WS_EV_NONE && used == 0 && prod == 0) break;
        }
    }
    assert_true(errors > 1000);
}

static void test_http_parse(void **st)
{
    (void)st;
    http_req r;
    char err[200];
    const char *req = "GET /ws?x=1 HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nUpgrade: websocket\r\n"
                      "Connection: keep-alive, Upgrade\r\n"
                      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                      "Origin: http://127.0.0.1:8080\r\nSec-WebSocket-Version: 13\r\n"
                      "X-Other: a\r\n\r\nXYZ";
    size_t n = strlen(req);
    /* Every prefix short of the empty line needs more. */
    for (size_t k = 0; k < n - 3; k++)
        assert_int_equal(http_parse_request(req, k, &r, err, sizeof err), 0);
    assert_int_equal(http_parse_request(req, n, &r, err, sizeof err), (int)(n - 3));
    assert_string_equal(r.method, "GET");
    assert_string_equal(r.target, "/ws?x=1");
    assert_int_equal(r.minor, 1);
    assert_string_equal(r.host, "127.0.0.1:8080");
    assert_string_equal(r.origin, "http://127.0.0.1:8080");
    assert_string_equal(r.ws_key, "dGhlIHNhbXBsZSBub25jZQ==");
    assert_string_equal(r.ws_version, "13");
    assert_true(http_has_token(r.connection, "upgrade"));
    assert_true(http_has_token(r.upgrade, "WebSocket"));
    assert_false(http_has_token(r.connection, "close"));
    assert_false(r.has_body);
    /* Malformed heads: the status and the place. */
    struct { const char *in; int status; const char *words; } bad[] = {
        {"GET / HTTP/2.0\r\n\r\n", -505, "HTTP/1.x"},
        {"GET /\r\n\r\n", -400, "METHOD TARGET VERSION"},
        {"GET / HTTP/1.1\r\nHost 1\r\n\r\n", -400, "line 2 has no 'name:'"},
        {"GET / HTTP/1.1\r\nHo st: 1\r\n\r\n", -400, "line 2: invalid character"},
        {"GET / HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n", -400, "a second Host"},
        {"GET / HTTP/1.1\r\nA: 1\r\nOrigin: x\1y\r\n\r\n", -400, "line 3: control character"},
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        int rc = http_parse_request(bad[k].in, strlen(bad[k].in), &r, err, sizeof err);
        if (rc != bad[k].status || !strstr(err, bad[k].words))
            fail_msg("'%s': %d '%s', expected %d '%s'", bad[k].in, rc, err, bad[k].status,
                     bad[k].words);
    }
    /* A header value over the kept size, a target over 255 bytes, a head over 8 KiB. */
    char big[HTTP_HEAD_MAX + 64];
    int m = snprintf(big, sizeof big, "GET / HTTP/1.1\r\nOrigin: %0300d\r\n\r\n", 1);
    assert_int_equal(http_parse_request(big, (size_t)m, &r, err, sizeof err), -431);
    m = snprintf(big, sizeof big, "GET /%0300d HTTP/1.1\r\n\r\n", 1);
    assert_int_equal(http_parse_request(big, (size_t)m, &r, err, sizeof err), -414);
    memset(big, 'a', sizeof big);
    assert_int_equal(http_parse_request(big, HTTP_HEAD_MAX, &r, err, sizeof err), -431);
    assert_int_equal(http_parse_request(big, HTTP_HEAD_MAX - 1, &r, err, sizeof err), 0);
    const char *body = "POST / HTTP/1.1\r\nContent-Length: 5\r\n\r\n";
    assert_true(http_parse_request(body, strlen(body), &r, err, sizeof err) > 0);
    assert_true(r.has_body);
    /* The response head. */
    char out[256];
    size_t hl = http_response_head(out, sizeof out, 404, "Not Found", "text/plain", 12, "X: y\r\n");
    assert_string_equal(out, "HTTP/1.1 404 Not Found\r\nContent-Type: text/plain\r\n"
                             "Content-Length: 12\r\nX: y\r\n\r\n");
    assert_int_equal(hl, strlen(out));
    assert_int_equal(http_response_head(out, 20, 404, "Not Found", "text/plain", 12, NULL), 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_accept_key),
        cmocka_unit_test(test_rfc_examples),
        cmocka_unit_test(test_lengths),
        cmocka_unit_test(test_fragments_and_control_between),
        cmocka_unit_test(test_close_frames),
        cmocka_unit_test(test_malformed),
        cmocka_unit_test(test_random_input),
        cmocka_unit_test(test_http_parse),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
