/* session.h — one client connection of the daemon, as one object that owns its I/O: reading
 * (SESS_IN_CHUNK bytes a read, a few reads a wakeup when its transport holds more), decoding,
 * the ordered output queue, writing, its event-loop interest, and closing (redis's connection
 * object; STYLE.md 23). Bytes cross the socket through a net_transport (transport.h): plain
 * TCP by default, the browser listener's HTTP + WebSocket layer (ws_conn.h) for /ws. What the
 * messages mean is the owner's business: the session hands each decoded message to
 * ops->on_message (dispatch.c) and reports its close through ops->on_close (daemon.c). It also
 * carries the per-client render and auth state the dispatcher keeps. Event-loop thread only.
 *
 * Output: the protocol answers requests in order, so the output is a FIFO of items: bytes
 * (whole messages) or a frame placeholder that a RENDER puts in at once and the encoder fills
 * later. Items after an unfilled placeholder wait for it. Streamed frames (sequence 0) have a
 * separate one-frame slot, written between items; a newer streamed frame replaces a waiting one
 * (latest wins). Memory per session is bounded: bytes items by SESS_OUT_MAX (over it the client
 * is disconnected), frames by the render thread's per-client outstanding limit.
 *
 * Transport: bytes move through s->tr (transport.h): net_tcp unless the owner puts another
 * layer (TLS, or WebSocket over TCP or TLS) in with sess_set_transport before the first kick.
 *
 * Lifetime: sess_close marks a session dead and closes its socket; the daemon frees it at a
 * safe point (before the loop sleeps), never inside a callback (STYLE.md 7). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "auth.h"
#include "ev.h"
#include "net.h"
#include "proto.h"
#include "render.h"
#include "transport.h"

enum {
    SESS_OUT_MAX = 4 << 20,     /* bytes of non-frame output queued before the client is dropped */
    SESS_IN_CHUNK = 64 * 1024,  /* bytes read per wakeup (STYLE.md 8) */
};

/* The connection deadlines (redis `timeout`, nginx client_body_timeout / send_timeout), in
 * milliseconds; 0 turns one off. The owner keeps one copy for all its sessions (sess.lim).
 * idle_ms: an authenticated session that neither sends nor receives a byte for this long, with
 *   no request of its own in progress (an OPEN preparing, frames owed), is closed.
 * read_ms: once the first byte of a message arrived, the whole message must arrive within
 *   this; a client trickling a message (slowloris) cannot hold its slot.
 * write_ms: while output waits on a full socket, some of it must leave within this; a client
 *   that stops reading is closed rather than keeping its queue forever. */
typedef struct sess_limits {
    uint32_t idle_ms;
    uint32_t read_ms;
    uint32_t write_ms;
} sess_limits;

typedef struct sess_item {
    int is_frame;               /* 1: a RENDER's frame placeholder */
    int filled;                 /* bytes present (always 1 for non-frames) */
    int counted;                /* a frame still counted as outstanding by the render thread */
    uint32_t seq;               /* the request it answers */
    uint8_t *data;
    size_t len;
    struct sess_item *next;
} sess_item;

typedef struct sess sess;

/* What the owner does for its sessions; every callback gets the owner pointer given to
 * sess_new. */
typedef struct sess_ops {
    /* on_message: one decoded message; may queue answers (sess_send), pause input, close. */
    void (*on_message)(void *owner, sess *s, const proto_msg *m);
    /* on_decode_error: the input stream is malformed (code PROTO_E_*, text): framing is lost,
     * so the owner answers and the session closes after flushing. */
    void (*on_decode_error)(void *owner, sess *s, int code, const char *text);
    /* on_close: the session closed (socket already closed, reason for the log); the owner
     * frees it later, at a safe point, with sess_free. */
    void (*on_close)(void *owner, sess *s, const char *reason);
    /* release: a frame the render thread counts as outstanding for s is gone unsent (dropped,
     * or s freed while it waited). */
    void (*release)(void *owner, uint32_t id);
    /* sending: such a frame starts being written (it leaves the waiting state; NULL: release
     * is called instead); sent: the frame being written is written and freed. */
    void (*sending)(void *owner, uint32_t id);
    void (*sent)(void *owner, uint32_t id);
    /* stream_blocked: whether a streamed frame waits to be written (latest-wins backpressure). */
    void (*stream_blocked)(void *owner, sess *s, int blocked);
} sess_ops;

struct sess {
    uint32_t id;                /* (generation << 16) | index; never 0 */
    int fd;
    void *owner;                /* the daemon context, passed to every ops callback */
    const sess_ops *ops;
    ev_loop *loop;
    char addr[NET_ADDR_LEN];
    char client_name[PROTO_MAX_CLIENT + 1];
    uint64_t t_connect_ms;

    /* transport */
    const net_transport *tr;    /* net_tcp by default */
    void *tr_ctx;               /* the layer's state; closed with the session */
    int rd_want;                /* the event the last NET_AGAIN read waits for (0: none) */
    int wr_want;                /* the event the last NET_AGAIN write waits for (0: none) */
    ev_timer pend_timer;        /* the layer holds input already off the socket: read it soon */
    char io_err[150];           /* the last transport error, for the close reason */
    int tr_failed;              /* the transport failed: its close is not graceful */

    /* input */
    proto_decoder dec;
    uint8_t *in;                /* SESS_IN_CHUNK bytes; in[in_off..in_len) not yet decoded */
    size_t in_len, in_off;
    int paused;                 /* 1 while an OPEN waits for its cloud: input is kept, not parsed */

