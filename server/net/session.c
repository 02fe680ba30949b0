/* session.c — a client connection's state and ordered output queue (see session.h). */
#include "session.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

sess *sess_new(uint32_t id, int fd, const char *addr, ev_loop *loop, const sess_ops *ops,
               void *owner)
{
    sess *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->in = malloc(SESS_IN_CHUNK);
    if (!s->in) { free(s); return NULL; }
    s->id = id;
    s->fd = fd;
    s->loop = loop;
    s->ops = ops;
    s->owner = owner;
    strncpy(s->addr, addr, sizeof s->addr - 1);
    s->tr = &net_tcp;
    proto_decoder_init(&s->dec, PROTO_C2S);
    s->dec.preauth = 1;
    s->cloud = -1;
    s->opening = -1;
    sp_params_defaults(&s->params);
    ev_timer_init(&s->hs_timer);
    ev_timer_init(&s->fps_timer);
    ev_timer_init(&s->idle_timer);
    ev_timer_init(&s->rd_timer);
    ev_timer_init(&s->wr_timer);
    ev_timer_init(&s->pend_timer);
    s->t_connect_ms = ev_now_ms();
    s->last_io_ms = s->t_connect_ms;
    return s;
}

void sess_set_transport(sess *s, const net_transport *tr, void *ctx)
{
    if (s->tr_ctx) s->tr->close(s->tr_ctx, 0);
    s->tr = tr ? tr : &net_tcp;
    s->tr_ctx = ctx;
    s->rd_want = s->wr_want = 0;
}

void sess_free(sess *s, void (*release)(void *user, uint32_t id), void *user)
{
    if (!s) return;
    if (s->tr_ctx) s->tr->close(s->tr_ctx, 0);
    sess_item *it = s->head;
    while (it) {
        sess_item *n = it->next;
        if (it->counted && release) release(user, s->id);
        free(it->data);
        free(it);
        it = n;
    }
    if (s->stream_frame && release) release(user, s->id);
    free(s->stream_frame);
    free(s->cur_own);
    proto_decoder_free(&s->dec);
    free(s->in);
    free(s);
}

static sess_item *append(sess *s)
{
    sess_item *it = calloc(1, sizeof *it);
    if (!it) return NULL;
    if (s->tail) s->tail->next = it;
    else s->head = it;
    s->tail = it;
    return it;
}

int sess_push(sess *s, proto_buf *b)
{
    if (s->out_bytes + b->len > SESS_OUT_MAX) {
        proto_buf_free(b);
        return SD_ELIMIT;
    }
    /* Coalesce with a ready bytes item at the tail that is not being written. */
    sess_item *t = s->tail;
    if (t && !t->is_frame && t != s->cur_item) {
        uint8_t *nd = realloc(t->data, t->len + b->len);
        if (!nd) { proto_buf_free(b); return SD_ENOMEM; }
        memcpy(nd + t->len, b->data, b->len);
        t->data = nd;
        t->len += b->len;
        s->out_bytes += b->len;
        proto_buf_free(b);
        return 0;
    }
    sess_item *it = append(s);
    if (!it) { proto_buf_free(b); return SD_ENOMEM; }
    it->filled = 1;
    it->data = b->data;
    it->len = b->len;
    s->out_bytes += b->len;
    memset(b, 0, sizeof *b);
    return 0;
}

int sess_push_frame_slot(sess *s, uint32_t seq)
{
    sess_item *it = append(s);
    if (!it) return SD_ENOMEM;
    it->is_frame = 1;
    it->seq = seq;
    s->frames_queued++;
    return 0;
}

int sess_fill_frame(sess *s, uint8_t *msg, size_t len)
{
    for (sess_item *it = s->head; it; it = it->next) {
        if (it->is_frame && !it->filled) {
            it->data = msg;
            it->len = len;
            it->filled = 1;
            it->counted = 1;
            s->frames_queued--;
            return 0;
        }
    }
    return SD_ENOTFOUND;
}

int sess_set_stream_frame(sess *s, uint8_t *msg, size_t len)
{
    int replaced = s->stream_frame != NULL;
    free(s->stream_frame);
    s->stream_frame = msg;
    s->stream_len = len;
    if (replaced) s->frames_dropped++;
    return replaced;
}

int sess_has_output(const sess *s)
{
    return s->cur != NULL || s->head != NULL || s->stream_frame != NULL;
}

/* next_message: makes the next ready message current (head item if filled, else a streamed
 * frame). Returns 0 when nothing is ready. */
