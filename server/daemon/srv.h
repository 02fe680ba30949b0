/* srv.h — the daemon's context, shared by daemon.c (start-up, sockets, signals) and
 * dispatch.c (requests, cloud table, worker events). Event-loop thread only, except
 * srv_pack_frame, which the encoder thread calls. */
#pragma once
#include <limits.h>
#include <stdint.h>

#include "auth.h"
#include "ev.h"
#include "render_thread.h"
#include "session.h"
#include "tls.h"
#include "ws_conn.h"

enum {
    SRV_MAX_PRELOAD = 32,
    SRV_TOKEN_MIN = 16,          /* bytes of token needed to listen beyond loopback */
    SRV_HTTP_FILES = 8,          /* embedded files the browser listener serves, at most */
};

typedef struct srv_opts {
    char host[NET_ADDR_LEN];     /* default 127.0.0.1 */
    int port;                    /* default 7878; 0 = ephemeral */
    char http_host[NET_ADDR_LEN]; /* --http: the browser listener; "" when off (default) */
    int http_port;
    const char *data_dir;        /* required */
    const char *cache_dir;       /* default NULL: cache.h's default */
    const char *token_file;      /* NULL: no auth (loopback only) */
    const char *tls_cert;        /* --tls-cert: NULL: plaintext (loopback only) */
    const char *tls_key;         /* --tls-key */
    const char *port_file;       /* write the bound port here */
    const char *shader_dir;
    rnd_backend_kind backend;
    const char *preload[SRV_MAX_PRELOAD];
    int npreload;
    int max_clients;             /* default 64 */
    int handshake_ms;            /* default 10000 */
    int idle_ms;                 /* --idle-timeout; default 300000; 0: none */
    int read_ms;                 /* --read-timeout; default 30000; 0: none */
    int write_ms;                /* --write-timeout; default 30000; 0: none */
    int max_unauth;              /* --max-unauth: connections not yet authenticated; default 64 */
    int max_per_addr;            /* --max-per-addr: connections from one address; default 0:
                                  * srv_per_addr_default(max_clients), set at start */
    int auth_delay_ms;           /* --auth-fail-delay: first failure's delay; default 250 */
    int auth_delay_local;        /* --auth-fail-delay given: loopback clients are delayed too */
    int shutdown_ms;             /* default 5000: how long SIGTERM waits for frames in flight */
    uint64_t gpu_memory;         /* --gpu-memory; default 0: the renderer sizes it */
    uint64_t max_frame_bytes;    /* --max-frame-bytes; default 0: a quarter of RAM */
    int lod_mode;                /* --lod auto|always|never (LOD_*); default auto */
    int lod_uploads;             /* --lod-inflight: LOD nodes loading at once; default 0: 4 */
    uint64_t prep_memory;        /* --prep-memory: the LOD build's memory cap; default 2 GiB */
    uint64_t preview_points;     /* --copc-preview: a COPC file's provisional cloud holds at
                                  * most this many points (rt_desc.preview_points); default 500k */
} srv_opts;

/* srv_parse_size: "512M", "4G", "1048576" (suffix K, M or G) into *out; at least 1 MiB.
 * Returns 0 or -1. */
int srv_parse_size(const char *s, uint64_t *out);

typedef struct srv_waiter {
    uint32_t sess, seq;
    int shown;                   /* the session was answered the provisional INFO: it draws the
                                  * provisional cloud and gets PROGRESS and the full INFO */
} srv_waiter;

/* One cloud known to the daemon, keyed by its real path. Loaded once, shared by all clients.
 * The table is the one owner of a cloud's identity: its key, (gen << 16) | (index + 1), is
 * what the workers' events carry; cloud_id is only the renderer's handle for its buffers. */
typedef struct srv_cloud {
    char path[PATH_MAX];
    char name[256];
    int state;                   /* SRV_CLOUD_* */
    uint16_t gen;                /* bumped each time the entry starts a load; kept when freed */
    uint32_t key, cloud_id;
    rt_cloud_info info;          /* READY: the cloud's; LOADING with prov_id: the provisional one's */
    uint32_t prov_id;            /* LOADING: the renderer's provisional cloud, 0 when none */
    srv_waiter *waiters;
    int nwait, capwait;
    uint64_t t_start_ms;
} srv_cloud;

enum { SRV_CLOUD_FREE = 0, SRV_CLOUD_LOADING, SRV_CLOUD_READY };

