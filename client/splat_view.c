/* splat_view.c — `splat view` (the binary splat-view): an interactive SDL2 window on a cloud
 * that a splatd daemon renders, through libsplatclient.
 *
 * Two threads. The network thread owns the client handle: it connects (and reconnects with
 * back-off), opens the cloud, turns streaming on, sends the camera and the parameters the
 * window asks for, receives the streamed frames (JPEG, decoded to RGBA by the library) and
 * hands the latest one over; it waits in poll() on the socket and on an eventfd that the
 * window thread writes when it wants something, so a camera change goes out at once even
 * while a frame is on its way. The window thread (main) handles SDL input, keeps the orbit
 * camera, shows the latest frame through a streaming texture and writes a heads-up line into
 * the window title; it never touches the socket, so input stays responsive whatever the
 * network does.
 *
 * Progressive quality: while the user drags (or zooms, or resizes) the window asks for half
 * the resolution, JPEG quality 50 and a point budget; 150 ms after the last input it asks for
 * the full resolution, quality 95 and the full budget. `--script FILE` replays input events
 * instead of waiting for a user (tests and benchmarks); `--verbose` logs every frame on
 * stdout. At quit the final camera is printed as `splat render` options. */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#include <SDL.h>

#include "campath.h"
#include "cli.h"
#include "params.h"
#include "spc_internal.h"
#include "splat_client.h"

enum { EXIT_FAIL = 1, EXIT_USAGE = 2 };

#define SETTLE_S 0.150       /* full quality this long after the last input */
#define DRAG_QUALITY 50      /* JPEG quality while interacting */
#define REST_QUALITY 95      /* JPEG quality at rest */
#define MAX_SAVES 8

static const char usage_text[] =
    "usage: splat view NAME [--host H] [--port P] [--token-file F] [--tls] [--tls-ca F]\n"
    "                  [--tls-name N] [--size WxH]\n"
    "                  [--set key=value ...] [--script FILE] [--verbose] [--drag-budget N]\n"
    "                  [--no-progressive] [--timeout S] [--keepalive S]\n"
    "\n"
    "Opens cloud NAME on a splatd server and shows it in a window; the server streams a new\n"
    "frame whenever the camera or a parameter changes.\n"
    "\n"
    "  --size WxH         window size (default 1280x720)\n"
    "  --set key=value    a parameter at start (repeatable; `splat render --help` lists them)\n"
    "  --script FILE      replay input events from FILE instead of waiting for a user:\n"
    "                     wait MS | drag DX DY | pan DX DY | wheel N | key NAME (SDL key name)\n"
    "                     | resize W H | save FILE | quit; '#' starts a comment\n"
    "  --verbose          one line per frame on stdout (size, pipeline, times, latency)\n"
    "  --drag-budget N    point budget while dragging (default 300000; 0: every point)\n"
    "  --no-progressive   always full resolution and quality (for measurements)\n"
    "  --timeout S        seconds one request may take (default 30)\n"
    "  --keepalive S      send PING after S seconds with nothing sent, so a resting viewer\n"
    "                     outlives the server's --idle-timeout (default 60; 0: never)\n"
    "\n";

static const char keys_text[] =
    "mouse: left-drag orbits around the cloud's centre, right-drag pans, wheel zooms\n"
    "keys:  1 points, 2 splat, 3.. further pipelines; U/J lambda up/down, I/K t up/down,\n"
    "       O/L l_m up/down; E toggles Eye-Dome Lighting; R resets the camera;\n"
    "       S saves the view as PNG (splat-view-N.png); H this help; Esc or Q quits\n";

/* ---- small helpers -------------------------------------------------------------------------- */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void v_sub(const double a[3], const double b[3], double o[3])
{
    for (int i = 0; i < 3; i++) o[i] = a[i] - b[i];
}

static double v_dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void v_cross(const double a[3], const double b[3], double o[3])
{
    double r[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                   a[0] * b[1] - a[1] * b[0]};
    memcpy(o, r, sizeof r);
}

static double v_norm(double a[3])
{
    double l = sqrt(v_dot(a, a));
    if (l > 0)
        for (int i = 0; i < 3; i++) a[i] /= l;
    return l;
}

/* v_rotate: v rotated by angle (radians) about the unit axis k (Rodrigues). */
static void v_rotate(double v[3], const double k[3], double angle)
{
    double c = cos(angle), s = sin(angle), kxv[3];
    v_cross(k, v, kxv);
    double kv = v_dot(k, v);
    for (int i = 0; i < 3; i++) v[i] = v[i] * c + kxv[i] * s + k[i] * kv * (1 - c);
}

/* ---- the orbit camera ----------------------------------------------------------------------- */

typedef struct orbit {
    double target[3];  /* the point orbited (the cloud's centre until the user pans) */
    double offset[3];  /* eye - target */
    double up[3];      /* the world's up axis (unit) */
    float fov;
} orbit;

static void orbit_from_camera(orbit *o, const spc_camera *c)
{
    memcpy(o->target, c->target, sizeof o->target);
    v_sub(c->eye, c->target, o->offset);
    memcpy(o->up, c->up, sizeof o->up);
    v_norm(o->up);
    o->fov = c->fov_deg;
}

static void orbit_camera(const orbit *o, uint32_t w, uint32_t h, spc_camera *c)
{
    memset(c, 0, sizeof *c);
    for (int i = 0; i < 3; i++) {
        c->target[i] = o->target[i];
        c->eye[i] = o->target[i] + o->offset[i];
        c->up[i] = o->up[i];
    }
    c->fov_deg = o->fov;
    c->width = w ? w : 1;
    c->height = h ? h : 1;
}

/* orbit_drag: turns the eye around the target, dx pixels about the up axis and dy pixels
 * about the camera's right axis, keeping at least 2 degrees from the up axis. */
static void orbit_drag(orbit *o, double dx, double dy)
{
    const double k = 0.008; /* radians per pixel */
    v_rotate(o->offset, o->up, -dx * k);
    double dir[3] = {-o->offset[0], -o->offset[1], -o->offset[2]}, right[3];
    v_cross(dir, o->up, right);
    if (v_norm(right) == 0) return;
    double trial[3] = {o->offset[0], o->offset[1], o->offset[2]};
    v_rotate(trial, right, -dy * k);
    double t[3] = {trial[0], trial[1], trial[2]};
    v_norm(t);
    double cosang = v_dot(t, o->up);
    if (fabs(cosang) < cos(2.0 * M_PI / 180.0)) memcpy(o->offset, trial, sizeof trial);
}

/* orbit_pan: moves target and eye along the view plane by dx, dy pixels of a frame h high. */
static void orbit_pan(orbit *o, double dx, double dy, uint32_t h)
{
    double dir[3] = {-o->offset[0], -o->offset[1], -o->offset[2]}, right[3], camup[3];
    double dist = v_norm(dir);
    v_cross(dir, o->up, right);
    if (v_norm(right) == 0) return;
    v_cross(right, dir, camup);
    double px = 2.0 * dist * tan(o->fov * M_PI / 360.0) / (h ? h : 1);
    for (int i = 0; i < 3; i++) o->target[i] += (-dx * right[i] + dy * camup[i]) * px;
}

