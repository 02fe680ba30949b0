/* transport.h — how a session's bytes cross its socket: plain TCP (net_tcp, net.c), TLS (tls.c),
 * or a layer stacked on another one, such as the browser listener's HTTP + WebSocket layer
 * (ws_conn.c), which itself reads and writes through a lower net_transport (TCP or TLS). A
 * session calls only these functions, so the layers stack without the session knowing which one
 * it has.
 *
 * Non-blocking contract (OpenSSL's SSL_read/SSL_write, generalised): read and write return the
 * bytes moved (> 0), 0 when the peer closed in order (read only; err may name why, e.g. "served
 * GET /"), or one of NET_AGAIN (nothing can move now; *want is EV_READ or EV_WRITE, the socket
 * event that lets the call progress: a TLS read may need to write, a TLS write to read, and a
 * layer's read may have its own output to write first), NET_ERR (err holds a sentence), or
 * NET_NOT_TLS (read only: a TLS listener got a first byte that cannot start a TLS handshake; err
 * says so). A write that returned NET_AGAIN is retried with the same bytes. The caller writes
 * whole protocol messages in order (several may come in one call, and a call may continue the
 * rest of one), so a framing layer finds each message's end from its header and makes it one
 * frame; a write may take fewer bytes than offered. pending says whether the layer holds input it
 * already took off the socket (the socket will not be readable for it): the caller reads again
 * without waiting for an event. Event-loop thread. */
#pragma once
#include <stddef.h>
#include <sys/types.h>

enum { NET_AGAIN = -1, NET_ERR = -2, NET_NOT_TLS = -3 };

typedef struct net_transport {
    const char *name;             /* "tcp", "tls", "ws": for the log */
    ssize_t (*read)(void *ctx, int fd, void *buf, size_t len, int *want, char *err, size_t errlen);
    ssize_t (*write)(void *ctx, int fd, const void *buf, size_t len, int *want, char *err,
                     size_t errlen);
    int (*pending)(void *ctx);
    /* midway: 1 while the layer holds part of one of its own units (a WebSocket frame, an HTTP
     * request head), so the session's read deadline covers a peer trickling those; NULL: never. */
    int (*midway)(void *ctx);
    /* close: ends the layer before its socket is closed (TLS: a close_notify, best effort) and
     * frees ctx; graceful is 0 after an error, when nothing more is to be written. */
    void (*close)(void *ctx, int graceful);
} net_transport;

/* net_tcp: the plain layer (recv/send with MSG_NOSIGNAL; ctx unused, may be NULL). */
extern const net_transport net_tcp;
