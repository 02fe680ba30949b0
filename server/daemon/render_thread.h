/* render_thread.h — the daemon's workers: one render thread that owns the GL context
 * (rnd_ctx), one encoder thread with its enc_ctx, and one prep thread that loads/prepares
 * clouds through the cache. They talk to the event loop only through this API: the loop
 * submits requests; the workers post rt_events and call ev_wakeup.
 *
 * Per client (a "slot", identified by the session id the loop gives it):
 *   - a latest-wins request (stream mode): a new one replaces the pending one;
 *   - a small FIFO of one-shot requests (RENDER), at most RT_QUEUE_MAX;
 *   - an outstanding count: frames rendering, encoding or waiting at the loop. The render
 *     thread skips a client with RT_MAX_OUTSTANDING frames outstanding, so a client that stops
 *     reading never costs render time and never makes frames pile up (the loop calls
 *     rt_frame_released when a frame leaves its waiting slot: sent to the socket or dropped).
 * The render thread serves clients with work round-robin, one frame at a time, and uploads
 * prepared clouds (before any frame) so that each cloud is on the GPU once, shared by all.
 * Frames are delivered in order per client (one encoder thread). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "cache.h"
#include "proto.h"
#include "render.h"
#include "sd_err.h"

enum { RT_QUEUE_MAX = 64, RT_MAX_OUTSTANDING = 2 }; /* 64: `splat path --inflight` allows up to 64 */

typedef struct rt_ctx rt_ctx;
typedef struct ev_loop ev_loop;

/* What one frame answers and how it came out; filled by the workers. */
typedef struct rt_frame_meta {
    uint32_t client;        /* session id */
    uint32_t req_seq;       /* the request's message sequence (RENDER, or CAMERA/PARAMS in stream mode) */
    uint32_t camera_seq;    /* the CAMERA message it renders, 0 = default camera */
    int stream;             /* 1: from the latest-wins slot */
    int width, height, pipeline, format;
    uint64_t render_us, readback_us, encode_us, points_drawn;
    uint32_t flags;         /* rnd_frame.flags (RND_FRAME_*) */
    int complete;           /* rnd_frame.complete */
    int provisional;        /* drawn from a provisional cloud (with `points`) */
} rt_frame_meta;

/* A render request as the loop submits it. */
typedef struct rt_request {
    uint32_t cloud_id;      /* from an RT_EV_CLOUD_READY event */
    rnd_camera cam;
    sp_params params;
    uint32_t req_seq, camera_seq;
    int refine;             /* the render thread's own: a refinement of the previous frame of
                             * a LOD cloud; it waits for the loader first. The loop sets 0. */
} rt_request;

/* Packs an encoded frame into the bytes the loop will write (header + payload), on the encoder
 * thread. Returns 0 with *msg (malloc'd) and *len set, or a negative code. */
typedef int (*rt_pack_fn)(void *user, const rt_frame_meta *m, const uint8_t *data, size_t len,
                          uint8_t **msg, size_t *msglen);

/* A distributed renderer (server/mpi/, `splatd --mpi`) in place of the local one: its
 * functions run on the render thread, which owns rnd. NULL members keep the local renderer's
 * behaviour. */
typedef struct rt_hooks {
    void *user;
    /* configure: adjusts the renderer's options before the render thread creates it. */
    void (*configure)(void *user, rnd_desc *d);
    /* adopt: takes the prepared cloud of the file at path (heap or mapped, the hook's to free)
     * and makes it renderable; returns the cloud id for render, or a negative SD_E* code. */
    int64_t (*adopt)(void *user, rnd_ctx *rnd, const char *path, pc_prepared *p, sd_err *err);
    /* render: rnd_render's contract, for the cloud id adopt returned. */
    int (*render)(void *user, rnd_ctx *rnd, uint32_t cloud_id, const rnd_camera *cam,
                  const sp_params *params, int want_float, rnd_frame *f, sd_err *err);
} rt_hooks;

