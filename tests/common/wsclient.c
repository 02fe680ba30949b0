/* wsclient.c — a blocking WebSocket client for the tests and the bench (see wsclient.h). */
#include "wsclient.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>

#include "testutil.h"

static int connect_port(int port)
{
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
        close(fd);
        return -1;
    }
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return fd;
}

/* tls_connect: a verified TLS client over the connected socket fd (CA file ca, the peer's
 * certificate must name IP 127.0.0.1). Returns the SSL, or NULL after printing why. */
static SSL *tls_connect(int fd, const char *ca)
{
    SSL_CTX *ctx = SSL_CTX_new(TLS_client_method());
    SSL *ssl = NULL;
    if (!ctx || SSL_CTX_load_verify_locations(ctx, ca, NULL) != 1) goto fail;
    SSL_CTX_set_verify(ctx, SSL_VERIFY_PEER, NULL);
    ssl = SSL_new(ctx);
    SSL_CTX_free(ctx); /* the SSL holds its own reference */
    ctx = NULL;
    if (!ssl || SSL_set_fd(ssl, fd) != 1 ||
        X509_VERIFY_PARAM_set1_ip_asc(SSL_get0_param(ssl), "127.0.0.1") != 1 ||
        SSL_connect(ssl) != 1)
        goto fail;
    return ssl;
fail:;
    const char *why = ERR_reason_error_string(ERR_get_error());
    printf("wsclient: TLS connection failed: %s\n", why ? why : "no OpenSSL reason");
    ERR_clear_error();
    SSL_free(ssl);
    SSL_CTX_free(ctx);
    return NULL;
}

/* io_recv / io_send_all: the socket's bytes, through ssl when there is one. */
static ssize_t io_recv(int fd, void *ssl, void *p, size_t n)
{
    if (!ssl) return recv(fd, p, n, 0);
    int r = SSL_read(ssl, p, n > INT32_MAX ? INT32_MAX : (int)n);
    return r > 0 ? r : -1;
}

static int io_send_all(int fd, void *ssl, const void *p, size_t n)
{
    if (!ssl) return tu_send_all(fd, p, n);
    const char *c = p;
    while (n > 0) {
        int w = SSL_write(ssl, c, n > INT32_MAX ? INT32_MAX : (int)n);
        if (w <= 0) return -1;
        c += w;
        n -= (size_t)w;
    }
    return 0;
}

/* io_wait: 1 when bytes can be read within timeout_ms (TLS may hold some already). */
static int io_wait(int fd, void *ssl, int timeout_ms)
{
    if (ssl && SSL_pending(ssl) > 0) return 1;
    struct pollfd p = {.fd = fd, .events = POLLIN};
    return poll(&p, 1, timeout_ms) > 0;
}

static void io_close(int fd, void *ssl)
{
    if (ssl) {
        SSL_shutdown(ssl);
        SSL_free(ssl);
    }
    if (fd >= 0) close(fd);
}

/* read_head: reads until the end of an HTTP head (or close, or timeout_ms); returns bytes. */
static int read_until(int fd, void *ssl, char *out, size_t cap, int timeout_ms, int head_only)
{
    size_t n = 0;
    while (n + 1 < cap) {
        if (!io_wait(fd, ssl, timeout_ms)) break;
        /* One byte at a time for a head, so no WebSocket byte after it is taken. */
        ssize_t r = io_recv(fd, ssl, out + n, head_only ? 1 : cap - 1 - n);
        if (r <= 0) break;
        n += (size_t)r;
        out[n] = 0;
        if (head_only && n >= 4 && !memcmp(out + n - 4, "\r\n\r\n", 4)) break;
    }
    out[n] = 0;
    return (int)n;
}

static int http_request(int port, const char *ca, const char *req, char *out, size_t cap)
{
    int fd = connect_port(port);
    if (fd < 0) return -1;
    SSL *ssl = ca ? tls_connect(fd, ca) : NULL;
    if (ca && !ssl) {
        close(fd);
        return -1;
    }
    io_send_all(fd, ssl, req, strlen(req));
    int n = read_until(fd, ssl, out, cap, 2000, 0);
    io_close(fd, ssl);
    return n;
}

int tu_http_request(int port, const char *req, char *out, size_t cap)
{
    return http_request(port, NULL, req, out, cap);
}