static int next_message(sess *s, void (*release)(void *, uint32_t), void *user)
{
    sess_item *h = s->head;
    if (h && h->filled) {
        s->cur_item = h;
        s->cur = h->data;
        s->cur_len = h->len;
        s->cur_off = 0;
        if (h->counted) {
            h->counted = 0;
            if (release) release(user, s->id);
        }
        return 1;
    }
    if (s->stream_frame) {
        s->cur_own = s->stream_frame;
        s->cur = s->stream_frame;
        s->cur_len = s->stream_len;
        s->cur_off = 0;
        s->stream_frame = NULL;
        if (release) release(user, s->id);
        return 1;
    }
    return 0;
}

/* done_message: frees the message just written (a frame's bytes are then given back to the
 * owner's budget through ops->sent). */
static void done_message(sess *s)
{
    int frame = !s->cur_item || s->cur_item->is_frame;
    if (s->cur_item) {
        sess_item *h = s->cur_item;
        if (h->is_frame) s->frames_sent++;
        else s->out_bytes -= h->len;
        s->head = h->next;
        if (!s->head) s->tail = NULL;
        free(h->data);
        free(h);
        s->cur_item = NULL;
    } else {
        free(s->cur_own);
        s->cur_own = NULL;
        s->frames_sent++;
    }
    s->cur = NULL;
    s->cur_len = s->cur_off = 0;
    if (frame && s->ops && s->ops->sent) s->ops->sent(s->owner, s->id);
}

int sess_flush(sess *s, void (*release)(void *user, uint32_t id), void *user)
{
    /* At most 16 messages per call, so one client cannot hold the loop (STYLE.md 8). */
    for (int n = 0; n < 16; n++) {
        if (!s->cur && !next_message(s, release, user)) return 1;
        while (s->cur_off < s->cur_len) {
            int want = 0;
            ssize_t w = s->tr->write(s->tr_ctx, s->fd, s->cur + s->cur_off,
                                     s->cur_len - s->cur_off, &want, s->io_err,
                                     sizeof s->io_err);
            if (w == NET_AGAIN) {
                s->wr_want = want;
                return 0;
            }
            if (w <= 0) {
                s->tr_failed = 1;
                return -EIO;
            }
            s->wr_want = 0;
            s->cur_off += (size_t)w;
            s->bytes_out += (uint64_t)w;
        }
        done_message(s);
    }
    int ready = s->cur || (s->head && s->head->filled) || s->stream_frame;
    return ready ? 0 : 1;
}

/* ---- the connection: reading, decoding, interest, deadlines, closing ---- */

int sess_busy(const sess *s)
{
    return s->opening >= 0 || s->frames_queued > 0 || sess_has_output(s);
}

static void on_idle(ev_loop *l, ev_timer *t, void *data)
{
    (void)t;
    sess *s = data;
    uint64_t now = ev_now_ms(), quiet = now - s->last_io_ms, lim = s->lim->idle_ms;
    if (sess_busy(s)) quiet = 0; /* waiting on the server is not the client's silence */
    if (quiet < lim) {
        /* Re-armed lazily here rather than on every byte: one heap operation per idle period
         * instead of one per read. */
        ev_timer_start(l, &s->idle_timer, lim - quiet, on_idle, s);
        return;
    }
    char why[96];
    snprintf(why, sizeof why, "idle for %u s (--idle-timeout)", (unsigned)(lim / 1000));
    sess_close(s, why);
}

static void on_read_deadline(ev_loop *l, ev_timer *t, void *data)
{
    (void)l; (void)t;
    sess *s = data;
    char why[128];
    snprintf(why, sizeof why, "a message still incomplete %u s after its first byte (--read-timeout)",
             (unsigned)(s->lim->read_ms / 1000));
    sess_close(s, why);
}

static void on_write_deadline(ev_loop *l, ev_timer *t, void *data)
{
    (void)l; (void)t;
    sess *s = data;
    char why[128];
    snprintf(why, sizeof why, "no output could be written for %u s: the client does not read "
             "(--write-timeout)", (unsigned)(s->lim->write_ms / 1000));
    sess_close(s, why);
}

/* read_deadline: arms the message deadline when a message has begun (the decoder holds part of
 * a header or payload) and the session is reading, and disarms it otherwise. The deadline runs
 * from the message's first byte, not between reads, so one byte a second cannot keep it
 * alive. */
static void read_deadline(sess *s)
{
    if (!s->lim || !s->lim->read_ms || s->dead) return;
    /* hdr_have is the decoder's count of header bytes of the message in progress: 0 exactly at
     * a message boundary (proto_decode resets it when a message completes). */
    int part = s->dec.hdr_have > 0 || (s->tr->midway && s->tr->midway(s->tr_ctx));
    int mid = part && !s->paused && !s->close_after;
    if (!mid) ev_timer_stop(s->loop, &s->rd_timer);
    else if (!ev_timer_armed(&s->rd_timer))
        ev_timer_start(s->loop, &s->rd_timer, s->lim->read_ms, on_read_deadline, s);
}

