/* fuzz_dispatch.c — the dispatch fuzz target (see fuzz_targets.h): the daemon's own session,
 * dispatch and render-thread code, in this process, serving one connection (a socketpair) per
 * input. The daemon is started once per process (srv_core_start: event loop, render, encoder
 * and prep threads on the real renderer, frames at most 128x128) with a 64-point cloud
 * prepared, and driven with ev_run_once. Separate from fuzz_targets.c so that the other
 * targets' fuzzers do not link the whole server. */
#include "fuzz_targets.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "proto.h"
#include "srv.h"

/* The daemon of this process: made on the first input, kept for the next ones (a fuzzer runs
 * millions of inputs; starting the renderer for each would be all it did). */
typedef struct fz_daemon {
    srv sv;
    char dir[256];
} fz_daemon;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static fz_daemon *daemon_get(void)
{
    static fz_daemon *d;
    if (d) return d;
    d = calloc(1, sizeof *d);
    if (!d) abort();
    const char *tmp = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    snprintf(d->dir, sizeof d->dir, "%s/splatd-fuzz-dispatch.XXXXXX", tmp);
    if (!mkdtemp(d->dir)) {
        perror("mkdtemp");
        abort();
    }
    static char data[300], cache[300], cloud[400];
    snprintf(data, sizeof data, "%s/data", d->dir);
    snprintf(cache, sizeof cache, "%s/cache", d->dir);
    snprintf(cloud, sizeof cloud, "%s/sphere.xyz", data);
    if (mkdir(data, 0755) != 0 || mkdir(cache, 0700) != 0) abort();
    FILE *f = fopen(cloud, "w");
    if (!f) abort();
    for (int i = 0; i < 64; i++) { /* a Fibonacci sphere */
        double z = 1 - 2 * (i + 0.5) / 64, r = sqrt(1 - z * z), a = i * 2.399963;
        fprintf(f, "%.5f %.5f %.5f\n", r * cos(a), r * sin(a), z);
    }
    if (fclose(f) != 0) abort();
    srv *sv = &d->sv;
    srv_opts_defaults(&sv->o);
    sv->o.data_dir = data;
    sv->o.cache_dir = cache;
    sv->o.max_clients = 2;
    sv->o.max_unauth = 2;
    sv->o.max_frame_bytes = 64u << 20;
    sv->lfd = sv->sigfd = sv->http_lfd = -1;
    sv->max_w = sv->max_h = 128;
    sd_err err = {0};
    if (srv_core_start(sv, &err) != 0 || srv_preload(sv, "sphere", &err) != 0) {
        fprintf(stderr, "fuzz dispatch: cannot start the daemon: %s\n", err.msg);
        abort();
    }
    /* Wait for the cloud (prepared and uploaded by the workers). */
    double t0 = now_s();
    for (;;) {
        ev_run_once(sv->loop, 20);
        int ready = sv->nclouds > 0 && sv->clouds[0].state == SRV_CLOUD_READY;
        if (ready) break;
        if (now_s() - t0 > 60) {
            fprintf(stderr, "fuzz dispatch: the cloud was not ready within 60 s\n");
            abort();
        }
    }
    return d;
}

/* out_check: feeds the daemon's bytes to a client-side decoder: every message must decode
 * and parse. Records the first ERROR's code in *first_err. */
static void out_check(proto_decoder *dec, const uint8_t *p, size_t n, int *first_err)
{
    while (n > 0) {
        size_t used = 0;
        proto_msg m;
        proto_error e;
        memset(&e, 0, sizeof e);
        int rc = proto_decode(dec, p, n, &used, &m, &e);
        p += used;
        n -= used;
        if (rc < 0) {
            fprintf(stderr, "fuzz oracle failed (dispatch): the daemon sent bytes its own client "
                    "decoder refuses: %s\n", e.msg);
            abort();
        }
        if (rc != PROTO_ONE_MSG) continue;
        if (m.h.type == PROTO_MSG_WELCOME) dec->version = m.h.version;
        if (fuzz_parse_msg(&m) < 0) {
            fprintf(stderr, "fuzz oracle failed (dispatch): the daemon sent a %s its own parser "
                    "refuses\n", proto_msg_name(m.h.type));
            abort();
        }
        if (m.h.type == PROTO_MSG_ERROR && !*first_err) {
            uint32_t code = 0;
            if (m.len >= 4) memcpy(&code, m.payload, 4);
            *first_err = code ? -(int)code : -1;
        }
    }
}

/* find_session: the live session on socket fd, or NULL. */
static sess *find_session(srv *sv, int fd)
{
    for (int i = 0; i < sv->nslots; i++)
        if (sv->sessions[i] && !sv->sessions[i]->dead && sv->sessions[i]->fd == fd)
            return sv->sessions[i];
    return NULL;
}

int fuzz_one_dispatch(const uint8_t *data, size_t len)
{
    fz_daemon *d = daemon_get();
    srv *sv = &d->sv;
    int sp[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0, sp) != 0) abort();
    if (srv_adopt(sv, sp[0], "fuzz:1") != 0) {
        fprintf(stderr, "fuzz oracle failed (dispatch): the daemon refused a connection with %d "
                "sessions open (one left over from an earlier input?)\n", sv->nsess);
        abort();
    }
    sess *s = find_session(sv, sp[0]);
    uint32_t id = s ? s->id : 0;
    proto_decoder dec;
    proto_decoder_init(&dec, PROTO_S2C);
    dec.max_payload = 1u << 20;
    int first_err = 0;
    size_t off = 0;
    uint8_t buf[65536];
    double t0 = now_s();
    int quiet = 0;
    /* Serve until the daemon closed the session, or everything was written and the daemon has
     * been quiet a few rounds, or 1 s (a slow input is not a finding; a hang would be). */
    while (now_s() - t0 < 1.0) {
        while (off < len) {
            ssize_t w = write(sp[1], data + off, len - off);
            if (w <= 0) break;
            off += (size_t)w;
        }
        ev_run_once(sv->loop, 2);
        ssize_t r;
        int got = 0;
        while ((r = read(sp[1], buf, sizeof buf)) > 0) {
            out_check(&dec, buf, (size_t)r, &first_err);
            got = 1;
        }
        s = srv_lookup(sv, id);
        if (!s || s->dead) break;
        int idle = off == len && !got && !sess_busy(s) && rt_pending(sv->rt, id) == 0 &&
                   s->in_off == s->in_len && !ev_timer_armed(&s->fps_timer);
        quiet = idle ? quiet + 1 : 0;
        if (quiet >= 3) break;
    }
    /* The client goes: the daemon must notice and free the session. */
    close(sp[1]);
    double t1 = now_s();
    while (srv_lookup(sv, id)) {
        ev_run_once(sv->loop, 5);
        if (now_s() - t1 > 5) {
            fprintf(stderr, "fuzz oracle failed (dispatch): the session outlived its client by "
                    "5 s\n");
            abort();
        }
    }
    ev_run_once(sv->loop, 0); /* before_sleep frees it */
    proto_decoder_free(&dec);
    return first_err;
}