/* orbit_zoom: n wheel steps towards the target (negative: away). */
static void orbit_zoom(orbit *o, double n)
{
    double f = pow(0.9, n);
    for (int i = 0; i < 3; i++) o->offset[i] *= f;
}

/* ---- the state shared by the two threads ---------------------------------------------------- */

typedef struct save_req {
    char path[1024];
    spc_camera cam;              /* the view when `save` was asked for: its camera */
    sp_params want;              /* and its parameters (a key right after must not change it) */
} save_req;

typedef struct shared {
    pthread_mutex_t mu;
    int wake_fd;                 /* eventfd: the window wants something */
    /* options */
    spc_options opt;
    const char *name;
    int verbose;
    int keepalive_s;             /* PING after this long with nothing sent; 0: never */
    /* window -> network */
    int quit;
    spc_camera cam;              /* the camera to show */
    uint64_t cam_gen;            /* +1 per change */
    double cam_t;                /* when the input that made it happened; < 0: no input (the
                                  * first camera, a reconnection, the full frame after a drag) */
    int cam_first;               /* send the camera before the parameters (a drag began) */
    sp_params want;              /* the parameters to show */
    uint64_t want_gen;
    save_req saves[MAX_SAVES];
    int nsaves;
    /* network -> window */
    int connected, ever_connected, fatal;
    char status[2048];           /* a disconnection, an error, a save; "" when none */
    spc_info info;
    uint64_t info_gen;
    uint8_t *rgba;               /* the latest frame */
    size_t rgba_cap;
    uint32_t fw, fh;
    char fpipe[32];
    uint32_t fcamseq;
    double frender_ms, fencode_ms, flatency_ms, ft;
    size_t fbytes;
    uint64_t fpoints;
    uint64_t frame_gen;
    uint8_t unavail[SP_PARAM_COUNT];     /* the server refused the parameter */
    uint8_t pipe_unavail[SP_PIPE_COUNT]; /* the server refused the pipeline */
    int saves_done;
    /* latency: cameras sent and the time of the input behind each (< 0: none); a sample is the
     * time from a camera input to the first frame drawn from that camera or a later one */
    struct { uint32_t seq; double t; } sent[64];
    int nsent;
    double lat[4096];
    int nlat;
    double lat_last_ms;          /* the latest sample, for the title */
    uint32_t server_event;       /* SDL user event: a frame or a status arrived */
} shared;

static void wake(shared *s)
{
    uint64_t one = 1;
    ssize_t n = write(s->wake_fd, &one, sizeof one);
    (void)n;
}

static void push_event(shared *s)
{
    SDL_Event ev;
    memset(&ev, 0, sizeof ev);
    ev.type = s->server_event;
    SDL_PushEvent(&ev);
}

static void set_status(shared *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void set_status(shared *s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    pthread_mutex_lock(&s->mu);
    vsnprintf(s->status, sizeof s->status, fmt, ap);
    pthread_mutex_unlock(&s->mu);
    va_end(ap);
    push_event(s);
}

/* ---- the network thread --------------------------------------------------------------------- */

static int is_conn_error(int code)
{
    return code == SPC_E_IO || code == SPC_E_TIMEOUT || code == SPC_E_CLOSED ||
           spc_error_fatal(code);
}

/* apply_params: sends the parameters of want that differ from *applied, all at once; when the
 * server refuses them (an unknown parameter or value, e.g. a pipeline it lacks), sends them one
 * by one and marks what it refused unavailable, putting want back to the value in force.
 * Returns 0 or a connection error code. */
static int apply_params(shared *s, spc_client *c, sp_params *applied, const sp_params *want,
                        const char *extra)
{
    char kvbuf[SP_PARAM_COUNT + 1][96];
    const char *kv[SP_PARAM_COUNT + 1];
    int ids[SP_PARAM_COUNT + 1];
    int n = 0;
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        char a[64], b[64];
        sp_param_get_text(applied, i, a, sizeof a);
        sp_param_get_text(want, i, b, sizeof b);
        if (!strcmp(a, b)) continue;
        snprintf(kvbuf[n], sizeof kvbuf[n], "%s=%s", sp_param_table[i].name, b);
        kv[n] = kvbuf[n];
        ids[n++] = i;
    }
    if (extra) {
        snprintf(kvbuf[n], sizeof kvbuf[n], "%s", extra);
        kv[n] = kvbuf[n];
        ids[n++] = -1;
    }
    if (!n) return 0;
    int rc = spc_set_params(c, kv, n);
    if (rc == 0) {
        for (int j = 0; j < n; j++) sp_param_set_kv(applied, kv[j], NULL, 0);
        return 0;
    }
    if (is_conn_error(rc)) return rc;
    for (int j = 0; j < n; j++) {
        rc = spc_set_param(c, kv[j]);
        if (rc == 0) {
            sp_param_set_kv(applied, kv[j], NULL, 0);
            continue;
        }
        if (is_conn_error(rc)) return rc;
        int id = ids[j];
        char old[64] = "";
        if (id >= 0) sp_param_get_text(applied, id, old, sizeof old);
        pthread_mutex_lock(&s->mu);
        if (id == SP_PIPELINE) {
            int v = s->want.pipeline;
            if (v >= 0 && v < SP_PIPE_COUNT) s->pipe_unavail[v] = 1;
        } else if (id >= 0 && rc == SPC_E_BAD_PARAM_NAME) {
            s->unavail[id] = 1;
        }
        if (id >= 0) sp_param_set_text(&s->want, sp_param_table[id].name, old, NULL, 0);
        snprintf(s->status, sizeof s->status, "%s: %s", kv[j], spc_errmsg(c));
        pthread_mutex_unlock(&s->mu);
        push_event(s);
    }
    return 0;
}

/* publish_frame: hands frame f over to the window and records its latency. */
static void publish_frame(shared *s, const spc_frame *f)
{
    double t = now_s();
    size_t need = (size_t)f->width * f->height * 4;
    pthread_mutex_lock(&s->mu);
    if (need > s->rgba_cap) {
        uint8_t *p = realloc(s->rgba, need);
        if (!p) {
            pthread_mutex_unlock(&s->mu);
            return;
        }
        s->rgba = p;
        s->rgba_cap = need;
    }
    memcpy(s->rgba, f->rgba, need);
    s->fw = f->width;
    s->fh = f->height;
    snprintf(s->fpipe, sizeof s->fpipe, "%s", f->pipeline);
    s->fcamseq = f->camera_seq;
    s->frender_ms = f->render_us / 1e3;
    s->fencode_ms = f->encode_us / 1e3;
    s->fbytes = f->data_len;
    s->fpoints = f->points_drawn;
    s->ft = t;
    /* The input behind every camera up to this one is now visible: its latency is the time
     * from that input to this frame. Cameras no input made (the first one, a reconnection's,
     * the full frame after a drag) have none; a frame that shows no new input has none. */
    double lat = -1;
    int k = 0;
    for (int j = 0; j < s->nsent; j++) {
        if (s->sent[j].seq <= f->camera_seq) {
            if (s->sent[j].t < 0) continue;
            lat = (t - s->sent[j].t) * 1e3;
            if (s->nlat < (int)(sizeof s->lat / sizeof s->lat[0])) s->lat[s->nlat++] = lat;
        } else {
            s->sent[k++] = s->sent[j];
        }
    }
    s->nsent = k;
    s->flatency_ms = lat;
    if (lat >= 0) s->lat_last_ms = lat;
    s->frame_gen++;
    pthread_mutex_unlock(&s->mu);
    push_event(s);
}

