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

enum { SRV_MAX_PRELOAD = 32 };

typedef struct srv_opts {
    char host[NET_ADDR_LEN];     /* default 127.0.0.1 */
    int port;                    /* default 7878; 0 = ephemeral */
    const char *data_dir;        /* required */
    const char *cache_dir;       /* default NULL: cache.h's default */
    const char *token_file;      /* NULL: no auth (loopback only) */
    const char *port_file;       /* write the bound port here */
    const char *shader_dir;
    rnd_backend_kind backend;
    const char *preload[SRV_MAX_PRELOAD];
    int npreload;
    int max_clients;             /* default 64 */
    int handshake_ms;            /* default 10000 */
    int shutdown_ms;             /* default 5000: how long SIGTERM waits for frames in flight */
    uint64_t gpu_memory;         /* --gpu-memory; default 0: the renderer sizes it */
} srv_opts;

typedef struct srv_waiter {
    uint32_t sess, seq;
} srv_waiter;

/* One cloud known to the daemon, keyed by its real path. Loaded once, shared by all clients. */
typedef struct srv_cloud {
    char path[PATH_MAX];
    char name[256];
    int state;                   /* SRV_CLOUD_* */
    uint32_t job, cloud_id;
    rt_cloud_info info;
    srv_waiter *waiters;
    int nwait, capwait;
    uint64_t t_start_ms;
} srv_cloud;

enum { SRV_CLOUD_FREE = 0, SRV_CLOUD_LOADING, SRV_CLOUD_READY };

typedef struct srv {
    srv_opts o;
    ev_loop *loop;
    rt_ctx *rt;
    auth_token token;
    int lfd, sigfd;
    int bound_port;
    sess **sessions;             /* max_clients slots */
    uint16_t *gens;
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
/* srv_release_frame: sess_ops.release (user = srv): the render thread's count of s's frames. */
void srv_release_frame(void *user, uint32_t id);
/* srv_pack_frame: rt_pack_fn: builds a FRAME message (header + payload). Encoder thread. */
int srv_pack_frame(void *user, const rt_frame_meta *m, const uint8_t *data, size_t len,
                   uint8_t **msg, size_t *msglen);