void sess_set_authed(sess *s)
{
    s->authed = 1;
    s->dec.preauth = 0;
    s->dec.version = s->version;
    ev_timer_stop(s->loop, &s->hs_timer);
    s->last_io_ms = ev_now_ms();
    if (s->lim && s->lim->idle_ms)
        ev_timer_start(s->loop, &s->idle_timer, s->lim->idle_ms, on_idle, s);
}

static void on_io(ev_loop *l, int fd, int mask, void *data);

static void on_pending(ev_loop *l, ev_timer *t, void *data)
{
    (void)t;
    sess *s = data;
    if (!s->dead) on_io(l, s->fd, EV_READ, s);
}

/* update_watch: EV_READ while the input is drained and the session takes requests, EV_WRITE
 * when output waits, EV_HUP alone while requests wait unread (to notice the client going).
 * A transport may turn these around (a TLS read that must write first, a write that must read
 * first), and input its layer already holds is read from a zero-delay timer, since the socket
 * will not signal it. */
static void update_watch(sess *s, int want_write)
{
    int mask = want_write ? (s->wr_want == EV_READ ? EV_READ : EV_WRITE) : 0;
    int reading = !s->paused && !s->close_after && s->in_off == s->in_len;
    if (reading) mask |= EV_READ | (s->rd_want == EV_WRITE ? EV_WRITE : 0);
    else if (!s->close_after) mask |= EV_HUP;
    if ((mask & EV_READ) && (mask & EV_HUP)) mask &= ~EV_HUP;
    if (reading && s->tr->pending(s->tr_ctx) && !ev_timer_armed(&s->pend_timer))
        ev_timer_start(s->loop, &s->pend_timer, 0, on_pending, s);
    if (ev_mask(s->loop, s->fd) == mask) return;
    if (mask == 0) ev_unwatch(s->loop, s->fd);
    else if (ev_watch(s->loop, s->fd, mask, on_io, s, NULL) != 0) sess_close(s, "event loop error");
}

/* release_cb: sess_flush's callback from sess_kick: a frame starts being written. */
static void release_cb(void *user, uint32_t id)
{
    sess *s = user;
    if (s->ops->sending) s->ops->sending(s->owner, id);
    else if (s->ops->release) s->ops->release(s->owner, id);
}

void sess_kick(sess *s)
{
    if (s->dead) return;
    uint64_t before = s->bytes_out;
    int rc = sess_flush(s, release_cb, s);
    int progress = s->bytes_out != before;
    if (progress) s->last_io_ms = ev_now_ms();
    if (rc < 0) {
        char r[192];
        snprintf(r, sizeof r, "%s", s->io_err[0] ? s->io_err : "write failed");
        sess_close(s, r);
        return;
    }
    if (s->close_after && !sess_has_output(s)) {
        sess_close(s, s->close_reason[0] ? s->close_reason : "closing");
        return;
    }
    /* The write deadline runs while output waits on a full socket and restarts whenever some
     * of it leaves (nginx send_timeout: between two successive writes). */
    if (s->lim && s->lim->write_ms) {
        if (rc == 1) ev_timer_stop(s->loop, &s->wr_timer);
        else if (progress || !ev_timer_armed(&s->wr_timer))
            ev_timer_start(s->loop, &s->wr_timer, s->lim->write_ms, on_write_deadline, s);
    }
    int blocked = s->stream_frame != NULL;
    if (blocked != s->stream_blocked) {
        s->stream_blocked = blocked;
        if (s->ops->stream_blocked) s->ops->stream_blocked(s->owner, s, blocked);
    }
    update_watch(s, rc == 0);
}

void sess_send(sess *s, proto_buf *b)
{
    if (s->dead) {
        proto_buf_free(b);
        return;
    }
    int rc = sess_push(s, b);
    if (rc == SD_ELIMIT) {
        s->close_after = 0;
        sess_close(s, "its output went over the limit (the client does not read)");
    } else if (rc != 0) {
        sess_close(s, "out of memory queueing output");
    }
}