/* do_save: renders the requested camera as PNG with the parameters at rest and writes it;
 * streaming is off meanwhile. Returns 0 or a connection error code. */
static int do_save(shared *s, spc_client *c, sp_params *applied, const save_req *r,
                   int streaming)
{
    int rc = streaming ? spc_stream(c, 0, 0) : 0;
    if (rc < 0) return rc;
    sp_params want = r->want; /* the view as it was when `save` was asked for */
    want.quality = REST_QUALITY;
    if ((rc = apply_params(s, c, applied, &want, "format=png")) < 0) return rc;
    uint32_t seq;
    if ((rc = spc_send_render(c, &r->cam, &seq)) < 0) return rc;
    spc_frame f;
    char err[1400] = "";
    for (;;) {
        rc = spc_recv_frame(c, &f, 0);
        if (rc < 0) {
            if (is_conn_error(rc)) return rc;
            snprintf(err, sizeof err, "%s", spc_errmsg(c));
            break;
        }
        if (f.seq == seq) break;
    }
    if (!err[0] && cp_mkdirs(r->path, err, sizeof err) == 0 &&
        cp_write_file(r->path, f.data, f.data_len, err, sizeof err) == 0)
        snprintf(err, sizeof err, "saved %s (%ux%u png)", r->path, f.width, f.height);
    else if (!err[0])
        snprintf(err, sizeof err, "saving %s failed", r->path);
    printf("%s\n", err);
    fflush(stdout);
    if ((rc = apply_params(s, c, applied, &want, "format=jpeg")) < 0) return rc;
    if (streaming && (rc = spc_stream(c, 1, 0)) < 0) return rc;
    pthread_mutex_lock(&s->mu);
    snprintf(s->status, sizeof s->status, "%s", err);
    s->saves_done++;
    pthread_mutex_unlock(&s->mu);
    push_event(s);
    return 0;
}

static void on_progress(void *user, const char *phase, float fraction, const char *text)
{
    shared *s = user;
    if (text && text[0]) set_status(s, "preparing %s: %s", s->name, text);
    else set_status(s, "preparing %s: %s %.0f%%", s->name, phase, 100.0 * fraction);
}

/* session: one connection's life, until the window quits (returns 0) or the connection fails
 * (returns the code; the message is in err). */
static int session(shared *s, spc_client *c, char *err, size_t errlen)
{
    spc_info info;
    /* A COPC file still preparing shows its top levels at once (a server without the
     * parameter refuses it: then the full cloud is waited for, as before). */
    int rc = spc_set_param(c, "provisional=1");
    if (rc < 0 && is_conn_error(rc)) goto fail;
    rc = spc_open(c, s->name, &info, on_progress, s);
    if (rc < 0) goto fail;
    int provisional = spc_open_provisional(c);
    pthread_mutex_lock(&s->mu);
    s->info = info;
    s->info_gen++;
    s->connected = 1;
    s->ever_connected = 1;
    s->status[0] = 0;
    if (provisional)
        snprintf(s->status, sizeof s->status, "first image: %llu points of %s's top levels, "
                 "drawn with points; the full cloud is still preparing",
                 (unsigned long long)info.points, s->name);
    pthread_mutex_unlock(&s->mu);
    push_event(s);

    sp_params applied;
    sp_params_defaults(&applied);
    if ((rc = apply_params(s, c, &applied, &applied, "format=jpeg")) < 0) goto fail;
    /* Streaming starts after the first camera: turned on before, it would render the server's
     * default camera first. */
    int streaming = 0;
    uint64_t cam_sent = 0, want_sent = 0;
    double last_sent = now_s(); /* the last request of ours: the server's idle clock */
    for (;;) {
        pthread_mutex_lock(&s->mu);
        int quit = s->quit, nsaves = s->nsaves;
        save_req save;
        if (nsaves) {
            save = s->saves[0];
            memmove(&s->saves[0], &s->saves[1], (size_t)(nsaves - 1) * sizeof s->saves[0]);
            s->nsaves--;
        }
        sp_params want = s->want;
        uint64_t want_gen = s->want_gen, cam_gen = s->cam_gen;
        spc_camera cam = s->cam;
        double cam_t = s->cam_t;
        int cam_first = s->cam_first;
        pthread_mutex_unlock(&s->mu);
        if (nsaves) {
            if ((rc = do_save(s, c, &applied, &save, streaming)) < 0) goto fail;
            cam_sent = 0; /* the save moved the server's camera */
            continue;
        }
        if (quit) return 0;
        /* Entering a drag, the camera goes first: the server renders the moved view at once
         * (at half size), and the lower quality follows. Settling, the full quality goes
         * first and the full-size camera after it, so no full-size frame renders with the
         * drag's quality. */
        for (int step = 0; step < 2; step++) {
            if ((step == 0) != cam_first) {
                if (want_gen != want_sent) {
                    if ((rc = apply_params(s, c, &applied, &want, NULL)) < 0) goto fail;
                    want_sent = want_gen;
                    last_sent = now_s();
                }
            } else if (cam_gen && cam_gen != cam_sent) {
                uint32_t seq = 0;
                rc = spc_set_camera(c, &cam, &seq);
                if (rc < 0 && is_conn_error(rc)) goto fail;
                last_sent = now_s();
                if (rc < 0) set_status(s, "camera: %s", spc_errmsg(c));
                cam_sent = cam_gen;
                pthread_mutex_lock(&s->mu);
                if (s->nsent == (int)(sizeof s->sent / sizeof s->sent[0])) {
                    memmove(&s->sent[0], &s->sent[1], (size_t)(s->nsent - 1) * sizeof s->sent[0]);
                    s->nsent--;
                }
                s->sent[s->nsent].seq = seq;
                s->sent[s->nsent].t = cam_t;
                s->nsent++;
                pthread_mutex_unlock(&s->mu);
                if (!streaming) {
                    if ((rc = spc_stream(c, 1, 0)) < 0) goto fail;
                    streaming = 1;
                }
            }
        }
        /* A viewer at rest sends nothing, and the server closes clients silent for its
         * --idle-timeout (300 s by default): a PING now and then keeps the connection. Frames
         * streamed meanwhile are skipped by the wait; the camera is still, so none is due. */
        if (s->keepalive_s > 0 && now_s() - last_sent >= s->keepalive_s) {
            if ((rc = spc_ping(c, NULL)) < 0) goto fail;
            last_sent = now_s();
            if (s->verbose) {
                printf("ping\n");
                fflush(stdout);
            }
        }
        /* Wait for a frame or a wish of the window; bytes the library holds already count as
         * readable (the socket alone would not say so). */
        int buffered = spc__buffered(c);
        struct pollfd p[2] = {{spc_fd(c), POLLIN, 0}, {s->wake_fd, POLLIN, 0}};
        if (!buffered && poll(p, 2, 200) < 0 && errno != EINTR) {
            rc = SPC_E_IO;
            snprintf(err, errlen, "poll: %s", strerror(errno));
            return rc;
        }
        if (p[1].revents & POLLIN) {
            uint64_t v;
            ssize_t n = read(s->wake_fd, &v, sizeof v);
            (void)n;
        }
        if (buffered || (p[0].revents & (POLLIN | POLLHUP | POLLERR))) {
            spc_frame f;
            rc = spc_recv_frame(c, &f, 1);
            if (rc < 0 && is_conn_error(rc)) goto fail;
            if (rc < 0) set_status(s, "%s", spc_errmsg(c));
            else if (f.rgba) publish_frame(s, &f);
            if (provisional && !spc_open_provisional(c)) { /* the full cloud replaced it */
                provisional = 0;
                set_status(s, "%s", rc < 0 ? spc_errmsg(c) : "");
            }
        }
    }
fail:
    snprintf(err, errlen, "%s", spc_errmsg(c));
    return rc;
}

