/* dispatch.c — the daemon's request handling: one function per message type, the cloud
 * table (each cloud prepared and uploaded once, shared by every client), and the events the
 * workers post (frames, progress, loaded clouds). Event-loop thread only, except
 * srv_pack_frame (encoder thread). Answers go out in request order (PROTOCOL.md section 5). */
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "datadir.h"
#include "srv.h"

#ifndef SPLATD_VERSION
#define SPLATD_VERSION "0.1.0"
#endif

void srv_log(const srv *sv, const sess *s, const char *fmt, ...)
{
    (void)sv;
    char line[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    time_t t = time(NULL);
    struct tm tm;
    gmtime_r(&t, &tm);
    char ts[32];
    strftime(ts, sizeof ts, "%Y-%m-%dT%H:%M:%SZ", &tm);
    if (s) fprintf(stderr, "splatd %s %s %s\n", ts, s->addr, line);
    else fprintf(stderr, "splatd %s %s\n", ts, line);
}

sess *srv_lookup(srv *sv, uint32_t id)
{
    uint32_t i = id & 0xffffu;
    if (i >= (uint32_t)sv->nslots) return NULL;
    sess *s = sv->sessions[i];
    return (s && s->id == id && !s->dead) ? s : NULL;
}

void srv_release_frame(void *user, uint32_t id)
{
    srv *sv = user;
    rt_frame_released(sv->rt, id);
}

void srv_sending_frame(void *user, uint32_t id)
{
    srv *sv = user;
    rt_frame_sending(sv->rt, id);
}

void srv_sent_frame(void *user, uint32_t id)
{
    srv *sv = user;
    rt_frame_sent(sv->rt, id);
}

/* utf8_len: the length (1-4) of the well-formed UTF-8 sequence at p (n bytes available), or
 * 0 when it is not one (RFC 3629: no overlong forms, no surrogates, at most U+10FFFF). */
static size_t utf8_len(const unsigned char *p, size_t n)
{
    unsigned c = p[0];
    if (c < 0x80) return 1;
    size_t k = c >= 0xf0 ? 4 : c >= 0xe0 ? 3 : c >= 0xc2 ? 2 : 0;
    if (k == 0 || c > 0xf4 || k > n) return 0;
    for (size_t i = 1; i < k; i++)
        if ((p[i] & 0xc0) != 0x80) return 0;
    if (c == 0xe0 && p[1] < 0xa0) return 0; /* overlong */
    if (c == 0xed && p[1] > 0x9f) return 0; /* surrogates */
    if (c == 0xf0 && p[1] < 0x90) return 0; /* overlong */
    if (c == 0xf4 && p[1] > 0x8f) return 0; /* over U+10FFFF */
    return k;
}

void srv_clean_text(const char *in, char *out, size_t len)
{
    const unsigned char *p = (const unsigned char *)in;
    size_t n = strlen(in), o = 0;
    if (len == 0) return;
    while (n) {
        size_t k = utf8_len(p, n);
        int escape = k == 0 || (k == 1 && (*p < 0x20 || *p == 0x7f));
        size_t need = escape ? 4 : k;
        if (o + need + 1 > len) break; /* never cut a sequence or an escape in half */
        if (escape) {
            snprintf(out + o, len - o, "\\x%02x", *p);
            k = 1;
        } else {
            memcpy(out + o, p, k);
        }
        o += need;
        p += k;
        n -= k;
    }
    out[o] = 0;
}

/* send_error: queues ERROR code for request seq; a fatal code (PROTOCOL.md 6) stops reading and
 * closes the connection once the output is flushed. Logs one line. */
static void send_error(srv *sv, sess *s, uint32_t seq, int code, const char *msg)
{
    proto_buf b = {.version = s->version};
    /* Texts may quote the client's own bytes (a parameter name) or a file's (a bad token):
     * the client gets valid UTF-8 without control characters, the log one line. */
    char text[PROTO_MAX_ERRTEXT + 1];
    srv_clean_text(msg, text, sizeof text);
    srv_log(sv, s, "error %s (seq %u): %s", proto_err_name(code), seq, text);
    if (proto_enc_error(&b, seq, (uint32_t)code, text) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
    if (proto_err_fatal(code) && !s->dead) {
        s->close_after = 1;
        snprintf(s->close_reason, sizeof s->close_reason, "after error %s", proto_err_name(code));
    }
}

int srv_pack_frame(void *user, const rt_frame_meta *m, const uint8_t *data, size_t len,
                   uint8_t **msg, size_t *msglen)
{
    (void)user;
    if (!proto_frame_fits(len)) return SD_ELIMIT;
    uint8_t *p = malloc(PROTO_FRAME_HEAD_LEN + len);
    if (!p) return SD_ENOMEM;
    proto_frame f = {
        .camera_seq = m->camera_seq, .pipeline = (uint8_t)m->pipeline, .format = (uint8_t)m->format,
        .width = (uint32_t)m->width, .height = (uint32_t)m->height, .render_us = m->render_us,
        .readback_us = m->readback_us, .encode_us = m->encode_us, .points_drawn = m->points_drawn,
        .flags = (uint16_t)((m->complete ? PROTO_FRAME_COMPLETE : 0) |
                            (m->flags & RND_FRAME_SOFT_TRUNCATED ? PROTO_FRAME_SOFT_TRUNCATED : 0) |
                            (m->provisional ? PROTO_FRAME_PROVISIONAL : 0)),
        .data_len = (uint32_t)len,
    };
    proto_frame_head(p, PROTO_VERSION, m->stream ? 0 : m->req_seq, &f);
    memcpy(p + PROTO_FRAME_HEAD_LEN, data, len);
    *msg = p;
    *msglen = PROTO_FRAME_HEAD_LEN + len;
    return 0;
}

/* ---- cloud table ---- */

static srv_cloud *cloud_by_path(srv *sv, const char *path)
{
    for (int i = 0; i < sv->nclouds; i++)
        if (sv->clouds[i].state != SRV_CLOUD_FREE && !strcmp(sv->clouds[i].path, path))
            return &sv->clouds[i];
    return NULL;
}

/* cloud_by_key: the loading entry an event's key names, or NULL (a stale key: the entry was
 * freed and started another load since). */
static srv_cloud *cloud_by_key(srv *sv, uint32_t key)
{
    uint32_t i = (key & 0xffffu) - 1;
    if ((key & 0xffffu) == 0 || i >= (uint32_t)sv->nclouds) return NULL;
    srv_cloud *c = &sv->clouds[i];
    return c->state == SRV_CLOUD_LOADING && c->key == key ? c : NULL;
}

/* cloud_start: a new LOADING entry for path with its prep job queued, or NULL when out of
 * memory. */
static srv_cloud *cloud_start(srv *sv, const char *path)
{
    srv_cloud *c = NULL;
    for (int i = 0; i < sv->nclouds; i++)
        if (sv->clouds[i].state == SRV_CLOUD_FREE) { c = &sv->clouds[i]; break; }
    if (!c) {
        if (sv->nclouds >= 0xffff) return NULL; /* keys hold the index in 16 bits */
        srv_cloud *nc = realloc(sv->clouds, (size_t)(sv->nclouds + 1) * sizeof *nc);
        if (!nc) return NULL;
        sv->clouds = nc;
        c = &sv->clouds[sv->nclouds++];
        c->gen = 0;
    }
    uint16_t gen = (uint16_t)(c->gen + 1);
    if (gen == 0) gen = 1; /* 0 never names a live load */
    memset(c, 0, sizeof *c);
    c->gen = gen;
    c->key = ((uint32_t)gen << 16) | (uint32_t)(c - sv->clouds + 1);
    snprintf(c->path, sizeof c->path, "%s", path);
    const char *slash = strrchr(path, '/');
    snprintf(c->name, sizeof c->name, "%s", slash ? slash + 1 : path);
    if (rt_prepare(sv->rt, path, c->key) != 0) return NULL;
    c->state = SRV_CLOUD_LOADING;
    c->t_start_ms = ev_now_ms();
    return c;
}

static int add_waiter(srv_cloud *c, uint32_t sess_id, uint32_t seq, int shown)
{
    if (c->nwait == c->capwait) {
        int cap = c->capwait ? c->capwait * 2 : 4;
        srv_waiter *w = realloc(c->waiters, (size_t)cap * sizeof *w);
        if (!w) return SD_ENOMEM;
        c->waiters = w;
        c->capwait = cap;
    }
    c->waiters[c->nwait++] = (srv_waiter){sess_id, seq, shown};
    return 0;
}

int srv_preload(srv *sv, const char *name, sd_err *err)
{
    char path[PATH_MAX];
    int rc = dd_resolve(sv->o.data_dir, name, path, sizeof path, NULL, err);
    if (rc) return rc;
    if (!cloud_by_path(sv, path) && !cloud_start(sv, path))
        return sd_errf(err, SD_ENOMEM, "out of memory preparing %s", name);
    return 0;
}

/* send_info: queues INFO about cloud c answering request seq. */
static void send_info(srv *sv, sess *s, const srv_cloud *c, uint32_t seq)
{
    proto_info in = c->info.summary;
    snprintf(in.name, sizeof in.name, "%s", c->name);
    proto_buf b = {.version = s->version};
    if (proto_enc_info(&b, seq, &in) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
}

/* ---- rendering requests ---- */

/* make_request: the current render request of s (its camera, or one framing the cloud). */
static void make_request(srv *sv, sess *s, rt_request *rq, uint32_t req_seq)
{
    memset(rq, 0, sizeof *rq);
    rq->cloud_id = s->cloud_id;
    rq->params = s->params;
    rq->req_seq = req_seq;
    if (s->have_camera) {
        rq->cam = s->cam;
        rq->camera_seq = s->camera_seq;
    } else {
        const srv_cloud *c = &sv->clouds[s->cloud];
        rnd_camera_frame(&c->info.summary.view, RND_DEFAULT_WIDTH, RND_DEFAULT_HEIGHT, 0,
                         &rq->cam);
        rq->camera_seq = 0;
    }
}

static void on_fps_timer(ev_loop *l, ev_timer *t, void *data);

/* frame_fits: 1 when a frame of rq can be sent (a raw frame's size is known before it is
 * rendered: it must fit the protocol's frame limit) and is within --max-frame-bytes on its own;
 * else answers BAD_CAMERA to request seq, naming the limit its size and format ask too much of,
 * and returns 0. Nothing is rendered for a frame that could not be sent. */
static int frame_fits(srv *sv, sess *s, const rt_request *rq, uint32_t seq)
{
    char t[320], fmt[32];
    const char *fname = sp_enum_name(SP_FORMAT, rq->params.format, fmt, sizeof fmt);
    uint64_t raw = (uint64_t)rq->cam.width * (uint64_t)rq->cam.height * 4;
    if (rq->params.format == SP_FMT_RAW && !proto_frame_fits(raw)) {
        snprintf(t, sizeof t, "a %dx%d frame in format raw is %llu bytes of FRAME payload, over "
                 "the protocol's frame limit of %u bytes (PROTOCOL.md section 3): ask for a "
                 "smaller size or a compressed format", rq->cam.width, rq->cam.height,
                 (unsigned long long)(raw + PROTO_FRAME_FIXED), (unsigned)PROTO_MAX_FRAME);
        send_error(sv, s, seq, PROTO_E_BAD_CAMERA, t);
        return 0;
    }
    uint64_t c = rt_frame_cost(rq), b = rt_frame_budget(sv->rt);
    if (c <= b) return 1;
    snprintf(t, sizeof t, "a %dx%d frame in format %s needs up to %llu MiB, over this server's "
             "%llu MiB for frames (--max-frame-bytes): ask for a smaller size or format",
             rq->cam.width, rq->cam.height, fname ? fname : "?",
             (unsigned long long)(c >> 20), (unsigned long long)(b >> 20));
    send_error(sv, s, seq, PROTO_E_BAD_CAMERA, t);
    return 0;
}

/* stream_update: in stream mode, submits the session's current view (latest wins), held back
 * by the fps timer when max_fps would be exceeded. */
static void stream_update(srv *sv, sess *s, uint32_t seq)
{
    if (!s->stream || s->cloud < 0 || sv->stopping) return;
    s->stream_seq = seq;
    uint64_t now = ev_now_ms();
    if (s->max_fps > 0) {
        /* In double and capped at a day: a cap as small as a float allows (1e-45 frames/s is
         * in [0, 1000]) makes 1000 / max_fps infinite, which no integer holds. */
        double gapd = 1000.0 / (double)s->max_fps;
        uint64_t gap = gapd < 86400000.0 ? (uint64_t)gapd : 86400000u;
        if (now < s->last_stream_ms + gap) {
            if (!ev_timer_armed(&s->fps_timer))
                ev_timer_start(sv->loop, &s->fps_timer, s->last_stream_ms + gap - now, on_fps_timer, s);
            return;
        }
    }
    ev_timer_stop(sv->loop, &s->fps_timer);
    s->last_stream_ms = now;
    rt_request rq;
    make_request(sv, s, &rq, seq);
    if (!frame_fits(sv, s, &rq, seq)) return;
    rt_submit_latest(sv->rt, s->id, &rq);
}

static void on_fps_timer(ev_loop *l, ev_timer *t, void *data)
{
    (void)l; (void)t;
    sess *s = data;
    stream_update(s->owner, s, s->stream_seq);
}

/* ---- one handler per message type; each returns after queueing its answer ---- */

static void send_welcome(srv *sv, sess *s, uint32_t seq)
{
    proto_welcome w = {0};
    w.version = s->version;
    w.auth_required = sv->token.len > 0;
    w.authenticated = (uint8_t)s->authed;
    memcpy(w.challenge, s->challenge, sizeof w.challenge);
    w.max_request = PROTO_MAX_REQUEST;
    w.max_width = (uint32_t)sv->max_w;
    w.max_height = (uint32_t)sv->max_h;
    snprintf(w.server, sizeof w.server, "splatd %s", SPLATD_VERSION);
    snprintf(w.backend, sizeof w.backend, "%s", rt_backend_name(sv->rt));
    snprintf(w.renderer, sizeof w.renderer, "%s", rt_renderer_string(sv->rt));
    proto_buf b = {.version = s->version};
    if (proto_enc_welcome(&b, seq, &w) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
}

static void on_hello(srv *sv, sess *s, const proto_msg *m)
{
    proto_hello h;
    proto_error pe = {0};
    int rc = proto_parse_hello(m->payload, m->len, &h, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    if (s->authed) {
        /* A connection has one handshake (PROTOCOL.md 4): a client sending HELLO again has lost
         * track of the connection's state, and another WELCOME would hide that. */
        send_error(sv, s, m->h.seq, PROTO_E_UNKNOWN_TYPE,
                   "HELLO after the handshake: a connection has one handshake");
        return;
    }
    int v = proto_pick_version(h.min_version, h.max_version, &pe);
    if (v < 0) { send_error(sv, s, m->h.seq, -v, pe.msg); return; }
    srv_clean_text(h.client, s->client_name, sizeof s->client_name); /* for the log */
    if (!s->hello_seen) {
        s->hello_seen = 1;
        s->version = (uint16_t)v;
        if (sv->token.len != 0) {
            /* The first HELLO only learns the challenge (PROTOCOL.md 4): answer unauthenticated. */
            send_welcome(sv, s, m->h.seq);
            return;
        }
    } else if (h.proof_len != PROTO_AUTH_LEN ||
               !auth_verify(&sv->token, s->challenge, h.proof, h.proof_len)) {
        /* Answered after a delay growing per address (daemon.c), not at once. */
        srv_auth_failed(sv, s, m->h.seq, h.proof_len == 0);
        return;
    }
    if (!srv_admit(sv, s, m->h.seq)) return;
    srv_log(sv, s, "hello from '%s', protocol %u%s", s->client_name, s->version,
            sv->token.len ? ", authenticated" : "");
    send_welcome(sv, s, m->h.seq);
}

static void on_list(srv *sv, sess *s, const proto_msg *m)
{
    proto_error pe;
    int prc = proto_parse_empty(m->h.type, m->len, &pe);
    if (prc < 0) { send_error(sv, s, m->h.seq, -prc, pe.msg); return; }
    dd_entry *v = NULL;
    size_t n = 0;
    sd_err err = {0};
    if (dd_list(sv->o.data_dir, &v, &n, &err) != 0) {
        send_error(sv, s, m->h.seq, PROTO_E_INTERNAL, err.msg);
        return;
    }
    proto_cloud_entry *items = calloc(n ? n : 1, sizeof *items);
    if (!items) { free(v); send_error(sv, s, m->h.seq, PROTO_E_INTERNAL, "out of memory"); return; }
    char rdir[PATH_MAX];
    if (!realpath(sv->o.data_dir, rdir)) snprintf(rdir, sizeof rdir, "%s", sv->o.data_dir);
    for (size_t i = 0; i < n; i++) {
        snprintf(items[i].name, sizeof items[i].name, "%s", v[i].name);
        items[i].bytes = v[i].size;
        char path[PATH_MAX];
        if (dd_resolve(sv->o.data_dir, v[i].name, path, sizeof path, NULL, NULL) == 0) {
            const srv_cloud *c = cloud_by_path(sv, path);
            if (c && c->state == SRV_CLOUD_READY) {
                items[i].points = c->info.summary.points;
                items[i].flags = PROTO_CLOUD_LOADED | PROTO_CLOUD_PREPARED;
            } else if (cache_probe_points(path, sv->o.cache_dir, 0, &items[i].points)) {
                /* prepared (for the daemon's k), not loaded: the count is in the cache header */
                items[i].flags = PROTO_CLOUD_PREPARED;
            }
        }
    }
    proto_buf b = {.version = s->version};
    if (proto_enc_clouds(&b, m->h.seq, items, (uint32_t)n) == 0) sess_send(s, &b);
    else { proto_buf_free(&b); send_error(sv, s, m->h.seq, PROTO_E_INTERNAL, "cloud list too long"); }
    free(items);
    free(v);
}

static void on_open(srv *sv, sess *s, const proto_msg *m)
{
    char name[PROTO_MAX_NAME + 1];
    proto_error pe = {0};
    int rc = proto_parse_open(m->payload, m->len, name, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    char path[PATH_MAX];
    dd_why why;
    sd_err err = {0};
    if (dd_resolve(sv->o.data_dir, name, path, sizeof path, &why, &err) != 0) {
        int code = why == DD_NOT_FOUND ? PROTO_E_NOT_FOUND
                 : why == DD_NOT_CLOUD ? PROTO_E_NOT_FOUND
                 : PROTO_E_BAD_NAME; /* bad name, outside the data dir, ambiguous */
        send_error(sv, s, m->h.seq, code, err.msg);
        return;
    }
    /* OPEN replaces the open cloud and resets the camera (PROTOCOL.md, OPEN). */
    s->cloud = -1;
    s->cloud_id = 0;
    s->have_camera = 0;
    s->camera_seq = 0;
    srv_cloud *c = cloud_by_path(sv, path);
    if (c && c->state == SRV_CLOUD_READY) {
        s->cloud = (int)(c - sv->clouds);
        s->cloud_id = c->cloud_id;
        srv_log(sv, s, "open %s: %s (in memory)", name, c->name);
        send_info(sv, s, c, m->h.seq);
        return;
    }
    if (!c) c = cloud_start(sv, path);
    int shown = c && c->prov_id && s->params.provisional;
    if (!c || add_waiter(c, s->id, m->h.seq, shown) != 0) {
        send_error(sv, s, m->h.seq, PROTO_E_INTERNAL, "out of memory opening the cloud");
        return;
    }
    if (shown) { /* its provisional cloud now, the full one later (PROTOCOL.md, OPEN) */
        s->cloud = (int)(c - sv->clouds);
        s->cloud_id = c->prov_id;
        srv_log(sv, s, "open %s: %s (provisional while preparing)", name, c->name);
        send_info(sv, s, c, m->h.seq);
        return;
    }
    srv_log(sv, s, "open %s: %s (preparing)", name, c->name);
    s->opening = (int)(c - sv->clouds);
    s->open_seq = m->h.seq;
    s->paused = 1; /* later requests wait for INFO, so answers stay in order */
}

static int need_cloud(srv *sv, sess *s, uint32_t seq, const char *what)
{
    if (s->cloud >= 0) return 1;
    char t[128];
    snprintf(t, sizeof t, "%s before a successful OPEN: open a cloud first", what);
    send_error(sv, s, seq, PROTO_E_NOT_OPEN, t);
    return 0;
}

/* camera_in: c as the renderer's camera into k; 0, or answers BAD_CAMERA to seq (what names the
 * message) when its size is over the server's maximum and returns -1. */
static int camera_in(srv *sv, sess *s, uint32_t seq, const char *what, const proto_camera *c,
                     rnd_camera *k)
{
    if ((int)c->width > sv->max_w || (int)c->height > sv->max_h) {
        char t[160];
        snprintf(t, sizeof t, "%s size %ux%u is over this server's maximum of %dx%d", what,
                 c->width, c->height, sv->max_w, sv->max_h);
        send_error(sv, s, seq, PROTO_E_BAD_CAMERA, t);
        return -1;
    }
    memcpy(k->eye, c->eye, sizeof k->eye);
    memcpy(k->target, c->target, sizeof k->target);
    memcpy(k->up, c->up, sizeof k->up);
    k->fov_deg = c->fov_deg;
    k->znear = c->znear;
    k->zfar = c->zfar;
    k->width = (int)c->width;
    k->height = (int)c->height;
    return 0;
}

/* PREFETCH: the next cameras of a path; the render thread reads their LOD nodes ahead. No
 * answer unless it is wrong (a flat cloud has nothing to prefetch: accepted, nothing done). */
static void on_prefetch(srv *sv, sess *s, const proto_msg *m)
{
    proto_prefetch pf;
    proto_error pe = {0};
    int rc = proto_parse_prefetch(m->payload, m->len, &pf, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    if (!need_cloud(sv, s, m->h.seq, "PREFETCH")) return;
    rnd_camera cams[PROTO_MAX_PREFETCH];
    for (unsigned k = 0; k < pf.count; k++) {
        char what[32];
        snprintf(what, sizeof what, "PREFETCH camera %u", k);
        if (camera_in(sv, s, m->h.seq, what, &pf.cams[k], &cams[k]) < 0) return;
    }
    rt_submit_prefetch(sv->rt, s->id, s->cloud_id, cams, pf.count, &s->params);
}

static void on_camera(srv *sv, sess *s, const proto_msg *m)
{
    proto_camera c;
    proto_error pe = {0};
    int rc = proto_parse_camera(m->payload, m->len, &c, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    if (!need_cloud(sv, s, m->h.seq, "CAMERA")) return;
    if (camera_in(sv, s, m->h.seq, "CAMERA", &c, &s->cam) < 0) return;
    s->have_camera = 1;
    s->camera_seq = m->h.seq;
    stream_update(sv, s, 0);
}

static void send_ok(srv *sv, sess *s, uint32_t seq)
{
    proto_buf b = {.version = s->version};
    if (proto_enc_empty(&b, PROTO_MSG_OK, seq) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
}

static void on_params(srv *sv, sess *s, const proto_msg *m)
{
    proto_error pe = {0};
    int rc = proto_parse_params(m->payload, m->len, &s->params, NULL, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    send_ok(sv, s, m->h.seq);
    stream_update(sv, s, 0);
}

static void on_render(srv *sv, sess *s, const proto_msg *m)
{
    proto_error pe;
    int prc = proto_parse_empty(m->h.type, m->len, &pe);
    if (prc < 0) { send_error(sv, s, m->h.seq, -prc, pe.msg); return; }
    if (!need_cloud(sv, s, m->h.seq, "RENDER")) return;
    if (sv->stopping) {
        send_error(sv, s, m->h.seq, PROTO_E_SHUTTING_DOWN, "the server is stopping");
        return;
    }
    rt_request rq;
    make_request(sv, s, &rq, m->h.seq);
    if (!frame_fits(sv, s, &rq, m->h.seq)) return;
    if (s->frames_queued >= RT_QUEUE_MAX + RT_MAX_OUTSTANDING ||
        rt_submit_queue(sv->rt, s->id, &rq) != 0) {
        char t[128];
        snprintf(t, sizeof t, "too many frames in flight: at most %d RENDER requests may wait",
                 RT_QUEUE_MAX);
        send_error(sv, s, m->h.seq, PROTO_E_BUSY, t);
        return;
    }
    if (sess_push_frame_slot(s, m->h.seq) != 0) sess_close(s, "out of memory");
}

static void on_stream(srv *sv, sess *s, const proto_msg *m)
{
    proto_stream st;
    proto_error pe = {0};
    int rc = proto_parse_stream(m->payload, m->len, &st, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    if (st.on && !need_cloud(sv, s, m->h.seq, "STREAM")) return;
    s->stream = st.on;
    s->max_fps = st.max_fps;
    if (!st.on) ev_timer_stop(sv->loop, &s->fps_timer);
    send_ok(sv, s, m->h.seq);
    stream_update(sv, s, 0); /* the current view, so a stream starts with a frame */
}

static void on_ping(srv *sv, sess *s, const proto_msg *m)
{
    proto_ping p;
    proto_error pe = {0};
    int rc = proto_parse_ping(m->payload, m->len, &p, &pe);
    if (rc < 0) { send_error(sv, s, m->h.seq, -rc, pe.msg); return; }
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    proto_pong pg = {p.token, (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u};
    proto_buf b = {.version = s->version};
    if (proto_enc_pong(&b, m->h.seq, &pg) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
}

void srv_handle(void *owner, sess *s, const proto_msg *m)
{
    srv *sv = owner;
    switch (m->h.type) {
    case PROTO_MSG_HELLO: on_hello(sv, s, m); break;
    case PROTO_MSG_LIST: on_list(sv, s, m); break;
    case PROTO_MSG_OPEN: on_open(sv, s, m); break;
    case PROTO_MSG_CAMERA: on_camera(sv, s, m); break;
    case PROTO_MSG_PARAMS: on_params(sv, s, m); break;
    case PROTO_MSG_RENDER: on_render(sv, s, m); break;
    case PROTO_MSG_STREAM: on_stream(sv, s, m); break;
    case PROTO_MSG_PREFETCH: on_prefetch(sv, s, m); break;
    case PROTO_MSG_PING: on_ping(sv, s, m); break;
    case PROTO_MSG_BYE: {
        proto_error pe;
        int prc = proto_parse_empty(m->h.type, m->len, &pe);
        if (prc < 0) { send_error(sv, s, m->h.seq, -prc, pe.msg); break; }
        s->close_after = 1;
        snprintf(s->close_reason, sizeof s->close_reason, "BYE");
        break;
    }
    default:
        send_error(sv, s, m->h.seq, PROTO_E_UNKNOWN_TYPE, "unexpected message type");
        break;
    }
}

void srv_decode_error(void *owner, sess *s, int code, const char *text)
{
    send_error(owner, s, 0, code, text);
}

/* ---- worker events ---- */

/* waiting: whether waiter w (session s) of cloud c (index idx) still waits for it: its OPEN
 * is unanswered, or answered provisionally and s still has that cloud open. */
static int waiting(const srv_cloud *c, const srv_waiter *w, const sess *s, int idx)
{
    (void)c;
    return w->shown ? s->cloud == idx && s->opening < 0 : s->opening == idx;
}

static void on_progress_ev(srv *sv, const rt_event *ev)
{
    srv_cloud *c = cloud_by_key(sv, ev->job);
    if (!c) return;
    proto_progress p = {0};
    p.phase = (uint8_t)(ev->phase >= 0 && ev->phase < PROTO_PHASE_COUNT ? ev->phase
                                                                         : PROTO_PHASE_LOAD);
    p.fraction = (float)(ev->fraction < 0 ? 0 : ev->fraction > 1 ? 1 : ev->fraction);
    snprintf(p.text, sizeof p.text, "%s %d%%", proto_phase_name(p.phase),
             (int)(p.fraction * 100 + 0.5f));
    for (int i = 0; i < c->nwait; i++) {
        sess *s = srv_lookup(sv, c->waiters[i].sess);
        if (!s || !waiting(c, &c->waiters[i], s, (int)(c - sv->clouds))) continue;
        proto_buf b = {.version = s->version};
        if (proto_enc_progress(&b, c->waiters[i].seq, &p) == 0) sess_send(s, &b);
        else proto_buf_free(&b);
        sess_kick(s);
    }
}

/* client_message: msg with every occurrence of the cloud's real path replaced by its name, so
 * an error sent to a client names the cloud it opened, never where the server keeps its files
 * (the full message is logged). */
static void client_message(const srv_cloud *c, const char *msg, char *out, size_t len)
{
    size_t pl = strlen(c->path), o = 0;
    while (*msg && o + 1 < len) {
        if (pl && !strncmp(msg, c->path, pl)) {
            o += (size_t)snprintf(out + o, len - o, "%s", c->name);
            if (o >= len) o = len - 1;
            msg += pl;
        } else {
            out[o++] = *msg++;
        }
    }
    out[o] = 0;
}

static void on_cloud_done(srv *sv, const rt_event *ev)
{
    srv_cloud *c = cloud_by_key(sv, ev->job);
    if (!c) return;
    int idx = (int)(c - sv->clouds);
    int ok = ev->kind == RT_EV_CLOUD_READY;
    c->prov_id = 0; /* released by the render thread at the swap */
    if (ok) {
        c->state = SRV_CLOUD_READY;
        c->cloud_id = ev->cloud_id;
        c->info = ev->info;
        srv_log(sv, NULL, "cloud %s ready: %llu points, %s in %.2f s", c->name,
                (unsigned long long)c->info.summary.points, c->info.cache_hit ? "from the cache" : "prepared",
                (double)(ev_now_ms() - c->t_start_ms) / 1000.0);
    } else {
        char clean[sizeof ev->err.msg * 4];
        srv_clean_text(ev->err.msg, clean, sizeof clean); /* it may quote the file's bytes */
        srv_log(sv, NULL, "cloud %s failed: %s", c->name, clean);
    }
    /* Detach the waiters first: a waiter's buffered requests may OPEN this cloud again. */
    srv_waiter *w = c->waiters;
    int nw = c->nwait;
    c->waiters = NULL;
    c->nwait = c->capwait = 0;
    if (!ok) c->state = SRV_CLOUD_FREE; /* a later OPEN retries */
    for (int i = 0; i < nw; i++) {
        sess *s = srv_lookup(sv, w[i].sess);
        if (!s || !waiting(&sv->clouds[idx], &w[i], s, idx)) continue;
        if (w[i].shown) { /* the swap: its requests from now on draw the full cloud */
            if (ok) {
                s->cloud_id = sv->clouds[idx].cloud_id;
                send_info(sv, s, &sv->clouds[idx], w[i].seq);
                stream_update(sv, s, 0); /* a streaming client gets a frame of the full cloud */
            } else {
                s->cloud = -1;
                s->cloud_id = 0;
                s->have_camera = 0;
                char msg[sizeof ev->err.msg + 256];
                client_message(&sv->clouds[idx], ev->err.msg, msg, sizeof msg);
                send_error(sv, s, w[i].seq, PROTO_E_LOAD_FAILED, msg);
            }
            sess_kick(s);
            continue;
        }
        s->opening = -1;
        s->paused = 0;
        if (ok) {
            /* sv->clouds may have moved (an earlier waiter's OPEN of another cloud). */
            const srv_cloud *cc = &sv->clouds[idx];
            s->cloud = idx;
            s->cloud_id = cc->cloud_id;
            send_info(sv, s, cc, w[i].seq);
        } else {
            char msg[sizeof ev->err.msg + 256];
            client_message(&sv->clouds[idx], ev->err.msg, msg, sizeof msg);
            send_error(sv, s, w[i].seq, PROTO_E_LOAD_FAILED, msg);
        }
        sess_input(s); /* requests that waited behind the OPEN */
    }
    free(w);
}

/* on_cloud_provisional: a loading cloud's provisional form is drawable: the waiters that
 * asked for it (parameter provisional) get its INFO and may render; they stay waiters for the
 * PROGRESS and the full INFO. */
static void on_cloud_provisional(srv *sv, const rt_event *ev)
{
    srv_cloud *c = cloud_by_key(sv, ev->job);
    if (!c) return;
    int idx = (int)(c - sv->clouds);
    c->prov_id = ev->cloud_id;
    c->info = ev->info;
    srv_log(sv, NULL, "cloud %s: provisional, %llu points, in %.2f s", c->name,
            (unsigned long long)c->info.summary.points,
            (double)(ev_now_ms() - c->t_start_ms) / 1000.0);
    int nw = c->nwait;
    for (int i = 0; i < nw; i++) {
        c = &sv->clouds[idx]; /* an earlier waiter's requests may have grown the table */
        srv_waiter *w = &c->waiters[i];
        sess *s = srv_lookup(sv, w->sess);
        if (!s || w->shown || s->opening != idx || !s->params.provisional) continue;
        w->shown = 1;
        s->opening = -1;
        s->paused = 0;
        s->cloud = idx;
        s->cloud_id = c->prov_id;
        send_info(sv, s, c, w->seq);
        sess_input(s); /* requests that waited behind the OPEN */
    }
}

/* cloud_forget: s's cloud failed for good (its cache file changed under the daemon: the render
 * thread released it): every session that has it open must OPEN again, and that OPEN loads it
 * anew (rebuilding the cache). */
static void cloud_forget(srv *sv, const sess *s)
{
    if (s->cloud < 0 || s->cloud >= sv->nclouds) return;
    srv_cloud *c = &sv->clouds[s->cloud];
    if (c->state != SRV_CLOUD_READY || c->cloud_id != s->cloud_id) return;
    int idx = s->cloud;
    srv_log(sv, NULL, "cloud %s dropped: its cache changed; the next OPEN loads it anew", c->name);
    for (int i = 0; i < sv->nslots; i++) {
        sess *o = sv->sessions[i];
        if (!o || o->cloud != idx) continue;
        o->cloud = -1;
        o->cloud_id = 0;
        o->have_camera = 0;
    }
    c->state = SRV_CLOUD_FREE;
}

static void on_frame_ev(srv *sv, rt_event *ev)
{
    sess *s = srv_lookup(sv, ev->meta.client);
    if (!s) return; /* its slot was already cleared by rt_client_close */
    if (ev->kind == RT_EV_FRAME_FAILED && ev->err.code == SD_ESTALE) cloud_forget(sv, s);
    if (ev->kind == RT_EV_FRAME_FAILED) {
        if (ev->meta.stream) {
            char clean[sizeof ev->err.msg * 4];
            srv_clean_text(ev->err.msg, clean, sizeof clean);
            srv_log(sv, s, "streamed frame failed: %s", clean);
            return;
        }
        /* The placeholder becomes the ERROR answer, in order. */
        for (sess_item *it = s->head; it; it = it->next) {
            if (it->is_frame && !it->filled) {
                proto_buf b = {.version = s->version};
                char text[PROTO_MAX_ERRTEXT + 1];
                srv_clean_text(ev->err.msg, text, sizeof text);
                if (proto_enc_error(&b, it->seq, PROTO_E_RENDER_FAILED, text) == 0) {
                    it->data = b.data;
                    it->len = b.len;
                    it->filled = 1;
                    it->is_frame = 0;
                    s->out_bytes += b.len;
                    s->frames_queued--;
                } else {
                    proto_buf_free(&b);
                }
                break;
            }
        }
        srv_log(sv, s, "error RENDER_FAILED (seq %u): %s", ev->meta.req_seq, ev->err.msg);
        sess_kick(s);
        return;
    }
    if (ev->meta.stream) {
        if (sess_set_stream_frame(s, ev->msg, ev->msglen)) rt_frame_released(sv->rt, s->id);
    } else if (sess_fill_frame(s, ev->msg, ev->msglen) != 0) {
        rt_frame_released(sv->rt, s->id);
        return; /* no placeholder (cannot happen): ev keeps msg, freed by the caller */
    }
    ev->msg = NULL;
    sess_kick(s);
}

void srv_on_worker_events(srv *sv)
{
    rt_event *ev = rt_take_events(sv->rt);
    while (ev) {
        rt_event *next = ev->next;
        switch (ev->kind) {
        case RT_EV_FRAME:
        case RT_EV_FRAME_FAILED: on_frame_ev(sv, ev); break;
        case RT_EV_PROGRESS: on_progress_ev(sv, ev); break;
        case RT_EV_CLOUD_READY:
        case RT_EV_CLOUD_FAILED: on_cloud_done(sv, ev); break;
        case RT_EV_CLOUD_PROVISIONAL: on_cloud_provisional(sv, ev); break;
        }
        rt_event_free(ev);
        ev = next;
    }
}
