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

/* read_head: reads until the end of an HTTP head (or close, or timeout_ms); returns bytes. */
static int read_until(int fd, char *out, size_t cap, int timeout_ms, int head_only)
{
    size_t n = 0;
    while (n + 1 < cap) {
        struct pollfd p = {.fd = fd, .events = POLLIN};
        if (poll(&p, 1, timeout_ms) <= 0) break;
        /* One byte at a time for a head, so no WebSocket byte after it is taken. */
        ssize_t r = recv(fd, out + n, head_only ? 1 : cap - 1 - n, 0);
        if (r <= 0) break;
        n += (size_t)r;
        out[n] = 0;
        if (head_only && n >= 4 && !memcmp(out + n - 4, "\r\n\r\n", 4)) break;
    }
    out[n] = 0;
    return (int)n;
}

int tu_http_request(int port, const char *req, char *out, size_t cap)
{
    int fd = connect_port(port);
    if (fd < 0) return -1;
    tu_send_all(fd, req, strlen(req));
    int n = read_until(fd, out, cap, 2000, 0);
    close(fd);
    return n;
}

int tu_ws_open(tu_ws *w, int port, const char *host, const char *origin, char *resp, size_t cap)
{
    memset(w, 0, sizeof w[0]);
    w->mask_seed = 0x9e3779b9u ^ (uint32_t)port;
    w->fd = connect_port(port);
    if (w->fd < 0) return -1;
    char hbuf[64], req[1024];
    if (!host) snprintf(hbuf, sizeof hbuf, "127.0.0.1:%d", port), host = hbuf;
    const char *key = "dGhlIHNhbXBsZSBub25jZQ==";
    char org[400] = "";
    if (origin) snprintf(org, sizeof org, "Origin: %s\r\n", origin);
    snprintf(req, sizeof req, "GET /ws HTTP/1.1\r\nHost: %s\r\nUpgrade: websocket\r\n"
             "Connection: Upgrade\r\nSec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n%s\r\n",
             host, key, org);
    if (tu_send_all(w->fd, req, strlen(req)) != 0) return -1;
    read_until(w->fd, resp, cap, 5000, 1);
    char acc[WS_ACCEPT_LEN + 1], want[80];
    ws_accept_key(key, strlen(key), acc);
    snprintf(want, sizeof want, "Sec-WebSocket-Accept: %s\r\n", acc);
    if (strncmp(resp, "HTTP/1.1 101 ", 13) != 0 || !strstr(resp, want)) {
        close(w->fd);
        w->fd = -1;
        return -1;
    }
    return 0;
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
    int rc = tu_send_all(w->fd, f, h + n);
    free(f);
    return rc;
}

int tu_ws_recv(tu_ws *w, int timeout_ms)
{
    if (!w->dec.msg_opcode) w->msg_len = 0; /* a control frame may come inside a message */
    for (;;) {
        if (w->in_off == w->in_len) {
            struct pollfd p = {.fd = w->fd, .events = POLLIN};
            if (poll(&p, 1, timeout_ms) <= 0) return -2;
            ssize_t r = recv(w->fd, w->in, sizeof w->in, 0);
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
    if (w->fd >= 0) close(w->fd);
    w->fd = -1;
    free(w->msg);
    w->msg = NULL;
    w->msg_cap = w->msg_len = 0;
}