static void *net_main(void *arg)
{
    shared *s = arg;
    double backoff = 0.25;
    for (;;) {
        pthread_mutex_lock(&s->mu);
        int quit = s->quit;
        pthread_mutex_unlock(&s->mu);
        if (quit) break;
        spc_client *c;
        char err[700];
        int rc = spc_connect(&s->opt, &c, err, sizeof err);
        if (rc == 0) {
            rc = session(s, c, err, sizeof err);
            spc_close(c);
            if (rc == 0) break;
        }
        pthread_mutex_lock(&s->mu);
        int ever = s->ever_connected, was = s->connected;
        s->connected = 0;
        /* A server that refuses the cloud or the token will refuse it again: give up at
         * once. A connection that fails is retried, except before the first success. */
        if (!ever || !is_conn_error(rc)) {
            s->fatal = 1;
            snprintf(s->status, sizeof s->status, "%s", err);
            pthread_mutex_unlock(&s->mu);
            push_event(s);
            break;
        }
        if (was) backoff = 0.25;
        snprintf(s->status, sizeof s->status, "disconnected (%s); reconnecting in %.1f s", err,
                 backoff);
        pthread_mutex_unlock(&s->mu);
        push_event(s);
        struct pollfd p = {s->wake_fd, POLLIN, 0};
        double until = now_s() + backoff;
        while (now_s() < until) {
            if (poll(&p, 1, (int)((until - now_s()) * 1e3) + 1) > 0) {
                uint64_t v;
                ssize_t n = read(s->wake_fd, &v, sizeof v);
                (void)n;
                pthread_mutex_lock(&s->mu);
                quit = s->quit;
                pthread_mutex_unlock(&s->mu);
                if (quit) break;
            }
        }
        backoff = backoff * 2 > 5 ? 5 : backoff * 2;
    }
    return NULL;
}

/* ---- the script ----------------------------------------------------------------------------- */

enum { EV_WAIT, EV_DRAG, EV_PAN, EV_WHEEL, EV_KEY, EV_RESIZE, EV_SAVE, EV_QUIT };

typedef struct script_ev {
    int kind, line;
    double a, b;
    SDL_Keycode key;
    char *text;
} script_ev;

/* script_load: parses FILE; on an error prints "FILE:LINE: what" and returns -1. */
static int script_load(const char *path, script_ev **out, int *nout)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "splat view: %s: %s\n", path, strerror(errno));
        return -1;
    }
    script_ev *ev = NULL;
    int n = 0, cap = 0, line = 0, rc = 0;
    char buf[1200];
    while (fgets(buf, sizeof buf, f)) {
        line++;
        char *hash = strchr(buf, '#');
        if (hash) *hash = 0;
        char cmd[32] = "", arg1[1100] = "", arg2[64] = "", extra[8] = "";
        int k = sscanf(buf, "%31s %1099s %63s %7s", cmd, arg1, arg2, extra);
        if (k <= 0) continue;
        if (n == cap) {
            cap = cap ? cap * 2 : 64;
            script_ev *p = realloc(ev, (size_t)cap * sizeof *ev);
            if (!p) {
                rc = -1;
                break;
            }
            ev = p;
        }
        script_ev e = {.line = line};
        const char *why = NULL;
        int want_args = 0;
        char *end;
        if (!strcmp(cmd, "wait")) e.kind = EV_WAIT, want_args = 1;
        else if (!strcmp(cmd, "drag")) e.kind = EV_DRAG, want_args = 2;
        else if (!strcmp(cmd, "pan")) e.kind = EV_PAN, want_args = 2;
        else if (!strcmp(cmd, "wheel")) e.kind = EV_WHEEL, want_args = 1;
        else if (!strcmp(cmd, "key")) e.kind = EV_KEY, want_args = 1;
        else if (!strcmp(cmd, "resize")) e.kind = EV_RESIZE, want_args = 2;
        else if (!strcmp(cmd, "save")) e.kind = EV_SAVE, want_args = 1;
        else if (!strcmp(cmd, "quit")) e.kind = EV_QUIT, want_args = 0;
        else why = "unknown command (wait, drag, pan, wheel, key, resize, save, quit)";
        if (!why && k - 1 != want_args) why = "wrong number of arguments";
        if (!why && (e.kind == EV_WAIT || e.kind == EV_DRAG || e.kind == EV_PAN ||
                     e.kind == EV_WHEEL || e.kind == EV_RESIZE)) {
            e.a = strtod(arg1, &end);
            if (*end || !isfinite(e.a)) why = "not a number";
            if (want_args == 2) {
                e.b = strtod(arg2, &end);
                if (*end || !isfinite(e.b)) why = "not a number";
            }
            if (!why && e.kind == EV_WAIT && (e.a < 0 || e.a > 3600e3))
                why = "wait needs 0 to 3600000 ms";
            if (!why && e.kind == EV_RESIZE &&
                (e.a < 1 || e.a > 16384 || e.b < 1 || e.b > 16384 || e.a != floor(e.a) ||
                 e.b != floor(e.b)))
                why = "resize needs whole sizes 1 to 16384";
        }
        if (!why && e.kind == EV_KEY) {
            e.key = SDL_GetKeyFromName(arg1);
            if (e.key == SDLK_UNKNOWN) why = "unknown SDL key name";
        }
        if (!why && e.kind == EV_SAVE && !(e.text = strdup(arg1))) why = "out of memory";
        if (why) {
            fprintf(stderr, "splat view: %s:%d: %s: %s", path, line, why, buf);
            if (!strchr(buf, '\n')) fputc('\n', stderr);
            rc = -1;
            break;
        }
        ev[n++] = e;
    }
    fclose(f);
    if (rc < 0) {
        for (int i = 0; i < n; i++) free(ev[i].text);
        free(ev);
        return -1;
    }
    *out = ev;
    *nout = n;
    return 0;
}

