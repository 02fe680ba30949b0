/* ws_conn.h — the browser listener's transport layer (transport.h): a connection begins as
 * HTTP/1.1 and either gets one of the embedded files (then closes) or upgrades to a WebSocket
 * on cfg->ws_path, after which every binary message carries one protocol message both ways:
 * input frames are unmasked into the session's input (a message that is not exactly one
 * protocol message closes the connection with 1007, before the session acts on any of it), and each protocol message the session
 * writes goes out as one unfragmented binary message (its length taken from its header). Pings are answered, a close is answered and
 * ends the connection, malformed frames end it with a close code (ws.c does the framing).
 *
 * It reads and writes through a lower transport: net_tcp, or TLS (tls.c) when the daemon has a
 * certificate (https and wss; a plaintext request to such a listener, NET_NOT_TLS from below,
 * is read in plaintext and answered with a 400 naming the https:// address). The session is the same object as for a TCP client: its deadlines, caps and
 * authentication apply from the first byte (an HTTP request is an unauthenticated connection).
 *
 * Checks before the upgrade: GET only, no body; Host present; Origin, when the request has one
 * (a browser always sends it on a WebSocket), equal to the page's own origin "http://" + Host
 * ("https://" over TLS),
 * so another site's script cannot open the socket; and, with loopback_hosts_only (no token),
 * a Host naming a loopback address, so a DNS-rebound name cannot reach the daemon either. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "transport.h"

typedef struct ws_file {
    const char *path;          /* "/", "/viewer.js" */
    const char *type;          /* Content-Type */
    const char *body;
    size_t len;
} ws_file;

typedef struct ws_conn_cfg {
    const ws_file *files;      /* served on GET; the query string is ignored */
    int nfiles;
    const char *ws_path;       /* the upgrade path, e.g. "/ws" */
    int loopback_hosts_only;   /* 1: the Host header must name a loopback address */
    int https;                 /* 1: the lower layer is TLS: the page's origin is https:// */
    uint64_t max_message;      /* payload bytes one WebSocket message may carry */
} ws_conn_cfg;

typedef struct ws_conn ws_conn;

/* ws_conn_new: the layer for one accepted connection, over lower (lower_ctx is handed to its
 * functions and closed with it). cfg must outlive the connection. NULL when out of memory. */
ws_conn *ws_conn_new(const ws_conn_cfg *cfg, const net_transport *lower, void *lower_ctx);

/* ws_conn_is_open: 1 once the WebSocket is open (the upgrade answer is written). */
int ws_conn_is_open(const ws_conn *c);

/* ws_transport: the layer's functions; ctx is a ws_conn. Before the upgrade a write drops its
 * bytes (an HTTP client is not sent protocol messages, e.g. the handshake timeout's ERROR). */
extern const net_transport ws_transport;