typedef struct rt_desc {
    rnd_desc rnd;           /* renderer options (back end, shader dir) */
    int max_clients;        /* slots; client ids must be < 2^16 in their low bits (index) */
    const char *cache_dir;  /* default NULL: cache.h's default */
    int prep_threads;       /* default 0: every core (passed to cache_desc.threads) */
    int lod_mode;           /* LOD_AUTO (default), LOD_ALWAYS, LOD_NEVER: which clouds get the
                             * level-of-detail form (lod.h, lod_want) */
    uint64_t prep_memory;   /* --prep-memory: the LOD build's memory cap (default 2 GiB) */
    uint64_t frame_budget;  /* --max-frame-bytes: bytes all frames outstanding (rendering,
                             * encoding, waiting at the loop) may hold, by rt_frame_cost;
                             * default 0: a quarter of RAM, at least 256 MiB */
    uint64_t preview_points; /* a first OPEN of a COPC file (name ending .copc.laz) without a
                             * valid flat cache: its top octree levels holding at most this
                             * many points (pc_read_copc_budget) are uploaded first, as a
                             * provisional cloud (RT_EV_CLOUD_PROVISIONAL), while the full prep
                             * runs; 0 (default): none */
    rt_pack_fn pack;        /* required */
    void *pack_user;
    const rt_hooks *hooks;  /* default NULL: the local renderer */
} rt_desc;

typedef enum {
    RT_EV_FRAME = 1,        /* meta, msg/msglen: a packed FRAME message */
    RT_EV_FRAME_FAILED,     /* meta (client, seqs), err */
    RT_EV_PROGRESS,         /* job, phase, fraction */
    RT_EV_CLOUD_READY,      /* job, cloud_id, info */
    RT_EV_CLOUD_FAILED,     /* job, err */
    RT_EV_CLOUD_PROVISIONAL, /* job, cloud_id, info: a provisional cloud of a job still
                             * preparing; that job's READY (or FAILED) follows. Requests for
                             * the provisional id are drawn with `points` (meta.provisional),
                             * and once the full cloud is uploaded the render thread draws
                             * them from it instead (the provisional cloud is released then) */
} rt_event_kind;

/* The summary of a prepared cloud the loop keeps to answer OPEN (INFO). */
/* A loaded cloud's summary: the protocol's INFO (filled once, from the prepared cloud, and
 * passed along as it is; the daemon sets the name) and whether the cache had it. */
typedef struct rt_cloud_info {
    proto_info summary;
    int cache_hit;
} rt_cloud_info;

typedef struct rt_event {
    rt_event_kind kind;
    rt_frame_meta meta;
    uint8_t *msg;           /* RT_EV_FRAME: owned by the event until rt_event_free */
    size_t msglen;
    uint32_t job;           /* prep events: the key given to rt_prepare */
    int phase;                  /* PROGRESS: PROTO_PHASE_* */
    double fraction;
    uint32_t cloud_id;
    rt_cloud_info info;
    sd_err err;
    struct rt_event *next;
} rt_event;

/* rt_create: starts the workers; the render thread opens the GL back end, and rt_create
 * waits for it. Returns NULL with err filled when the renderer cannot start. Events are
 * announced by ev_wakeup(loop). */
rt_ctx *rt_create(const rt_desc *d, ev_loop *loop, sd_err *err);

/* rt_destroy: stops and joins the workers (frames in flight are finished first, then
 * dropped), frees every queued request and event. NULL is allowed. */
void rt_destroy(rt_ctx *rt);

/* rt_stop_for_exit: like rt_destroy, but when the prep thread is in the middle of preparing a
 * cloud (which cannot be interrupted and may take minutes), stops only the render and encoder
 * threads and returns 1: rt is then left as it is, still in use by the prep thread, and the
 * caller must exit the process without touching rt or the loop again. Returns 0 when rt was
 * destroyed. Used at SIGTERM, so that a stop request never waits for a preparation. */
int rt_stop_for_exit(rt_ctx *rt);

const char *rt_renderer_string(const rt_ctx *rt);
const char *rt_backend_name(const rt_ctx *rt);
/* rt_gpu_budget: the bytes of cloud buffers the renderer keeps on the GPU (rnd_desc.gpu_memory). */
uint64_t rt_gpu_budget(const rt_ctx *rt);