/* ---- the window ------------------------------------------------------------------------------ */

typedef struct view {
    shared *s;
    SDL_Window *win;
    SDL_Renderer *ren;
    SDL_Texture *tex;
    uint32_t tw, th;              /* the texture's size */
    uint32_t ww, wh;              /* the window's size: the full frame size */
    orbit cam, home;
    int have_cam;
    int progressive;
    int64_t drag_budget;
    int64_t rest_budget;          /* the point budget at rest (--set point_budget, else 0) */
    int interacting;
    double last_input;
    int ldown, rdown;
    int help;
    int nsave;
    double fps_t[64];
    int nfps;
    uint64_t shown_gen;
    double title_t;
    /* statistics */
    double drag_time, drag_since;
    long drag_frames, rest_frames, frames;
} view;

/* update_camera: sends the orbit camera at the size the state asks for; t_input: when the
 * input that moved it happened, < 0 when no input did (no latency is measured for it). */
static void update_camera(view *v, double t_input)
{
    if (!v->have_cam) return;
    uint32_t w = v->ww, h = v->wh;
    if (v->interacting && v->progressive) {
        w = (w + 1) / 2;
        h = (h + 1) / 2;
    }
    spc_camera c;
    orbit_camera(&v->cam, w, h, &c);
    pthread_mutex_lock(&v->s->mu);
    /* An unchanged camera brings no new frame: sending it would only leave its latency clock
     * running until some later frame. */
    if (v->s->cam_gen && !memcmp(&c, &v->s->cam, sizeof c)) {
        pthread_mutex_unlock(&v->s->mu);
        return;
    }
    v->s->cam = c;
    v->s->cam_gen++;
    v->s->cam_t = t_input;
    pthread_mutex_unlock(&v->s->mu);
    wake(v->s);
}

/* set_quality: the JPEG quality and point budget of the current state. */
static void set_quality(view *v)
{
    pthread_mutex_lock(&v->s->mu);
    int drag = v->interacting && v->progressive;
    v->s->want.quality = drag ? DRAG_QUALITY : REST_QUALITY;
    int64_t b = v->rest_budget;
    if (drag && v->drag_budget > 0 && (b == 0 || v->drag_budget < b) &&
        v->s->info.points > (uint64_t)v->drag_budget)
        b = v->drag_budget;
    v->s->want.point_budget = b;
    v->s->want_gen++;
    v->s->cam_first = drag;
    pthread_mutex_unlock(&v->s->mu);
    wake(v->s);
}

/* touched: an input that moves the view; enters the interacting state. */
static void touched(view *v, double t)
{
    v->last_input = t;
    if (!v->interacting) {
        v->interacting = 1;
        v->drag_since = t;
        set_quality(v);
    }
    update_camera(v, t);
}

/* settle: 150 ms after the last input, the full frame at full quality. */
static void settle(view *v, double t)
{
    if (v->interacting && t - v->last_input >= SETTLE_S) {
        v->interacting = 0;
        v->drag_time += t - v->drag_since;
        set_quality(v);
        update_camera(v, -1); /* the full frame of the view the drag's frames showed */
    }
}

/* step_param: a float parameter up (dir 1) or down (-1): x1.25 / x0.8 when its range is
 * positive, else a twentieth of the range; a parameter this server lacks is reported. */
static void step_param(view *v, const char *name, int dir)
{
    int id = sp_param_find(name);
    shared *s = v->s;
    pthread_mutex_lock(&s->mu);
    if (id < 0 || s->unavail[id]) {
        snprintf(s->status, sizeof s->status, "%s: not available on this server", name);
    } else {
        const sp_param_info *p = &sp_param_table[id];
        char cur[64], nv[64];
        sp_param_get_text(&s->want, id, cur, sizeof cur);
        double x = strtod(cur, NULL);
        if (p->min > 0) x = dir > 0 ? x * 1.25 : x * 0.8;
        else x += dir * (p->max - p->min) / 20;
        x = x < p->min ? p->min : x > p->max ? p->max : x;
        snprintf(nv, sizeof nv, "%.6g", x);
        sp_param_set_text(&s->want, name, nv, NULL, 0);
        s->want_gen++;
        s->status[0] = 0;
    }
    pthread_mutex_unlock(&s->mu);
    wake(s);
}

static void request_save(view *v, const char *path)
{
    shared *s = v->s;
    pthread_mutex_lock(&s->mu);
    if (!v->have_cam) {
        snprintf(s->status, sizeof s->status, "nothing to save yet");
    } else if (s->nsaves == MAX_SAVES) {
        snprintf(s->status, sizeof s->status, "too many saves queued");
    } else {
        save_req *r = &s->saves[s->nsaves++];
        snprintf(r->path, sizeof r->path, "%s", path);
        orbit_camera(&v->cam, v->ww, v->wh, &r->cam);
        r->want = s->want;
        snprintf(s->status, sizeof s->status, "saving %s", path);
    }
    pthread_mutex_unlock(&s->mu);
    wake(s);
}

/* key: one key press; returns 1 when it quits. */
static int key(view *v, SDL_Keycode k)
{
    shared *s = v->s;
    double t = now_s();
    if (k == SDLK_ESCAPE || k == SDLK_q) return 1;
    if (k >= SDLK_1 && k <= SDLK_9) {
        int idx = (int)(k - SDLK_1);
        pthread_mutex_lock(&s->mu);
        if (idx >= SP_PIPE_COUNT) {
            snprintf(s->status, sizeof s->status, "no pipeline %d: this viewer knows %d", idx + 1,
                     SP_PIPE_COUNT);
        } else if (s->pipe_unavail[idx]) {
            char nm[32];
            snprintf(s->status, sizeof s->status, "pipeline %s: not available on this server",
                     sp_enum_name(SP_PIPELINE, idx, nm, sizeof nm));
        } else {
            s->want.pipeline = idx;
            s->want_gen++;
            s->status[0] = 0;
        }
        pthread_mutex_unlock(&s->mu);
        wake(s);
        return 0;
    }
    switch (k) {
    case SDLK_u: step_param(v, "lambda", 1); break;
    case SDLK_j: step_param(v, "lambda", -1); break;
    case SDLK_i: step_param(v, "t", 1); break;
    case SDLK_k: step_param(v, "t", -1); break;
    case SDLK_o: step_param(v, "l_m", 1); break;
    case SDLK_l: step_param(v, "l_m", -1); break;
    case SDLK_e: {
        int id = sp_param_find("shading");
        pthread_mutex_lock(&s->mu);
        if (id < 0 || s->unavail[id]) {
            snprintf(s->status, sizeof s->status, "shading=edl: not available on this server");
        } else {
            s->want.shading = s->want.shading == SP_SHADING_EDL ? SP_SHADING_LAMBERT
                                                                : SP_SHADING_EDL;
            s->want_gen++;
            s->status[0] = 0;
        }
        pthread_mutex_unlock(&s->mu);
        wake(s);
        break;
    }
    case SDLK_r:
        if (v->have_cam) {
            v->cam = v->home;
            update_camera(v, t);
        }
        break;
    case SDLK_s: {
        char path[64];
        snprintf(path, sizeof path, "splat-view-%d.png", ++v->nsave);
        request_save(v, path);
        break;
    }
    case SDLK_h:
        v->help = !v->help;
        if (v->help) fputs(keys_text, stdout), fflush(stdout);
        break;
    default: break;
    }
    return 0;
}

