/* wsclient.h — a blocking WebSocket client for the tests and the bench (the browser's side of
 * `splatd --http`, in C): the opening handshake, masked binary messages out, whole messages in
 * (framing by server/net/ws.c with require_mask = 0). Each message in either direction is one
 * protocol message. The _tls variants speak https/wss (OpenSSL's client, the server's
 * certificate verified against a CA file and the address 127.0.0.1). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "ws.h"

typedef struct tu_ws {
    int fd;
    void *ssl;                 /* SSL * over fd for wss, else NULL */
    ws_decoder dec;
    uint8_t in[64 * 1024];
    size_t in_len, in_off;
    uint8_t *msg;              /* the message being assembled */
    size_t msg_len, msg_cap;
    ws_event ev;               /* the last control frame or error */
    uint32_t mask_seed;
} tu_ws;

/* tu_http_request: connects to 127.0.0.1:port, sends req as it is and reads the answer until
 * the server closes or 2 s pass (at most cap - 1 bytes, NUL-terminated). Returns its length or
 * -1 when no connection. */
int tu_http_request(int port, const char *req, char *out, size_t cap);

/* tu_https_request: tu_http_request over TLS, the server's certificate checked against the
 * PEM file ca and the IP address 127.0.0.1. Returns the answer's length, or -1 when no TLS
 * connection could be made (the reason on stdout). */
int tu_https_request(int port, const char *ca, const char *req, char *out, size_t cap);

/* tu_ws_open_tls: tu_ws_open over TLS (wss), verified as in tu_https_request. */
int tu_ws_open_tls(tu_ws *w, int port, const char *ca, const char *host, const char *origin,
                   char *resp, size_t cap);

/* tu_ws_open: connects to 127.0.0.1:port and upgrades on /ws with origin (NULL: no Origin
 * header) and host ("127.0.0.1:PORT" when NULL); the answer's head is copied into resp. Returns
 * 0 once 101 arrived with the right Sec-WebSocket-Accept, else -1 (the socket closed). */
int tu_ws_open(tu_ws *w, int port, const char *host, const char *origin, char *resp, size_t cap);

/* tu_ws_send: one masked frame of opcode op (fin set) carrying p[0..n). 0 or -1. */
int tu_ws_send(tu_ws *w, int op, const void *p, size_t n);

/* tu_ws_recv: the next data message (its bytes in w->msg, w->msg_len) or control frame.
 * Returns WS_EV_END for a message, WS_EV_PING/PONG/CLOSE with w->ev filled, WS_EV_ERROR for
 * a malformed frame, or -2 when the connection ended or nothing came within timeout_ms. */
int tu_ws_recv(tu_ws *w, int timeout_ms);

void tu_ws_close(tu_ws *w);