/* rt_frame_budget: the frame budget in bytes (rt_desc.frame_budget or its default). */
uint64_t rt_frame_budget(const rt_ctx *rt);
/* rt_frame_cost: the bytes a frame of rq may hold at most while it is rendered, encoded and
 * waits to be sent (read-back, encoder output and the packed message). A frame starts only
 * while the costs of the frames outstanding plus its own stay within the budget; the loop
 * refuses a single frame over it (rt_frame_budget). */
uint64_t rt_frame_cost(const rt_request *rq);

/* rt_client_open: claims the slot of client id (index = id & 0xffff < max_clients). Returns 0
 * or SD_ELIMIT. rt_client_close: drops its requests; frames already in flight are still
 * posted (the loop ignores events of a closed id). */
int rt_client_open(rt_ctx *rt, uint32_t id);
void rt_client_close(rt_ctx *rt, uint32_t id);

/* rt_submit_latest: sets the client's latest-wins request, replacing a pending one (which is
 * returned as 1 so the caller can count drops; 0 when none was pending). */
int rt_submit_latest(rt_ctx *rt, uint32_t id, const rt_request *rq);
/* rt_submit_queue: appends a one-shot request. Returns 0, or SD_ELIMIT when RT_QUEUE_MAX are
 * already queued (the caller answers BUSY). */
int rt_submit_queue(rt_ctx *rt, uint32_t id, const rt_request *rq);
/* rt_submit_prefetch: the client's PREFETCH (the next cameras of its path, at most
 * PROTO_MAX_PREFETCH): the render thread makes the nodes they need resident ahead, between
 * frames; a later one replaces it. Only LOD clouds have anything to prefetch. Returns 0. */
int rt_submit_prefetch(rt_ctx *rt, uint32_t id, uint32_t cloud_id, const rnd_camera *cams,
                       int n, const sp_params *params);
/* rt_frame_released: one frame of client id is gone before being written (a streamed frame
 * replaced by a newer one, a failed frame): no longer outstanding, its bytes given back. */
void rt_frame_released(rt_ctx *rt, uint32_t id);
/* rt_frame_sending: client id's oldest outstanding frame started being written to its socket:
 * it no longer counts as outstanding (its next frame may render), but its bytes stay counted
 * against the frame budget until rt_frame_sent (or rt_client_close). */
void rt_frame_sending(rt_ctx *rt, uint32_t id);
/* rt_frame_sent: the frame being written to client id has been written (and freed). */
void rt_frame_sent(rt_ctx *rt, uint32_t id);
/* rt_set_stream_blocked: while blocked, the client's latest-wins (streamed) requests wait: the
 * loop sets it when a streamed frame waits unsent (the client is not reading), so a stalled
 * streaming client costs no render time. */
void rt_set_stream_blocked(rt_ctx *rt, uint32_t id, int blocked);
/* rt_pending: requests queued or latest pending for id, plus frames outstanding. */
int rt_pending(rt_ctx *rt, uint32_t id);

/* rt_prepare: queues the preparation + upload of the cloud file path (resolved, inside the
 * data dir); its progress and result arrive as events carrying key, the caller's identity of
 * the cloud (the daemon's cloud table owns it; the workers keep no registry of their own).
 * Returns 0, or -1 when out of memory. */
int rt_prepare(rt_ctx *rt, const char *path, uint32_t key);

/* rt_take_events: the posted events, oldest first, as a list the caller now owns. */
rt_event *rt_take_events(rt_ctx *rt);
void rt_event_free(rt_event *ev);

/* rt_busy: 1 while any frame is rendering or encoding, any request is queued, or any event
 * waits to be taken (a prep job in progress does not count: shutdown does not wait for it). */
int rt_busy(rt_ctx *rt);
/* rt_drop_requests: drops every pending latest-wins (streamed) request and every prep job not
 * started (shutdown). Queued RENDER requests stay: each has an answer slot at its client, and
 * the shutdown deadline bounds how long they may take. */
void rt_drop_requests(rt_ctx *rt);