/* update_title: the heads-up line. */
static void update_title(view *v)
{
    shared *s = v->s;
    double t = now_s();
    int n = 0;
    for (int i = 0; i < v->nfps; i++) n += t - v->fps_t[i] <= 1.0;
    char title[4096], params[400], pipes[160] = "";
    pthread_mutex_lock(&s->mu);
    for (int i = 0; i < SP_PIPE_COUNT; i++) {
        char nm[32];
        sp_enum_name(SP_PIPELINE, i, nm, sizeof nm);
        size_t l = strlen(pipes);
        snprintf(pipes + l, sizeof pipes - l, "%s%d%s%s%s", i ? " " : "", i + 1,
                 i == s->want.pipeline ? "*" : ":", nm, s->pipe_unavail[i] ? "(n/a)" : "");
    }
    static const char *const knobs[] = {"lambda", "t", "l_m"};
    size_t l = 0;
    params[0] = 0;
    for (int i = 0; i < 3; i++) {
        int id = sp_param_find(knobs[i]);
        char val[64] = "n/a";
        if (id >= 0 && !s->unavail[id]) sp_param_get_text(&s->want, id, val, sizeof val);
        l += (size_t)snprintf(params + l, sizeof params - l, "%s %s=%s", i ? "," : "", knobs[i],
                              val);
    }
    snprintf(params + l, sizeof params - l, ", edl %s, q%d%s",
             s->want.shading == SP_SHADING_EDL ? "on" : "off", (int)s->want.quality,
             v->interacting && v->progressive ? " (moving)" : "");
    if (v->help) {
        snprintf(title, sizeof title, "splat view — 1-%d pipelines, U/J lambda, I/K t, O/L l_m, "
                 "E edl, R reset, S save, H help, Esc/Q quit; drag orbit, right-drag pan, wheel "
                 "zoom", SP_PIPE_COUNT);
    } else if (!s->connected && !s->ever_connected) {
        snprintf(title, sizeof title, "splat view %s — %s", s->name,
                 s->status[0] ? s->status : "connecting");
    } else {
        char lat[48] = "";
        if (s->nlat) /* the last input's, kept until the next input's */
            snprintf(lat, sizeof lat, " | latency %.0f ms", s->lat_last_ms);
        snprintf(title, sizeof title,
                 "%s%s%s | %d fps | render %.1f ms, encode %.1f ms%s | %s %ux%u | %s |%s%s%s",
                 s->connected ? "" : "DISCONNECTED | ", s->name, "", n, s->frender_ms,
                 s->fencode_ms, lat, s->fpipe, s->fw, s->fh, pipes, params,
                 s->status[0] ? " | " : "", s->status);
    }
    pthread_mutex_unlock(&s->mu);
    SDL_SetWindowTitle(v->win, title);
    v->title_t = t;
}

