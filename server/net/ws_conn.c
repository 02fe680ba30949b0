/* ws_conn.c — HTTP + WebSocket as a transport layer (see ws_conn.h). */
#include "ws_conn.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "ev.h"
#include "http.h"
#include "net.h"
#include "proto.h"
#include "ws.h"

enum {
    WSC_RIN = 64 * 1024,       /* raw bytes read from the lower layer at a time */
    WSC_STAGE = 4096,          /* payload bytes written together with a frame header */
    WSC_CTL = 2 * (2 + WS_CONTROL_MAX), /* pending pongs / a close, between data frames */
};

enum { WSC_HTTP, WSC_RESPOND, WSC_UPGRADING, WSC_OPEN, WSC_DONE };
enum { WSC_GO_ON = -100 }; /* read_open: no bytes for the caller yet, the loop goes on */

struct ws_conn {
    const ws_conn_cfg *cfg;
    const net_transport *lo;
    void *lo_ctx;
    int fd;
    int state;
    int plain_on_tls;          /* a plaintext HTTP request came to a TLS listener */
    /* HTTP */
    char head[HTTP_HEAD_MAX];
    size_t head_len, head_used;
    char rh[1024];             /* response head */
    size_t rh_len, rh_off;
    const char *body;          /* response body (an embedded file or rh's own text) */
    size_t body_len, body_off;
    char ebody[256];           /* the text of an error response */
    char why[192];             /* DONE: what the read reports */
    int why_error;             /* DONE: report NET_ERR rather than an orderly end */
    /* WebSocket */
    ws_decoder dec;
    uint8_t rin[WSC_RIN];
    size_t rin_len, rin_off;
    uint8_t ctl[WSC_CTL];      /* complete control frames waiting for a frame boundary */
    size_t ctl_len;
    int close_sent;
    uint8_t stage[WS_MAX_HEADER + WSC_STAGE];
    size_t st_len, st_off, st_ret;
    uint64_t frame_left;       /* payload bytes of the data frame being written, not yet taken */
    /* One protocol message per WebSocket message: the current message's size and header. */
    uint64_t msg_got;
    uint8_t msg_hdr[PROTO_HEADER_LEN];
    size_t msg_hdr_have;
    uint8_t held;              /* the protocol message's last byte, held until the WebSocket
                                * message ends there (one_message) */
    char bad_msg[160];         /* a message that was not one protocol message: fails the next
                                * read */
};

ws_conn *ws_conn_new(const ws_conn_cfg *cfg, const net_transport *lower, void *lower_ctx)
{
    ws_conn *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    c->cfg = cfg;
    c->lo = lower;
    c->lo_ctx = lower_ctx;
    c->fd = -1;
    c->dec.max_message = cfg->max_message;
    c->dec.require_mask = 1;
    c->dec.binary_only = 1;
    return c;
}

int ws_conn_is_open(const ws_conn *c)
{
    return c->state == WSC_OPEN;
}

/* ---- HTTP ---- */

static const char sec_headers[] =
    "Cache-Control: no-store\r\n"
    "X-Content-Type-Options: nosniff\r\n"
    "Referrer-Policy: no-referrer\r\n"
    "Content-Security-Policy: default-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; frame-ancestors 'none'\r\n"
    "Connection: close\r\n";

/* respond: queues a complete response (head + body) and what the read reports once it is out. */
static void respond(ws_conn *c, int status, const char *reason, const char *ctype,
                    const char *body, size_t blen, const char *extra, int is_error,
                    const char *why)
{
    char hdrs[600];
    snprintf(hdrs, sizeof hdrs, "%s%s", sec_headers, extra ? extra : "");
    c->rh_len = http_response_head(c->rh, sizeof c->rh, status, reason, ctype, blen, hdrs);
    c->rh_off = 0;
    c->body = body;
    c->body_len = blen;
    c->body_off = 0;
    c->state = WSC_RESPOND;
    c->why_error = is_error;
    snprintf(c->why, sizeof c->why, "%.190s", why);
}