int tu_https_request(int port, const char *ca, const char *req, char *out, size_t cap)
{
    return http_request(port, ca, req, out, cap);
}

static int ws_open(tu_ws *w, int port, const char *ca, const char *host, const char *origin,
                   char *resp, size_t cap)
{
    memset(w, 0, sizeof w[0]);
    w->mask_seed = 0x9e3779b9u ^ (uint32_t)port;
    resp[0] = 0;
    w->fd = connect_port(port);
    if (w->fd < 0) return -1;
    if (ca && !(w->ssl = tls_connect(w->fd, ca))) {
        close(w->fd);
        w->fd = -1;
        return -1;
    }
    char hbuf[64], req[1024];
    if (!host) snprintf(hbuf, sizeof hbuf, "127.0.0.1:%d", port), host = hbuf;
    const char *key = "dGhlIHNhbXBsZSBub25jZQ==";
    char org[400] = "";
    if (origin) snprintf(org, sizeof org, "Origin: %s\r\n", origin);
    snprintf(req, sizeof req, "GET /ws HTTP/1.1\r\nHost: %s\r\nUpgrade: websocket\r\n"
             "Connection: Upgrade\r\nSec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n%s\r\n",
             host, key, org);
    if (io_send_all(w->fd, w->ssl, req, strlen(req)) != 0) return -1;
    read_until(w->fd, w->ssl, resp, cap, 5000, 1);
    char acc[WS_ACCEPT_LEN + 1], want[80];
    ws_accept_key(key, strlen(key), acc);
    snprintf(want, sizeof want, "Sec-WebSocket-Accept: %s\r\n", acc);
    if (strncmp(resp, "HTTP/1.1 101 ", 13) != 0 || !strstr(resp, want)) {
        io_close(w->fd, w->ssl);
        w->fd = -1;
        w->ssl = NULL;
        return -1;
    }
    return 0;
}

int tu_ws_open(tu_ws *w, int port, const char *host, const char *origin, char *resp, size_t cap)
{
    return ws_open(w, port, NULL, host, origin, resp, cap);
}

int tu_ws_open_tls(tu_ws *w, int port, const char *ca, const char *host, const char *origin,
                   char *resp, size_t cap)
{
    return ws_open(w, port, ca, host, origin, resp, cap);
}

int tu_ws_send(tu_ws *w, int op, const void *p, size_t n)
{
    uint8_t mask[4];
    w->mask_seed = w->mask_seed * 1664525u + 1013904223u;
    memcpy(mask, &w->mask_seed, 4);
    uint8_t *f = malloc(WS_MAX_HEADER + n);
    if (!f) return -1;
    size_t h = ws_frame_header(f, 1, op, n, mask);
    memcpy(f + h, p, n);
    ws_mask(f + h, n, mask, 0);
    int rc = io_send_all(w->fd, w->ssl, f, h + n);
    free(f);
    return rc;
}

int tu_ws_recv(tu_ws *w, int timeout_ms)
{
    if (!w->dec.msg_opcode) w->msg_len = 0; /* a control frame may come inside a message */
    for (;;) {
        if (w->in_off == w->in_len) {
            if (!io_wait(w->fd, w->ssl, timeout_ms)) return -2;
            ssize_t r = io_recv(w->fd, w->ssl, w->in, sizeof w->in);
            if (r <= 0) return -2;
            w->in_off = 0;
            w->in_len = (size_t)r;
        }
        if (w->msg_cap - w->msg_len < sizeof w->in) {
            size_t nc = w->msg_cap ? 2 * w->msg_cap : 4 * sizeof w->in;
            uint8_t *nm = realloc(w->msg, nc);
            if (!nm) return -2;
            w->msg = nm;
            w->msg_cap = nc;
        }
        size_t used, prod;
        int rc = ws_decode(&w->dec, w->in + w->in_off, w->in_len - w->in_off, &used,
                           w->msg + w->msg_len, w->msg_cap - w->msg_len, &prod, &w->ev);
        w->in_off += used;
        w->msg_len += prod;
        if (rc != WS_EV_NONE) return rc;
    }
}

void tu_ws_close(tu_ws *w)
{
    io_close(w->fd, w->ssl);
    w->fd = -1;
    w->ssl = NULL;
    free(w->msg);
    w->msg = NULL;
    w->msg_cap = w->msg_len = 0;
}
