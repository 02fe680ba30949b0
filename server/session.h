/* session.h — one client connection of the daemon: its decoder, render state, auth state and
 * ordered output queue. Lives on the event-loop thread only.
 *
 * Output: the protocol answers requests in order, so the output is a FIFO of items: bytes
 * (whole messages) or a frame placeholder that a RENDER puts in at once and the encoder fills
 * later. Items after an unfilled placeholder wait for it. Streamed frames (sequence 0) have a
 * separate one-frame slot, written between items; a newer streamed frame replaces a waiting one
 * (latest wins). Memory per session is bounded: bytes items by SESS_OUT_MAX (over it the client
 * is disconnected), frames by the render thread's per-client outstanding limit.
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

enum {
    SESS_OUT_MAX = 4 << 20,     /* bytes of non-frame output queued before the client is dropped */
    SESS_IN_CHUNK = 64 * 1024,  /* bytes read per wakeup (STYLE.md 8) */
};

typedef struct sess_item {
    int is_frame;               /* 1: a RENDER's frame placeholder */
    int filled;                 /* bytes present (always 1 for non-frames) */
    int counted;                /* a frame still counted as outstanding by the render thread */
    uint32_t seq;               /* the request it answers */
    uint8_t *data;
    size_t len;
    struct sess_item *next;
} sess_item;

typedef struct sess {
    uint32_t id;                /* (generation << 16) | index; never 0 */
    int fd;
    void *owner;                /* the daemon context (for timer callbacks) */
    char addr[NET_ADDR_LEN];
    char client_name[PROTO_MAX_CLIENT + 1];
    uint64_t t_connect_ms;

    /* input */
    proto_decoder dec;
    uint8_t *in;                /* SESS_IN_CHUNK bytes; in[in_off..in_len) not yet decoded */
    size_t in_len, in_off;
    int paused;                 /* 1 while an OPEN waits for its cloud: input is kept, not parsed */

    /* connection state */
    int hello_seen, authed;
    uint16_t version;
    uint8_t challenge[AUTH_CHALLENGE_LEN];
    ev_timer hs_timer;          /* handshake timeout */
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
} sess;

/* sess_new: a session for the accepted socket fd. Returns NULL when out of memory. */
sess *sess_new(uint32_t id, int fd, const char *addr);
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
 * state (starts being written). */
int sess_flush(sess *s, void (*release)(void *user, uint32_t id), void *user);

/* sess_has_output: 1 when anything is queued or being written. */
int sess_has_output(const sess *s);