static void respond_error(ws_conn *c, int status, const char *why, const char *extra)
{
    const char *reason = status == 400 ? "Bad Request" : status == 403 ? "Forbidden"
                       : status == 404 ? "Not Found" : status == 405 ? "Method Not Allowed"
                       : status == 414 ? "URI Too Long" : status == 426 ? "Upgrade Required"
                       : status == 431 ? "Request Header Fields Too Large"
                       : status == 505 ? "HTTP Version Not Supported" : "Error";
    int n = snprintf(c->ebody, sizeof c->ebody, "%d %s: %.200s\n", status, reason, why);
    size_t bl = n > 0 && (size_t)n < sizeof c->ebody ? (size_t)n : strlen(c->ebody);
    char w[192];
    snprintf(w, sizeof w, "HTTP request refused with %d: %.150s", status, why);
    respond(c, status, reason, "text/plain; charset=utf-8", c->ebody, bl, extra, 1, w);
}

/* host_part: the host of a Host header value ("h:p", "[v6]:p", "h") into out. */
static void host_part(const char *hv, char *out, size_t len)
{
    const char *s = hv, *e;
    if (*s == '[') {
        s++;
        e = strchr(s, ']');
        if (!e) e = s + strlen(s);
    } else {
        e = strrchr(s, ':');
        if (!e) e = s + strlen(s);
    }
    size_t n = (size_t)(e - s) < len - 1 ? (size_t)(e - s) : len - 1;
    memcpy(out, s, n);
    out[n] = 0;
}

/* handle: answers a complete request head. */
static void handle(ws_conn *c, const http_req *r)
{
    if (c->plain_on_tls) {
        /* Answered in plaintext (the request was), with the address that works; nothing is
         * served over it. */
        char why[HTTP_FIELD_MAX + 96];
        snprintf(why, sizeof why, "this server speaks HTTPS only: open https://%s/",
                 r->has_host ? r->host : "HOST:PORT");
        respond_error(c, 400, why, NULL);
        return;
    }
    if (strcmp(r->method, "GET") != 0) {
        respond_error(c, 405, "only GET is served", "Allow: GET\r\n");
        return;
    }
    if (r->has_body) {
        respond_error(c, 400, "a GET with a body", NULL);
        return;
    }
    if (!r->has_host) {
        respond_error(c, 400, "no Host header", NULL);
        return;
    }
    if (c->cfg->loopback_hosts_only) {
        char h[HTTP_FIELD_MAX];
        host_part(r->host, h, sizeof h);
        if (!net_host_is_loopback(h)) {
            char why[HTTP_FIELD_MAX + 96];
            snprintf(why, sizeof why, "Host '%s' is not a loopback address (without a token the "
                     "daemon answers loopback names only)", r->host);
            respond_error(c, 403, why, NULL);
            return;
        }
    }
    char path[HTTP_FIELD_MAX];
    size_t pl = strcspn(r->target, "?#");
    memcpy(path, r->target, pl);
    path[pl] = 0;
    if (strcmp(path, c->cfg->ws_path) != 0) {
        for (int i = 0; i < c->cfg->nfiles; i++) {
            const ws_file *f = &c->cfg->files[i];
            if (strcmp(path, f->path) != 0) continue;
            char why[HTTP_FIELD_MAX + 32];
            snprintf(why, sizeof why, "served GET %s", path);
            respond(c, 200, "OK", f->type, f->body, f->len, NULL, 0, why);
            return;
        }
        respond_error(c, 404, "no such page", NULL);
        return;
    }
    /* The WebSocket opening handshake (RFC 6455 4.2.1). */
    if (r->has_origin) {
        char own[HTTP_FIELD_MAX + 8];
        snprintf(own, sizeof own, "%s://%s", c->cfg->https ? "https" : "http", r->host);
        if (strcasecmp(own, r->origin) != 0) {
            char why[2 * HTTP_FIELD_MAX + 64];
            snprintf(why, sizeof why, "Origin '%s' is not this page's origin '%s'", r->origin, own);
            respond_error(c, 403, why, NULL);
            return;
        }
    }
    if (!http_has_token(r->upgrade, "websocket") || !http_has_token(r->connection, "upgrade")) {
        respond_error(c, 426, "this path takes a WebSocket upgrade only",
                      "Upgrade: websocket\r\n");
        return;
    }
    if (strcmp(r->ws_version, "13") != 0) {
        respond_error(c, 426, "Sec-WebSocket-Version must be 13", "Sec-WebSocket-Version: 13\r\n");
        return;
    }
    char acc[WS_ACCEPT_LEN + 1];
    if (ws_accept_key(r->ws_key, strlen(r->ws_key), acc) != 0) {
        respond_error(c, 400, "Sec-WebSocket-Key is not the base64 text of 16 bytes", NULL);
        return;
    }
    c->rh_len = (size_t)snprintf(c->rh, sizeof c->rh,
                                 "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n"
                                 "Connection: Upgrade\r\nSec-WebSocket-Accept: %s\r\n\r\n", acc);
    c->rh_off = 0;
    c->body = NULL;
    c->body_len = c->body_off = 0;
    c->state = WSC_UPGRADING;
}