    /* connection state */
    int hello_seen, authed;
    uint16_t version;
    uint8_t challenge[AUTH_CHALLENGE_LEN];
    ev_timer hs_timer;          /* handshake timeout; also the delay before an AUTH_FAILED */
    const sess_limits *lim;     /* the owner's deadlines; NULL: none */
    ev_timer idle_timer;        /* armed by sess_set_authed; re-armed while there is activity */
    ev_timer rd_timer;          /* armed while a message is partly received */
    ev_timer wr_timer;          /* armed while output waits on a full socket */
    uint64_t last_io_ms;        /* the last byte read or written, for the idle deadline */
    uint64_t last_in_ms;        /* when bytes last came from the client (0: none yet); the
                                 * daemon's pre-auth eviction weighs it (admit.c) */
    int auth_failing;           /* a wrong proof waits for its delayed answer */
    uint32_t fail_seq;          /* the HELLO whose wrong proof is answered after the delay */
    int fail_noproof;           /* that HELLO carried no proof at all */
    int close_after;            /* BYE or a fatal error: flush, then close */
    int dead;                   /* closed; freed at the next safe point */
    char close_reason[160];

    /* render state */
    int cloud;                  /* cloud table index, -1 when none */
    int opening;                /* cloud table index being opened, -1 when none */
    uint32_t open_seq;
    uint32_t cloud_id;
    int have_camera;
    rnd_camera cam;
    uint32_t camera_seq;
    sp_params params;
    int stream;
    float max_fps;
    uint64_t last_stream_ms;
    uint32_t stream_seq;        /* the message that triggered the pending streamed frame */
    ev_timer fps_timer;         /* a streamed frame held back by max_fps */
    int frames_queued;          /* RENDER placeholders not yet filled */

    /* output */
    sess_item *head, *tail;
    size_t out_bytes;           /* bytes in items, for SESS_OUT_MAX */
    uint8_t *stream_frame;      /* a waiting streamed frame, or NULL */
    int stream_blocked;         /* last value told to rt_set_stream_blocked */
    size_t stream_len;
    uint8_t *cur;               /* the message being written (owned by cur_item or cur_own) */
    size_t cur_len, cur_off;
    sess_item *cur_item;        /* when cur belongs to the head item */
    uint8_t *cur_own;           /* when cur is a streamed frame taken from the slot */

    /* statistics for the close log line */
    uint64_t frames_sent, frames_dropped, bytes_out;
    struct sess *next_dead;
};

/* sess_new: a session for the accepted socket fd, served on loop for owner through ops.
 * Returns NULL when out of memory. Start it with sess_kick. */
sess *sess_new(uint32_t id, int fd, const char *addr, ev_loop *loop, const sess_ops *ops,
               void *owner);

/* sess_set_transport: the layer the session's bytes go through from now on (ctx is taken over
 * and closed with the session; a layer set before is closed); NULL: plain TCP. Call before the
 * first sess_kick, or to drop a layer that refused the connection (NET_NOT_TLS). */
void sess_set_transport(sess *s, const net_transport *tr, void *ctx);

/* sess_set_authed: the session passed authentication: requests after HELLO are decoded with
 * the full limits, and the idle deadline starts. */
void sess_set_authed(sess *s);
/* sess_busy: 1 while the session waits on the server (an OPEN preparing, frames owed, output
 * queued), so silence from the client is not idleness. */
int sess_busy(const sess *s);

/* sess_input: decodes and hands over the buffered input until it runs out, the session
 * pauses (paused = 1, e.g. an OPEN waiting for its cloud) or closes; then sess_kick. Call it
 * again after unpausing. */
void sess_input(sess *s);
/* sess_kick: writes what can be written now and updates the loop interest; closes the session
 * on a write error, or once a close-after-flush session has written everything. */
void sess_kick(sess *s);
/* sess_send: queues one encoded message (b's bytes taken over); an output over SESS_OUT_MAX
 * closes the session (a client that does not read). Does not write: sess_kick does. */
void sess_send(sess *s, proto_buf *b);
/* sess_close: closes the socket, stops the session's timers and tells the owner; safe to call
 * twice. The session stays allocated until the owner's sess_free. */
void sess_close(sess *s, const char *reason);
/* sess_free: frees s and everything queued in it (the socket must already be closed). Calls
 * release(user, id) for each frame still counted as outstanding by the render thread. */
void sess_free(sess *s, void (*release)(void *user, uint32_t id), void *user);

/* sess_push: appends one encoded message (b's bytes, taken over; b is left empty) as a ready
 * item. Returns 0, or SD_ELIMIT when the output is over SESS_OUT_MAX, SD_ENOMEM. */
int sess_push(sess *s, proto_buf *b);
/* sess_push_frame_slot: appends an unfilled frame placeholder for request seq. */
int sess_push_frame_slot(sess *s, uint32_t seq);
/* sess_fill_frame: fills the first unfilled placeholder with msg (taken over). Returns 0, or
 * SD_ENOTFOUND when none waits (msg is then freed by the caller). */
int sess_fill_frame(sess *s, uint8_t *msg, size_t len);
/* sess_set_stream_frame: puts a streamed frame in the slot; returns 1 when it replaced a waiting
 * one (which is freed and must be released to the render thread), 0 otherwise. */
int sess_set_stream_frame(sess *s, uint8_t *msg, size_t len);

/* sess_flush: writes what can be written without blocking, in order. Returns 1 when
 * everything is written, 0 when the socket is full (watch EV_WRITE), or a negative errno when
 * the connection failed. release(user, id) is called for each frame that leaves the waiting
 * state (starts being written). On failure s->io_err says why. */
int sess_flush(sess *s, void (*release)(void *user, uint32_t id), void *user);

/* sess_has_output: 1 when anything is queued or being written. */
int sess_has_output(const sess *s);