/* show_frame: the latest frame into the texture and the window. */
static void show_frame(view *v)
{
    shared *s = v->s;
    int verbose_line = 0;
    char line[400] = "";
    pthread_mutex_lock(&s->mu);
    if (s->frame_gen != v->shown_gen && s->rgba) {
        v->shown_gen = s->frame_gen;
        if (!v->tex || v->tw != s->fw || v->th != s->fh) {
            if (v->tex) SDL_DestroyTexture(v->tex);
            v->tex = SDL_CreateTexture(v->ren, SDL_PIXELFORMAT_RGBA32,
                                       SDL_TEXTUREACCESS_STREAMING, (int)s->fw, (int)s->fh);
            v->tw = s->fw;
            v->th = s->fh;
        }
        if (v->tex) SDL_UpdateTexture(v->tex, NULL, s->rgba, (int)s->fw * 4);
        double t = now_s();
        if (v->nfps == (int)(sizeof v->fps_t / sizeof v->fps_t[0])) {
            memmove(&v->fps_t[0], &v->fps_t[1], (size_t)(v->nfps - 1) * sizeof v->fps_t[0]);
            v->nfps--;
        }
        v->fps_t[v->nfps++] = t;
        v->frames++;
        if (v->interacting) v->drag_frames++;
        else v->rest_frames++;
        if (s->verbose) {
            char lat[32] = "-"; /* this frame shows no new input */
            if (s->flatency_ms >= 0) snprintf(lat, sizeof lat, "%.1f", s->flatency_ms);
            snprintf(line, sizeof line, "frame %ux%u pipeline=%s camera_seq=%u render_ms=%.1f "
                     "encode_ms=%.1f bytes=%zu points=%llu latency_ms=%s quality=%d moving=%d",
                     s->fw, s->fh, s->fpipe, s->fcamseq, s->frender_ms, s->fencode_ms, s->fbytes,
                     (unsigned long long)s->fpoints, lat, (int)s->want.quality, v->interacting);
            verbose_line = 1;
        }
    }
    pthread_mutex_unlock(&s->mu);
    if (verbose_line) {
        printf("%s\n", line);
        fflush(stdout);
    }
    SDL_SetRenderDrawColor(v->ren, 0, 0, 0, 255);
    SDL_RenderClear(v->ren);
    if (v->tex) SDL_RenderCopy(v->ren, v->tex, NULL, NULL);
    SDL_RenderPresent(v->ren);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* print_summary: the final camera as `splat render` options and the measurements. */
static void print_summary(view *v)
{
    shared *s = v->s;
    if (v->have_cam) {
        spc_camera c;
        orbit_camera(&v->cam, v->ww, v->wh, &c);
        printf("camera --eye %.17g,%.17g,%.17g --target %.17g,%.17g,%.17g --up %.17g,%.17g,%.17g "
               "--fov %.9g --size %ux%u\n", c.eye[0], c.eye[1], c.eye[2], c.target[0],
               c.target[1], c.target[2], c.up[0], c.up[1], c.up[2], (double)c.fov_deg, c.width,
               c.height);
    }
    pthread_mutex_lock(&s->mu);
    qsort(s->lat, (size_t)s->nlat, sizeof s->lat[0], cmp_double);
    char lat[96] = ""; /* no camera input, no latency */
    if (s->nlat)
        snprintf(lat, sizeof lat, " latency_p50_ms=%.1f latency_p90_ms=%.1f",
                 s->lat[s->nlat / 2], s->lat[(s->nlat * 9) / 10]);
    int nlat = s->nlat;
    pthread_mutex_unlock(&s->mu);
    printf("stats frames=%ld moving_frames=%ld moving_s=%.2f moving_fps=%.2f rest_frames=%ld "
           "latency_n=%d%s\n", v->frames, v->drag_frames, v->drag_time,
           v->drag_time > 0 ? v->drag_frames / v->drag_time : 0.0, v->rest_frames, nlat, lat);
    fflush(stdout);
}

/* handle_event: one SDL event; returns 1 when it quits. */
static int handle_event(view *v, const SDL_Event *ev)
{
    double t = now_s();
    switch (ev->type) {
    case SDL_QUIT: return 1;
    case SDL_KEYDOWN: return key(v, ev->key.keysym.sym);
    case SDL_MOUSEBUTTONDOWN:
    case SDL_MOUSEBUTTONUP: {
        int down = ev->type == SDL_MOUSEBUTTONDOWN;
        if (ev->button.button == SDL_BUTTON_LEFT) v->ldown = down;
        if (ev->button.button == SDL_BUTTON_RIGHT) v->rdown = down;
        break;
    }
    case SDL_MOUSEMOTION:
        if (!v->have_cam) break;
        if (v->ldown) {
            orbit_drag(&v->cam, ev->motion.xrel, ev->motion.yrel);
            touched(v, t);
        } else if (v->rdown) {
            orbit_pan(&v->cam, ev->motion.xrel, ev->motion.yrel, v->wh);
            touched(v, t);
        }
        break;
    case SDL_MOUSEWHEEL:
        if (!v->have_cam) break;
        orbit_zoom(&v->cam, ev->wheel.y);
        touched(v, t);
        break;
    case SDL_WINDOWEVENT:
        if (ev->window.event == SDL_WINDOWEVENT_SIZE_CHANGED) {
            v->ww = (uint32_t)(ev->window.data1 > 0 ? ev->window.data1 : 1);
            v->wh = (uint32_t)(ev->window.data2 > 0 ? ev->window.data2 : 1);
            if (v->have_cam) touched(v, t);
        }
        show_frame(v);
        break;
    default: break;
    }
    return 0;
}

/* run_script_event: one script line as the input it stands for; returns 1 when it quits. */
static int run_script_event(view *v, const script_ev *e)
{
    double t = now_s();
    switch (e->kind) {
    case EV_DRAG:
        orbit_drag(&v->cam, e->a, e->b);
        touched(v, t);
        break;
    case EV_PAN:
        orbit_pan(&v->cam, e->a, e->b, v->wh);
        touched(v, t);
        break;
    case EV_WHEEL:
        orbit_zoom(&v->cam, e->a);
        touched(v, t);
        break;
    case EV_KEY: return key(v, e->key);
    case EV_RESIZE:
        SDL_SetWindowSize(v->win, (int)e->a, (int)e->b);
        v->ww = (uint32_t)e->a;
        v->wh = (uint32_t)e->b;
        touched(v, t);
        break;
    case EV_SAVE: request_save(v, e->text); break;
    case EV_QUIT: return 1;
    default: break;
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *name = NULL, *script = NULL, *sets[CLI_MAX_SETS];
    int nsets = 0, verbose = 0, progressive = 1, timeout_s = 30, keepalive_s = 60;
    long long drag_budget = 300000;
    spc_options opt = {.host = "127.0.0.1", .port = SPC_DEFAULT_PORT, .client_name = "splat view"};
    uint32_t w = 1280, h = 720;
    int i = 1;
    if (i < argc && !strcmp(argv[i], "view")) i++;
    for (; i < argc; i++) {
        const char *a = argv[i];
        const char *val = i + 1 < argc ? argv[i + 1] : NULL;
        int takes = !strcmp(a, "--host") || !strcmp(a, "--port") || !strcmp(a, "--token-file") ||
                    !strcmp(a, "--tls-ca") || !strcmp(a, "--tls-name") ||
                    !strcmp(a, "--size") || !strcmp(a, "--set") || !strcmp(a, "--script") ||
                    !strcmp(a, "--drag-budget") || !strcmp(a, "--timeout") ||
                    !strcmp(a, "--keepalive");
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(usage_text, stdout);
            fputs(keys_text, stdout);
            return 0;
        }
        if (takes && !val) {
            fprintf(stderr, "splat view: %s needs a value\n", a);
            return EXIT_USAGE;
        }
        char *end;
        if (!strcmp(a, "--host")) opt.host = val;
        else if (!strcmp(a, "--port")) {
            long p = strtol(val, &end, 10);
            if (*end || p < 1 || p > 65535) {
                fprintf(stderr, "splat view: --port needs 1 to 65535, not '%s'\n", val);
                return EXIT_USAGE;
            }
            opt.port = (int)p;
        } else if (!strcmp(a, "--token-file")) opt.token_file = val;
        else if (!strcmp(a, "--tls")) opt.tls = 1;
        else if (!strcmp(a, "--tls-ca")) opt.tls_ca = val;
        else if (!strcmp(a, "--tls-name")) opt.tls_name = val;
        else if (!strcmp(a, "--size")) {
            if (cli_parse_size(val, &w, &h) < 0) {
                fprintf(stderr, "splat view: --size needs WxH (1..16384 each), not '%s'\n", val);
                return EXIT_USAGE;
            }
        } else if (!strcmp(a, "--set")) {
            if (nsets == CLI_MAX_SETS) {
                fprintf(stderr, "splat view: too many --set\n");
                return EXIT_USAGE;
            }
            sets[nsets++] = val;
        } else if (!strcmp(a, "--script")) script = val;
        else if (!strcmp(a, "--drag-budget")) {
            drag_budget = strtoll(val, &end, 10);
            if (*end || drag_budget < 0) {
                fprintf(stderr, "splat view: --drag-budget needs a count >= 0\n");
                return EXIT_USAGE;
            }
        } else if (!strcmp(a, "--timeout")) {
            long tt = strtol(val, &end, 10);
            if (*end || tt < 0 || tt > 86400) {
                fprintf(stderr, "splat view: --timeout needs 0 to 86400 seconds\n");
                return EXIT_USAGE;
            }
            timeout_s = (int)tt;
        } else if (!strcmp(a, "--keepalive")) {
            long k = strtol(val, &end, 10);
            if (*end || k < 0 || k > 86400) {
                fprintf(stderr, "splat view: --keepalive needs 0 to 86400 seconds, not '%s'\n", val);
                return EXIT_USAGE;
            }
            keepalive_s = (int)k;
        } else if (!strcmp(a, "--verbose") || !strcmp(a, "-v")) verbose = 1;
        else if (!strcmp(a, "--no-progressive")) progressive = 0;
        else if (a[0] == '-' && a[1]) {
            fprintf(stderr, "splat view: unknown option %s\n%s", a, usage_text);
            return EXIT_USAGE;
        } else if (!name) name = a;
        else {
            fprintf(stderr, "splat view: one cloud NAME only ('%s' is extra)\n", a);
            return EXIT_USAGE;
        }
        if (takes) i++;
    }
    if (!name) {
        fprintf(stderr, "splat view: which cloud? %s", usage_text);
        return EXIT_USAGE;
    }
    opt.timeout_ms = timeout_s ? timeout_s * 1000 : -1;

    static shared s; /* large (the latency samples): not on the stack */
    pthread_mutex_init(&s.mu, NULL);
    s.opt = opt;
    s.name = name;
    s.verbose = verbose;
    s.keepalive_s = keepalive_s;
    sp_params_defaults(&s.want);
    char err[600];
    for (int k = 0; k < nsets; k++)
        if (sp_param_set_kv(&s.want, sets[k], err, sizeof err) < 0) {
            fprintf(stderr, "splat view: --set %s: %s\n", sets[k], err);
            return EXIT_USAGE;
        }
    s.want.format = SP_FMT_JPEG;
    int64_t rest_budget = s.want.point_budget;
    s.want.quality = REST_QUALITY;
    s.want_gen = 1;

    script_ev *sc = NULL;
    int nsc = 0;
    if (script && script_load(script, &sc, &nsc) < 0) return EXIT_USAGE;

    /* SDL's software renderer by default (the environment's SDL_RENDER_DRIVER prevails): the
     * window's work is one texture upload and one scaled copy per frame, which needs no GL
     * driver in this process (no GPU on a render client, and none for Xvfb). */
    SDL_SetHintWithPriority(SDL_HINT_RENDER_DRIVER, "software", SDL_HINT_DEFAULT);
    SDL_SetHintWithPriority(SDL_HINT_FRAMEBUFFER_ACCELERATION, "0", SDL_HINT_DEFAULT);
    if (SDL_Init(SDL_INIT_VIDEO | SDL_INIT_EVENTS) < 0) {
        fprintf(stderr, "splat view: cannot start SDL video (is DISPLAY set?): %s\n",
                SDL_GetError());
        return EXIT_FAIL;
    }
    const char *drv = SDL_GetCurrentVideoDriver();
    if (!script && drv && (!strcmp(drv, "offscreen") || !strcmp(drv, "dummy"))) {
        fprintf(stderr, "splat view: no display to show a window on (SDL video driver %s; is "
                "DISPLAY set?)\n", drv);
        SDL_Quit();
        return EXIT_FAIL;
    }
    s.server_event = SDL_RegisterEvents(1);
    s.wake_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    view v = {.s = &s, .progressive = progressive, .drag_budget = drag_budget,
              .rest_budget = rest_budget, .ww = w, .wh = h};
    char title[300];
    snprintf(title, sizeof title, "splat view %s — connecting", name);
    v.win = SDL_CreateWindow(title, SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED, (int)w,
                             (int)h, SDL_WINDOW_RESIZABLE);
    if (v.win) v.ren = SDL_CreateRenderer(v.win, -1, 0);
    if (v.win && !v.ren) v.ren = SDL_CreateRenderer(v.win, -1, SDL_RENDERER_SOFTWARE);
    if (!v.win || !v.ren || s.wake_fd < 0) {
        fprintf(stderr, "splat view: cannot open a window: %s\n", SDL_GetError());
        if (v.win) SDL_DestroyWindow(v.win);
        SDL_Quit();
        return EXIT_FAIL;
    }
    pthread_t net;
    if (pthread_create(&net, NULL, net_main, &s) != 0) {
        fprintf(stderr, "splat view: cannot start the network thread\n");
        return EXIT_FAIL;
    }
    show_frame(&v);

    static char last_status[sizeof s.status];
    uint64_t info_seen = 0;
    int sci = 0, quit = 0, rc = 0, quit_asked = 0;
    double script_due = now_s();
    while (!quit) {
        SDL_Event ev;
        int timeout = 50;
        if (v.interacting) timeout = 10;
        if (sc && v.have_cam) timeout = 2;
        if (SDL_WaitEventTimeout(&ev, timeout)) {
            do {
                if (ev.type == s.server_event) continue;
                if (handle_event(&v, &ev)) quit = 1;
            } while (!quit && SDL_PollEvent(&ev));
        }
        double t = now_s();
        pthread_mutex_lock(&s.mu);
        int fatal = s.fatal, new_info = s.info_gen != info_seen;
        int new_frame = s.frame_gen != v.shown_gen;
        spc_info info = s.info;
        info_seen = s.info_gen;
        pthread_mutex_unlock(&s.mu);
        if (fatal) {
            fprintf(stderr, "splat view: %s\n", s.status);
            rc = EXIT_FAIL;
            break;
        }
        if (new_info) {
            if (!v.have_cam) {
                spc_camera c;
                spc_camera_frame(&info, w, h, &c);
                orbit_from_camera(&v.home, &c);
                v.cam = v.home;
                v.have_cam = 1;
                script_due = t;
            }
            update_camera(&v, -1); /* a new session needs the camera again (no input) */
        }
        if (new_frame) show_frame(&v);
        if (verbose) {
            /* Status changes (a refused parameter, a save, a disconnection) as log lines. */
            pthread_mutex_lock(&s.mu);
            int changed = strcmp(s.status, last_status) != 0;
            if (changed) snprintf(last_status, sizeof last_status, "%s", s.status);
            pthread_mutex_unlock(&s.mu);
            if (changed && last_status[0]) printf("status %s\n", last_status), fflush(stdout);
        }
        settle(&v, t);
        /* The script runs once the cloud is open, each line when the previous wait is over. */
        while (sc && v.have_cam && !quit && sci < nsc && t >= script_due) {
            const script_ev *e = &sc[sci++];
            if (e->kind == EV_WAIT) script_due = t + e->a / 1e3;
            else if (run_script_event(&v, e)) quit = 1;
        }
        if (sc && sci == nsc && !quit) quit = 1; /* the end of a script quits */
        if (t - v.title_t > 0.25 || new_frame) update_title(&v);
        if (quit && !quit_asked) {
            /* Let queued saves finish: the network thread takes them before it stops. */
            quit_asked = 1;
            pthread_mutex_lock(&s.mu);
            int pending = s.nsaves;
            pthread_mutex_unlock(&s.mu);
            if (pending) quit = 0;
        } else if (quit_asked) {
            pthread_mutex_lock(&s.mu);
            quit = s.nsaves == 0 || !s.connected;
            pthread_mutex_unlock(&s.mu);
        }
    }
    if (v.interacting) v.drag_time += now_s() - v.drag_since;
    pthread_mutex_lock(&s.mu);
    s.quit = 1;
    pthread_mutex_unlock(&s.mu);
    wake(&s);
    pthread_join(net, NULL);
    if (rc == 0) print_summary(&v);
    for (int k = 0; k < nsc; k++) free(sc[k].text);
    free(sc);
    free(s.rgba);
    if (v.tex) SDL_DestroyTexture(v.tex);
    SDL_DestroyRenderer(v.ren);
    SDL_DestroyWindow(v.win);
    SDL_Quit();
    close(s.wake_fd);
    pthread_mutex_destroy(&s.mu);
    return rc;
}