/* flush_response: writes the queued response. Returns 1 when all of it is out, or NET_AGAIN /
 * NET_ERR from the lower layer. */
static int flush_response(ws_conn *c, int *want, char *err, size_t errlen)
{
    while (c->rh_off < c->rh_len || c->body_off < c->body_len) {
        int head = c->rh_off < c->rh_len;
        const char *p = head ? c->rh + c->rh_off : c->body + c->body_off;
        size_t n = head ? c->rh_len - c->rh_off : c->body_len - c->body_off;
        ssize_t w = c->lo->write(c->lo_ctx, c->fd, p, n, want, err, errlen);
        if (w < 0) return (int)w;
        if (head) c->rh_off += (size_t)w;
        else c->body_off += (size_t)w;
    }
    return 1;
}

/* ---- WebSocket ---- */

static int mid_frame(const ws_conn *c)
{
    return c->st_off < c->st_len || c->frame_left > 0;
}

/* queue_control: appends a control frame; a pong that does not fit replaces nothing and is
 * dropped (RFC 6455 5.5.3 lets a pong answer only the latest ping). */
static void queue_control(ws_conn *c, int op, const uint8_t *p, size_t n)
{
    if (c->close_sent) return;
    if (c->ctl_len + 2 + n > sizeof c->ctl) return;
    c->ctl_len += ws_frame_header(c->ctl + c->ctl_len, 1, op, n, NULL);
    memcpy(c->ctl + c->ctl_len, p, n);
    c->ctl_len += n;
}

/* queue_close: appends a close frame with code and reason; nothing is written after it. */
static void queue_close(ws_conn *c, uint16_t code, const char *reason)
{
    if (c->close_sent) return;
    uint8_t f[4 + WS_REASON_MAX];
    size_t n = ws_close_frame(f, code, reason);
    if (c->ctl_len + n > sizeof c->ctl) c->ctl_len = 0; /* the close matters more than pongs */
    memcpy(c->ctl + c->ctl_len, f, n);
    c->ctl_len += n;
    c->close_sent = 1;
}

/* flush_control: writes the pending control frames when no data frame is being written. The
 * lower layer's AGAIN is not an error: they wait for the next write or read. */