/* Authentication failures of one client address (the address without its port), for the
 * growing delay before an AUTH_FAILED answer. A fixed table: when full, the entry whose last
 * failure is oldest is reused, so memory stays bounded whatever the number of addresses. */
typedef struct srv_authfail {
    char host[NET_ADDR_LEN];
    uint32_t fails;
    uint64_t last_ms;
} srv_authfail;

enum {
    SRV_AUTHFAIL_SLOTS = 256,
    SRV_AUTHFAIL_FORGET_MS = 10 * 60 * 1000, /* failures forgotten after 10 quiet minutes */
    SRV_AUTHFAIL_MAX_SHIFT = 6,              /* the delay doubles up to 64x the first one */
};

/* A connection of the unauthenticated pool, as admit.c weighs it for eviction. */
typedef struct srv_pre {
    sess *s;
    char host[NET_ADDR_LEN];     /* its address without the port */
    int count;                   /* connections of the pool (and the newcomer) from that address */
    int kind;                    /* admit.c's PRE_* */
    uint64_t quiet;              /* ms since its last bytes, or since it connected */
} srv_pre;

/* A silent newcomer waiting in the lobby for its first bytes while the pool is full (admit.c). */
typedef struct srv_lobby_ent {
    struct srv *sv;
    int fd;                      /* -1: a free entry */
    int http;                    /* from the browser listener */
    uint64_t t_ms;               /* accepted then */
    char addr[NET_ADDR_LEN];
} srv_lobby_ent;

enum {
    SRV_QUIET_MS = 2000,         /* a pre-auth connection that sent nothing for this long (since
                                  * it connected, or since its last bytes) is quiet: the first
                                  * to make room for a newcomer (admit.c) */
    SRV_LOBBY_PER_UNAUTH = 16,   /* lobby places per --max-unauth place (at least 64, at most
                                  * 4096) */
    SRV_LOBBY_SWEEP_MS = 250,    /* how often the lobby is swept for --handshake-timeout */
    SRV_ROOM_LOBBY = 1,          /* srv_room: the newcomer waits in the lobby */
};

typedef struct srv {
    srv_opts o;
    ev_loop *loop;
    rt_ctx *rt;
    const rt_hooks *hooks;       /* a distributed renderer (daemon_run), or NULL */
    auth_token token;
    tls_server *tls;             /* NULL: plaintext */
    int lfd, sigfd;
    int bound_port;
    int http_lfd;                /* --http listener, -1 when off */
    int http_bound_port;
    ws_conn_cfg http_cfg;        /* what every browser connection is served */
    ws_file http_files[SRV_HTTP_FILES];
    char http_paths[SRV_HTTP_FILES][64];
    sess **sessions;             /* max_clients + max_unauth slots */
    int nslots;
    sess_limits lim;             /* the deadlines every session gets (from o) */
    srv_authfail authfail[SRV_AUTHFAIL_SLOTS];
    uint16_t *gens;
    srv_pre *pre;                /* nslots entries: admit.c's scratch for choosing who makes
                                  * room */
    srv_lobby_ent *lobby;        /* nlobby_cap entries, nlobby of them in use */
    int nlobby, nlobby_cap;
    ev_timer lobby_timer;        /* sweeps the lobby while it holds any */
    int nsess;
    sess *dead;                  /* closed sessions, freed before the loop sleeps */
    srv_cloud *clouds;
    int nclouds;
    int stopping;
    uint64_t stop_deadline_ms;
    ev_timer stop_timer;
    int max_w, max_h;
} srv;