void sess_close(sess *s, const char *reason)
{
    if (s->dead) return;
    s->dead = 1;
    ev_unwatch(s->loop, s->fd);
    if (s->tr_ctx) s->tr->close(s->tr_ctx, !s->tr_failed);
    s->tr_ctx = NULL;
    close(s->fd);
    s->fd = -1;
    ev_timer_stop(s->loop, &s->hs_timer);
    ev_timer_stop(s->loop, &s->fps_timer);
    ev_timer_stop(s->loop, &s->idle_timer);
    ev_timer_stop(s->loop, &s->rd_timer);
    ev_timer_stop(s->loop, &s->wr_timer);
    ev_timer_stop(s->loop, &s->pend_timer);
    s->ops->on_close(s->owner, s, reason);
}

void sess_input(sess *s)
{
    while (!s->dead && !s->close_after && !s->paused && s->in_off < s->in_len) {
        size_t used = 0;
        proto_msg m;
        proto_error pe = {0};
        int rc = proto_decode(&s->dec, s->in + s->in_off, s->in_len - s->in_off, &used, &m, &pe);
        s->in_off += used;
        if (rc < 0) {
            /* Framing is lost: the owner answers with the code, and the session closes once
             * that is written (PROTOCOL.md 2). */
            s->ops->on_decode_error(s->owner, s, -rc, pe.msg);
            break;
        }
        if (rc == PROTO_ONE_MSG) s->ops->on_message(s->owner, s, &m);
    }
    if (s->in_off == s->in_len) s->in_off = s->in_len = 0;
    read_deadline(s);
    sess_kick(s);
}

/* read_some: one read through the transport into the input buffer, decoded at once. Returns
 * 1 when bytes came, 0 when none could (the transport waits for an event), -1 when the session
 * closed or is closing. */
static int read_some(sess *s)
{
    int want = EV_READ;
    s->io_err[0] = 0;
    ssize_t r = s->tr->read(s->tr_ctx, s->fd, s->in, SESS_IN_CHUNK, &want, s->io_err,
                            sizeof s->io_err);
    s->rd_want = r == NET_AGAIN ? want : 0;
    if (r == 0) {
        char why[sizeof s->io_err];
        snprintf(why, sizeof why, "%s", s->io_err[0] ? s->io_err
                 : s->authed ? "closed by the client" : "closed by the client before the handshake");
        sess_close(s, why);
        return -1;
    }
    if (r == NET_AGAIN) {
        /* The transport may hold part of one of its own units (a WebSocket frame header): the
         * read deadline covers those as well as a protocol message begun. */
        read_deadline(s);
        return 0;
    }
    if (r == NET_NOT_TLS) {
        /* A plaintext client on a TLS listener: told so in plaintext (the one thing sent
         * unencrypted), then closed; nothing it sent is read. */
        char why[sizeof s->io_err];
        snprintf(why, sizeof why, "%s", s->io_err);
        sess_set_transport(s, NULL, NULL);
        s->io_err[0] = 0;
        s->ops->on_decode_error(s->owner, s, PROTO_E_AUTH_REQUIRED,
                                "this server accepts TLS connections only: connect with TLS "
                                "(splat --tls, spc_options.tls)");
        snprintf(s->close_reason, sizeof s->close_reason, "%s", why);
        sess_kick(s);
        return -1;
    }
    if (r < 0) {
        char why[sizeof s->io_err];
        snprintf(why, sizeof why, "%s", s->io_err[0] ? s->io_err : "read failed");
        s->tr_failed = 1;
        sess_close(s, why);
        return -1;
    }
    s->last_io_ms = ev_now_ms();
    s->in_off = 0;
    s->in_len = (size_t)r;
    sess_input(s);
    return 1;
}

static void on_io(ev_loop *l, int fd, int mask, void *data)
{
    (void)l;
    (void)fd;
    sess *s = data;
    if (s->dead) return;
    if (mask & EV_READ) s->last_in_ms = ev_now_ms(); /* bytes (or the end) arrived */
    if ((mask & EV_HUP) && !(mask & EV_READ)) {
        /* A hang-up while its input is not being read: the answers have nobody to go to. */
        sess_close(s, "closed by the client while its requests waited");
        return;
    }
    /* A read is due on input, or on the socket turning writable when the last read had to
     * write first (a TLS handshake or key update behind a full send buffer). */
    int readable = (mask & EV_READ) || (s->rd_want == EV_WRITE && (mask & EV_WRITE));
    if (readable && s->in_off == s->in_len) {
        /* A few reads when the transport holds more input than one buffer (a WebSocket's
         * frames); sess_input kicks the output after each. */
        for (int n = 0; n < 4; n++) {
            int rc = read_some(s);
            if (rc < 0) return;
            if (rc == 0 || s->dead || s->paused || s->close_after || s->in_off != s->in_len ||
                !s->tr->pending(s->tr_ctx))
                break;
        }
        if (!s->dead) sess_kick(s);
        return;
    }
    sess_kick(s);
}