static void flush_control(ws_conn *c)
{
    int want;
    char e[8];
    if (c->st_off < c->st_len && c->st_ret == 0 && c->frame_left == 0) {
        /* The stage holds only the rest of control frames: it can go on by itself. */
        while (c->st_off < c->st_len) {
            ssize_t w = c->lo->write(c->lo_ctx, c->fd, c->stage + c->st_off,
                                     c->st_len - c->st_off, &want, e, sizeof e);
            if (w <= 0) return;
            c->st_off += (size_t)w;
        }
        c->st_off = c->st_len = 0;
    }
    if (mid_frame(c) || !c->ctl_len) return;
    size_t off = 0;
    while (off < c->ctl_len) {
        ssize_t w = c->lo->write(c->lo_ctx, c->fd, c->ctl + off, c->ctl_len - off, &want, e,
                                 sizeof e);
        if (w <= 0) break;
        off += (size_t)w;
    }
    /* A control frame written in part goes on in the stage, so frames stay whole. */
    if (off > 0 && off < c->ctl_len) {
        memcpy(c->stage, c->ctl + off, c->ctl_len - off);
        c->st_len = c->ctl_len - off;
        c->st_off = 0;
        c->st_ret = 0;
        c->ctl_len = 0;
    } else if (off == c->ctl_len) {
        c->ctl_len = 0;
    }
}

/* not_one: records in bad_msg why the data message being received is not one protocol message
 * (got: its bytes so far, or more than that when over); it fails the next read. */
static void not_one(ws_conn *c, uint64_t want, int over)
{
    if (over)
        snprintf(c->bad_msg, sizeof c->bad_msg, "a WebSocket message of more than %llu bytes is "
                 "not one protocol message (its header gives %llu)", (unsigned long long)want,
                 (unsigned long long)want);
    else if (c->msg_hdr_have < PROTO_HEADER_LEN)
        snprintf(c->bad_msg, sizeof c->bad_msg, "a WebSocket message of %llu bytes is not one "
                 "protocol message (it ends inside the %d-byte header)",
                 (unsigned long long)c->msg_got, PROTO_HEADER_LEN);
    else
        snprintf(c->bad_msg, sizeof c->bad_msg, "a WebSocket message of %llu bytes is not one "
                 "protocol message (its header gives %llu)", (unsigned long long)c->msg_got,
                 (unsigned long long)want);
}

/* one_message: checks the data message being received, buf[0..n) its next bytes (end: the
 * message ended with them), and returns how many of them the session may have now: they stay
 * at the start of buf.
 *
 * The message must hold exactly one protocol message: a header and the payload length the
 * header gives. That is known only at the message's end, and the session acts on a protocol
 * message as soon as its last byte arrives; so the last byte of the protocol message (the
 * header's length says which) is held back until the WebSocket message ends there. A message
 * that turns out longer (two PINGs in one) or shorter is then refused before the session has
 * seen a complete protocol message in it: nothing of it is acted on. The bytes before the
 * held one go on at once, so a large message needs no buffer of its own. A mismatch is kept
 * in bad_msg and fails the next read, after the bytes returned now (a header the session
 * itself refuses, e.g. a wrong magic, is answered with the protocol's error first). */
static size_t one_message(ws_conn *c, uint8_t *buf, size_t n, int end)
{
    size_t k = PROTO_HEADER_LEN - c->msg_hdr_have;
    if (k > n) k = n;
    memcpy(c->msg_hdr + c->msg_hdr_have, buf, k);
    c->msg_hdr_have += k;
    uint64_t before = c->msg_got, want = 0;
    c->msg_got += n;
    if (c->msg_hdr_have == PROTO_HEADER_LEN) {
        proto_header h;
        proto_get_header(c->msg_hdr, &h);
        want = PROTO_HEADER_LEN + (uint64_t)h.len;
    }
    /* Bytes at offsets below lim may go now: all of an incomplete header but its last byte
     * (the header alone may be the whole message), else all but the protocol message's last. */
    uint64_t lim = want ? want - 1 : PROTO_HEADER_LEN - 1;
    uint64_t top = c->msg_got < lim ? c->msg_got : lim;
    size_t pass = top > before ? (size_t)(top - before) : 0;
    if (want && c->msg_got > want) {
        not_one(c, want, 1);
        return pass;
    }
    if (want && c->msg_got == want && n > 0) c->held = buf[n - 1]; /* offset want - 1 */
    if (!end) return pass;
    if (!want || c->msg_got != want) {
        not_one(c, want, 0);
        return pass;
    }
    buf[pass++] = c->held; /* the message ends where its protocol message does */
    c->msg_got = 0;
    c->msg_hdr_have = 0;
    return pass;
}