/* srv_log: one line on stderr, "splatd: ADDR message", ADDR from s when not NULL. */
void srv_log(const srv *sv, const sess *s, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* srv_adopt: serves the connected non-blocking socket c from peer addr ("HOST:PORT"): the
 * admission limits, a new session (TLS when the daemon has it), its handshake deadline. On
 * refusal the socket is answered BUSY (or closed) and closed, and SD_ELIMIT/SD_ENOMEM returned;
 * else 0. What on_accept does with each accepted socket; the dispatch fuzzer's way in. */
int srv_adopt(srv *sv, int c, const char *addr);

/* srv_per_addr_default: --max-per-addr when it is not given: half of --max-clients (at least
 * 1), at most 32. One address then never holds more than half of the slots, so a client from
 * another address always finds room (with --max-clients 1 the one slot is everybody's), while
 * the default --max-clients 64 keeps 32 for one busy machine (a render farm's head, a test
 * run). */
int srv_per_addr_default(int max_clients);

/* srv_opts_defaults: o with every default (as `splatd` with no option). */
void srv_opts_defaults(srv_opts *o);
/* srv_core_start: the parts of start-up the sessions need (event loop, session table,
 * deadlines, the render, encoder and prep threads); no socket, signal or preload. sv->o must
 * be set; sv->max_w/max_h (0: 8192) bound frame sizes. Returns 0 or an SD_E* code with err.
 * srv_teardown: closes every session and frees what srv_core_start and start-up made; returns 1
 * when a cloud preparation was left running (the process should exit without waiting). */
int srv_core_start(srv *sv, sd_err *err);
int srv_teardown(srv *sv);

/* srv_addr_host: the address of "HOST:PORT" or "[V6]:PORT" without its port (and brackets),
 * for per-address counting: a client's reconnections differ only in the port. */
void srv_addr_host(const char *addr, char *out, size_t len);
/* srv_room: whether a new connection (socket fd) from host (an address without port) may be
 * served now, under --max-per-addr, --max-clients and --max-unauth; when the unauthenticated
 * pool is full, one of it is closed to make room for a newcomer that has spoken (the policy is
 * admit.c's). Returns 0 (serve it), SRV_ROOM_LOBBY (it has not spoken: srv_lobby_hold), or
 * SD_ELIMIT with why (for the log) and *client_text (for the refusal) set. */
int srv_room(srv *sv, int fd, const char *host, char *why, size_t whylen,
             const char **client_text);
/* srv_lobby_hold: socket fd from addr (http: the browser listener's) waits in the lobby for
 * its first bytes, then goes through srv_adopt_conn again (admit.c). srv_lobby_free: closes
 * every lobby socket and frees the lobby. */
void srv_lobby_hold(srv *sv, int fd, const char *addr, int http);
void srv_lobby_free(srv *sv);
/* srv_adopt_conn: srv_adopt for either listener (http: the browser listener). */
int srv_adopt_conn(srv *sv, int c, const char *addr, int http);
/* srv_answer_and_close: queues ERROR code (request seq) on s and closes it once written. */
void srv_answer_and_close(srv *sv, sess *s, uint32_t seq, int code, const char *text);

/* srv_admit: s has just authenticated (a HELLO without a token, or with the right proof):
 * admits it under --max-clients (sess_set_authed) and returns 1; or answers BUSY to request
 * seq, closes it once that is written and returns 0. */
int srv_admit(srv *sv, sess *s, uint32_t seq);
/* srv_auth_failed: s sent a wrong proof (or none) in HELLO seq: stops reading it and answers
 * AUTH_FAILED (then closes) after a delay that doubles with each failure from its address. */
void srv_auth_failed(srv *sv, sess *s, uint32_t seq, int noproof);

/* srv_clean_text: in as text safe to send and log, at most len - 1 bytes and NUL-terminated:
 * well-formed UTF-8 kept, every other byte and every control character (newlines included)
 * written as \xNN; a sequence or escape that does not fit is dropped whole. */
void srv_clean_text(const char *in, char *out, size_t len);

/* srv_handle: sess_ops.on_message: one decoded message of s (owner = the srv). */
void srv_handle(void *owner, sess *s, const proto_msg *m);
/* srv_decode_error: sess_ops.on_decode_error: answers the malformed input with its ERROR,
 * fatal codes closing the session once flushed. */
void srv_decode_error(void *owner, sess *s, int code, const char *text);
/* srv_lookup: the live session with id, or NULL (stale ids give NULL). */
sess *srv_lookup(srv *sv, uint32_t id);
/* srv_on_worker_events: handles every event the workers posted (frames, progress, clouds). */
void srv_on_worker_events(srv *sv);
/* srv_preload: resolves and starts preparing cloud name. Returns 0 or SD_E* with err. */
int srv_preload(srv *sv, const char *name, sd_err *err);
/* srv_release_frame: sess_ops.release (user = srv): the render thread's count of s's frames.
 * srv_sending_frame, srv_sent_frame: sess_ops.sending and .sent: a frame starts being written
 * (no longer outstanding, still in the frame budget), and is written (out of the budget). */
void srv_release_frame(void *user, uint32_t id);
void srv_sending_frame(void *user, uint32_t id);
void srv_sent_frame(void *user, uint32_t id);
/* srv_pack_frame: rt_pack_fn: builds a FRAME message (header + payload). Encoder thread. */
int srv_pack_frame(void *user, const rt_frame_meta *m, const uint8_t *data, size_t len,
                   uint8_t **msg, size_t *msglen);