static ssize_t read_open(ws_conn *c, void *buf, size_t len, int *want, char *err, size_t errlen)
{
    flush_control(c);
    if (c->bad_msg[0]) {
        /* Reported one read late, so the bytes before it reached the session in order. */
        queue_close(c, WS_CLOSE_INVALID, "one protocol message per WebSocket message");
        flush_control(c);
        snprintf(err, errlen, "WebSocket: %s (closed with %u)", c->bad_msg, WS_CLOSE_INVALID);
        return NET_ERR;
    }
    if (c->rin_off == c->rin_len) {
        c->rin_off = c->rin_len = 0;
        ssize_t r = c->lo->read(c->lo_ctx, c->fd, c->rin, sizeof c->rin, want, err, errlen);
        if (r == 0) snprintf(err, errlen, "closed by the client (no WebSocket close)");
        if (r <= 0) return r;
        c->rin_len = (size_t)r;
    }
    size_t used = 0, produced = 0;
    ws_event ev;
    int e = ws_decode(&c->dec, c->rin + c->rin_off, c->rin_len - c->rin_off, &used, buf, len,
                      &produced, &ev);
    c->rin_off += used;
    size_t pass = produced || e == WS_EV_END ? one_message(c, buf, produced, e == WS_EV_END) : 0;
    if (e == WS_EV_ERROR) {
        /* The close frame can go only at a frame boundary of the output; mid-frame the
         * connection just ends. */
        queue_close(c, ev.code, ev.why);
        flush_control(c);
        snprintf(err, errlen, "WebSocket: %s (closed with %u)", ev.why, ev.code);
        return NET_ERR;
    }
    if (e == WS_EV_PING) {
        queue_control(c, WS_OP_PONG, ev.payload, ev.len);
        flush_control(c);
    } else if (e == WS_EV_CLOSE) {
        queue_close(c, ev.code == WS_CLOSE_NO_STATUS ? WS_CLOSE_NORMAL : ev.code, "");
        flush_control(c);
        c->state = WSC_DONE;
        c->why_error = 0;
        snprintf(c->why, sizeof c->why, "closed by the client (WebSocket close %u)", ev.code);
    }
    if (pass) return (ssize_t)pass;
    return WSC_GO_ON;
}

static ssize_t wsc_read(void *ctx, int fd, void *buf, size_t len, int *want, char *err,
                        size_t errlen)
{
    ws_conn *c = ctx;
    c->fd = fd;
    /* Bounded: a wakeup's work stays small; pending() brings the caller back. */
    for (int round = 0; round < 32; round++) {
        switch (c->state) {
        case WSC_HTTP: {
            ssize_t r = c->lo->read(c->lo_ctx, fd, c->head + c->head_len,
                                    sizeof c->head - c->head_len, want, err, errlen);
            if (r == NET_NOT_TLS) {
                /* A browser that typed http:// on the https listener: its request is read in
                 * plaintext and answered with a 400 naming the https address. */
                c->lo->close(c->lo_ctx, 0);
                c->lo = &net_tcp;
                c->lo_ctx = NULL;
                c->plain_on_tls = 1;
                continue;
            }
            if (r == 0) snprintf(err, errlen, "closed by the client %s",
                                 c->head_len ? "in the middle of an HTTP request"
                                             : "before sending an HTTP request");
            if (r <= 0) return r;
            c->head_len += (size_t)r;
            http_req req;
            char why[160];
            int h = http_parse_request(c->head, c->head_len, &req, why, sizeof why);
            if (h < 0) respond_error(c, -h, why, NULL);
            else if (h > 0) c->head_used = (size_t)h, handle(c, &req);
            break;
        }
        case WSC_RESPOND:
        case WSC_UPGRADING: {
            int rc = flush_response(c, want, err, errlen);
            if (rc < 0) return rc;
            if (c->state == WSC_RESPOND) {
                c->state = WSC_DONE;
                break;
            }
            /* Bytes a client sent after its request head belong to the WebSocket. */
            c->rin_len = c->head_len - c->head_used;
            memcpy(c->rin, c->head + c->head_used, c->rin_len);
            c->rin_off = 0;
            c->state = WSC_OPEN;
            break;
        }
        case WSC_DONE:
            snprintf(err, errlen, "%s", c->why);
            return c->why_error ? NET_ERR : 0;
        case WSC_OPEN: {
            ssize_t r = read_open(c, buf, len, want, err, errlen);
            if (r != WSC_GO_ON) return r;
            break;
        }
        }
    }
    *want = EV_READ;
    return NET_AGAIN;
}

static ssize_t wsc_write(void *ctx, int fd, const void *buf, size_t len, int *want, char *err,
                         size_t errlen)
{
    ws_conn *c = ctx;
    c->fd = fd;
    if (c->state != WSC_OPEN || c->close_sent) return (ssize_t)len; /* nobody to frame it for */
    for (;;) {
        if (c->st_off < c->st_len) {
            ssize_t w = c->lo->write(c->lo_ctx, fd, c->stage + c->st_off, c->st_len - c->st_off,
                                     want, err, errlen);
            if (w < 0) return w;
            c->st_off += (size_t)w;
            if (c->st_off < c->st_len) continue;
            c->st_off = c->st_len = 0;
            size_t r = c->st_ret;
            c->st_ret = 0;
            if (r) return (ssize_t)r;
            continue;
        }
        if (c->frame_left) {
            size_t n = len < c->frame_left ? len : (size_t)c->frame_left;
            ssize_t w = c->lo->write(c->lo_ctx, fd, buf, n, want, err, errlen);
            if (w > 0) c->frame_left -= (uint64_t)w;
            return w;
        }
        if (c->ctl_len) {
            /* Control frames between two data frames. */
            memcpy(c->stage, c->ctl, c->ctl_len);
            c->st_len = c->ctl_len;
            c->ctl_len = 0;
            c->st_ret = 0;
            continue;
        }
        /* A new message at a protocol message boundary: one binary frame holding exactly that
         * protocol message (its header gives the length; the session may hand over several
         * messages at once), its frame header and first bytes in one write. */
        uint64_t mlen = len;
        if (len >= PROTO_HEADER_LEN) {
            proto_header ph;
            proto_get_header(buf, &ph);
            if (PROTO_HEADER_LEN + (uint64_t)ph.len < mlen) mlen = PROTO_HEADER_LEN + ph.len;
        }
        size_t h = ws_frame_header(c->stage, 1, WS_OP_BINARY, mlen, NULL);
        size_t k = mlen < WSC_STAGE ? (size_t)mlen : WSC_STAGE;
        memcpy(c->stage + h, buf, k);
        c->st_len = h + k;
        c->st_off = 0;
        c->st_ret = k;
        c->frame_left = mlen - k;
    }
}

static int wsc_pending(void *ctx)
{
    ws_conn *c = ctx;
    return (c->state == WSC_OPEN && (c->rin_off < c->rin_len || c->bad_msg[0])) ||
           c->state == WSC_DONE || c->lo->pending(c->lo_ctx);
}

static int wsc_midway(void *ctx)
{
    ws_conn *c = ctx;
    if (c->state == WSC_HTTP) return c->head_len > 0;
    return c->state == WSC_OPEN && ws_decoder_midway(&c->dec);
}

static void wsc_close(void *ctx, int graceful)
{
    ws_conn *c = ctx;
    if (!c) return;
    if (graceful && c->state == WSC_OPEN && c->fd >= 0) {
        /* The server ends the connection (BYE, an error answered, shutdown): a close frame
         * when it can go whole now. */
        queue_close(c, WS_CLOSE_NORMAL, "");
        flush_control(c);
    }
    c->lo->close(c->lo_ctx, graceful);
    free(c);
}

const net_transport ws_transport = {"ws", wsc_read, wsc_write, wsc_pending, wsc_midway,
                                    wsc_close};
