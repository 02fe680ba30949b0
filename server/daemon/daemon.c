/* daemon.c — `splatd` (the default sub-command): options, start-up checks and the wiring of
 * the event loop (sockets, signals, timers) to the workers (render_thread.c) and the request
 * handlers (dispatch.c).
 *
 * Threads: this one runs the event loop for every socket; render_thread.c adds the render,
 * encoder and prep threads. SIGTERM/SIGINT arrive through a signalfd (blocked in every thread);
 * SIGPIPE is ignored and sends use MSG_NOSIGNAL. */
#include <errno.h>
#include <getopt.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "commands.h"
#include "daemon.h"
#include "datadir.h"
#include "page_gen.h"
#include "lod.h"
#include "srv.h"
#include "tls.h"

static void usage(FILE *f)
{
    fprintf(f,
            "usage: splatd [--listen HOST:PORT] --data DIR [options]\n"
            "\n"
            "Serves the point clouds of DIR to splat clients: renders frames on demand and streams them.\n"
            "\n"
            "  --listen HOST:PORT   address to listen on (default 127.0.0.1:7878; port 0 picks a free\n"
            "                       port, printed on stderr as 'listening on HOST:PORT'). Without\n"
            "                       --token-file, --tls-cert and --tls-key only loopback addresses\n"
            "                       are accepted.\n"
            "  --http HOST:PORT     also serve the browser viewer: GET / is the page, /ws its\n"
            "                       WebSocket carrying the same protocol (off by default; the\n"
            "                       same loopback-only rule without --token-file as --listen)\n"
            "  --port-file F        write the bound port to F once listening (with --http, the\n"
            "                       HTTP port on a second line)\n"
            "  --data DIR           the data directory: clients open clouds by file name in it\n"
            "  --cache DIR          prepared-cloud cache (default $SPLATD_CACHE, $XDG_CACHE_HOME/splatd,\n"
            "                       ~/.cache/splatd)\n"
            "  --backend B          auto (default), egl or osmesa\n"
            "  --shader-dir DIR     load shaders from DIR instead of the built-in copies\n"
            "  --token-file F       require clients to prove they know the token in F (HMAC-SHA256\n"
            "                       of a random challenge); F must not be accessible by group or others\n"
            "  --tls-cert F         serve TLS (1.2 or newer) with the PEM certificate chain in F;\n"
            "                       required, with --tls-key, to listen beyond loopback\n"
            "  --tls-key F          the certificate's PEM private key (mode 0600)\n"
            "  --preload NAME ...   prepare and upload these clouds at start-up (names up to the next\n"
            "                       option; --preload may also be repeated)\n"
            "  --max-clients N      authenticated connections served at once (default 64)\n"
            "  --max-unauth N       connections not yet authenticated, counted apart from\n"
            "                       --max-clients (default 64); when full, a new connection waits\n"
            "                       until it sends its first bytes, then takes the place of one\n"
            "                       that has sent nothing for 2 s, else nothing yet, else of the\n"
            "                       one connected the longest\n"
            "  --max-per-addr N     connections from one client address (default: half of\n"
            "                       --max-clients, at least 1, at most 32)\n"
            "  --handshake-timeout S  seconds a client has to authenticate (default 10)\n"
            "  --idle-timeout S     close an authenticated client silent this long with nothing of\n"
            "                       its own in progress (default 300; 0: never)\n"
            "  --read-timeout S     seconds a message may take to arrive once its first byte has\n"
            "                       (default 30; 0: no limit)\n"
            "  --write-timeout S    close a client whose output could not move for S seconds because\n"
            "                       it does not read (default 30; 0: no limit)\n"
            "  --max-frame-bytes SIZE  memory all frames being rendered, encoded or waiting to be\n"
            "                       sent may hold (suffix K, M or G; default: a quarter of RAM); a\n"
            "                       frame waits until it fits, one larger than SIZE is refused\n"
            "  --auth-fail-delay MS  delay before a failed authentication is answered, doubling with\n"
            "                       each failure from the same address up to 64x (default 250 for\n"
            "                       non-loopback clients; given explicitly, loopback clients too;\n"
            "                       0: none)\n"
            "  --gpu-memory SIZE    bytes of cloud buffers kept on the GPU (suffix K, M or G; default:\n"
            "                       3/4 of the device's memory, a quarter of RAM on a software\n"
            "                       renderer). Clouds no client has rendered for longest leave first\n"
            "                       and come back when rendered again.\n"
            "  --lod auto|always|never  which clouds get the level-of-detail form (an out-of-core\n"
            "                       octree drawn under point_budget): auto = files of 64 MiB or more\n"
            "  --prep-memory SIZE   memory cap of the LOD build (default 2G)\n"
            "  --lod-inflight N     LOD nodes the loader thread reads at once (default 4); a frame\n"
            "                       draws a missing node's ancestor instead, and the next frames\n"
            "                       of the same view refine it\n"
            "  --copc-preview N     a first OPEN of an unprepared .copc.laz shows COPC's top octree\n"
            "                       levels (at most N points together; at least the root) to\n"
            "                       clients that set provisional=1, while the full prep runs\n"
            "                       (default 500000; 0: off)\n"
            "  --help               this text\n"
            "\n"
            "SIGTERM or SIGINT stops accepting, finishes the frames in flight (at most 5 s) and exits 0.\n");
}

/* parse_size: "N", "NK", "NM", "NG" (powers of 1024) into bytes, at least 1 MiB. 0 or -1. */
int srv_parse_size(const char *s, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (end == s || errno || s[0] == '-') return -1;
    int shift = 0;
    if (*end == 'K' || *end == 'k') shift = 10, end++;
    else if (*end == 'M' || *end == 'm') shift = 20, end++;
    else if (*end == 'G' || *end == 'g') shift = 30, end++;
    if (*end || v > (UINT64_MAX >> shift)) return -1;
    v <<= shift;
    if (v < (1u << 20)) return -1;
    *out = v;
    return 0;
}

int srv_per_addr_default(int max_clients)
{
    int half = max_clients / 2;
    return half < 1 ? 1 : half > 32 ? 32 : half;
}

void srv_opts_defaults(srv_opts *o)
{
    memset(o, 0, sizeof *o);
    snprintf(o->host, sizeof o->host, "127.0.0.1");
    o->port = PROTO_DEFAULT_PORT;
    o->max_clients = 64;
    o->handshake_ms = 10000;
    o->idle_ms = 300000;
    o->read_ms = 30000;
    o->write_ms = 30000;
    o->max_unauth = 64;
    o->auth_delay_ms = 250;
    o->shutdown_ms = 5000;
    o->preview_points = 500000;
}

/* parse_opts: fills o from argv. Returns 0, 1 for --help (exit 0), or -1 after printing the
 * error (exit 2). */
static int parse_opts(int argc, char **argv, srv_opts *o)
{
    enum { O_LISTEN = 1000, O_DATA, O_CACHE, O_BACKEND, O_TOKEN, O_PRELOAD, O_SHADERS, O_MAXC,
           O_PORTFILE, O_HS, O_GPUMEM, O_LOD, O_PREPMEM, O_LODUP, O_FRAMEMEM, O_IDLE, O_RDTO, O_WRTO,
           O_UNAUTH, O_PERADDR, O_AUTHDELAY, O_HTTP, O_TLSCERT, O_TLSKEY, O_HELP,
           O_PREVIEW };
    static const struct option lo[] = {
        {"listen", required_argument, 0, O_LISTEN},   {"data", required_argument, 0, O_DATA},
        {"cache", required_argument, 0, O_CACHE},     {"backend", required_argument, 0, O_BACKEND},
        {"token-file", required_argument, 0, O_TOKEN}, {"preload", required_argument, 0, O_PRELOAD},
        {"shader-dir", required_argument, 0, O_SHADERS}, {"max-clients", required_argument, 0, O_MAXC},
        {"port-file", required_argument, 0, O_PORTFILE}, {"handshake-timeout", required_argument, 0, O_HS},
        {"gpu-memory", required_argument, 0, O_GPUMEM},
        {"lod", required_argument, 0, O_LOD}, {"lod-inflight", required_argument, 0, O_LODUP}, {"prep-memory", required_argument, 0, O_PREPMEM},
        {"max-frame-bytes", required_argument, 0, O_FRAMEMEM},
        {"idle-timeout", required_argument, 0, O_IDLE}, {"read-timeout", required_argument, 0, O_RDTO},
        {"write-timeout", required_argument, 0, O_WRTO}, {"max-unauth", required_argument, 0, O_UNAUTH},
        {"max-per-addr", required_argument, 0, O_PERADDR},
        {"auth-fail-delay", required_argument, 0, O_AUTHDELAY},
        {"http", required_argument, 0, O_HTTP},
        {"tls-cert", required_argument, 0, O_TLSCERT}, {"tls-key", required_argument, 0, O_TLSKEY},
        {"copc-preview", required_argument, 0, O_PREVIEW},
        {"help", no_argument, 0, O_HELP},             {0, 0, 0, 0},
    };
    srv_opts_defaults(o);
    optind = 1;
    opterr = 0;
    int c;
    int after_preload = 0; /* operands right after --preload are more names ("--preload A B") */
    /* "-" first: operands come back in order as option 1 instead of being permuted to the end,
     * so they can be told apart by what precedes them. */
    while ((c = getopt_long(argc, argv, "-h", lo, NULL)) != -1) {
        sd_err err = {0};
        char *end;
        long v;
        if (c != 1) after_preload = c == O_PRELOAD;
        switch (c) {
        case 1:
            if (!after_preload) {
                fprintf(stderr, "splatd: unexpected argument '%s' (see splatd --help)\n", optarg);
                return -1;
            }
            /* fall through - one more --preload name */
        case O_PRELOAD:
            if (o->npreload == SRV_MAX_PRELOAD) {
                fprintf(stderr, "splatd: at most %d --preload names\n", SRV_MAX_PRELOAD);
                return -1;
            }
            o->preload[o->npreload++] = optarg;
            break;
        case O_LISTEN:
            if (net_parse_hostport(optarg, o->host, sizeof o->host, &o->port, &err) != 0) {
                fprintf(stderr, "splatd: --listen: %s\n", err.msg);
                return -1;
            }
            break;
        case O_HTTP:
            if (net_parse_hostport(optarg, o->http_host, sizeof o->http_host, &o->http_port,
                                   &err) != 0) {
                fprintf(stderr, "splatd: --http: %s\n", err.msg);
                return -1;
            }
            break;
        case O_DATA: o->data_dir = optarg; break;
        case O_CACHE: o->cache_dir = optarg; break;
        case O_TOKEN: o->token_file = optarg; break;
        case O_TLSCERT: o->tls_cert = optarg; break;
        case O_TLSKEY: o->tls_key = optarg; break;
        case O_SHADERS: o->shader_dir = optarg; break;
        case O_PORTFILE: o->port_file = optarg; break;
        case O_BACKEND:
            if (!strcmp(optarg, "auto")) o->backend = RND_BACKEND_AUTO;
            else if (!strcmp(optarg, "egl")) o->backend = RND_BACKEND_EGL;
            else if (!strcmp(optarg, "osmesa")) o->backend = RND_BACKEND_OSMESA;
            else {
                fprintf(stderr, "splatd: --backend '%s': expected auto, egl or osmesa\n", optarg);
                return -1;
            }
            break;
        case O_LOD:
            if (!strcmp(optarg, "auto")) o->lod_mode = LOD_AUTO;
            else if (!strcmp(optarg, "always")) o->lod_mode = LOD_ALWAYS;
            else if (!strcmp(optarg, "never")) o->lod_mode = LOD_NEVER;
            else {
                fprintf(stderr, "splatd: --lod '%s': expected auto, always or never\n", optarg);
                return -1;
            }
            break;
        case O_PREVIEW: {
            char *e = NULL;
            errno = 0;
            unsigned long long np = strtoull(optarg, &e, 10);
            if (!e || *e || errno || optarg[0] == '-' || np > 100000000ull) {
                fprintf(stderr, "splatd: --copc-preview '%s': expected 0 to 100000000 points\n",
                        optarg);
                return -1;
            }
            o->preview_points = np;
            break;
        }
        case O_LODUP: {
            char *e = NULL;
            long nup = strtol(optarg, &e, 10);
            if (!e || *e || nup < 1 || nup > 1024) {
                fprintf(stderr, "splatd: --lod-inflight '%s': expected 1 to 1024\n", optarg);
                return -1;
            }
            o->lod_uploads = (int)nup;
            break;
        }
        case O_PREPMEM:
            if (srv_parse_size(optarg, &o->prep_memory) != 0) {
                fprintf(stderr, "splatd: --prep-memory '%s': expected a size such as 2G\n", optarg);
                return -1;
            }
            break;
        case O_GPUMEM:
            if (srv_parse_size(optarg, &o->gpu_memory) != 0) {
                fprintf(stderr, "splatd: --gpu-memory '%s': expected a size such as 512M or 4G "
                        "(at least 1M)\n", optarg);
                return -1;
            }
            break;
        case O_FRAMEMEM:
            if (srv_parse_size(optarg, &o->max_frame_bytes) != 0) {
                fprintf(stderr, "splatd: --max-frame-bytes '%s': expected a size such as 512M or "
                        "4G (at least 1M)\n", optarg);
                return -1;
            }
            break;
        case O_MAXC:
        case O_HS:
        case O_IDLE:
        case O_RDTO:
        case O_WRTO:
        case O_UNAUTH:
        case O_PERADDR:
        case O_AUTHDELAY: {
            /* One table of the numeric options: name, range, and where the value goes (seconds
             * become milliseconds). */
            const char *name = "max-clients";
            long vmin = 1, hi = 4096, scale = 1;
            int *dst = &o->max_clients;
            switch (c) {
            case O_HS: name = "handshake-timeout"; dst = &o->handshake_ms; hi = 3600; scale = 1000; break;
            case O_IDLE: name = "idle-timeout"; dst = &o->idle_ms; vmin = 0; hi = 86400; scale = 1000; break;
            case O_RDTO: name = "read-timeout"; dst = &o->read_ms; vmin = 0; hi = 3600; scale = 1000; break;
            case O_WRTO: name = "write-timeout"; dst = &o->write_ms; vmin = 0; hi = 3600; scale = 1000; break;
            case O_UNAUTH: name = "max-unauth"; dst = &o->max_unauth; break;
            case O_PERADDR: name = "max-per-addr"; dst = &o->max_per_addr; hi = 8192; break;
            case O_AUTHDELAY: name = "auth-fail-delay"; dst = &o->auth_delay_ms; vmin = 0; hi = 60000; break;
            default: break;
            }
            errno = 0;
            v = strtol(optarg, &end, 10);
            if (*end || end == optarg || errno || v < vmin || v > hi) {
                fprintf(stderr, "splatd: --%s '%s': expected a number in %ld..%ld\n", name,
                        optarg, vmin, hi);
                return -1;
            }
            *dst = (int)(v * scale);
            if (c == O_AUTHDELAY) o->auth_delay_local = 1;
            break;
        }
        case 'h':
        case O_HELP: usage(stdout); return 1;
        default:
            fprintf(stderr, "splatd: unknown or incomplete option '%s' (see splatd --help)\n",
                    argv[optind - 1]);
            return -1;
        }
    }
    if (optind < argc) {
        fprintf(stderr, "splatd: unexpected argument '%s' (see splatd --help)\n", argv[optind]);
        return -1;
    }
    if (!o->data_dir) {
        fprintf(stderr, "splatd: --data DIR is required (the directory of clouds to serve)\n");
        return -1;
    }
    return 0;
}

/* ---- sessions ---- */

/* on_sess_close: a session closed (sess_close): the log line, the render thread forgets its
 * requests and frames, and it joins the list freed before the loop sleeps. */
static void on_sess_close(void *owner, sess *s, const char *reason)
{
    srv *sv = owner;
    /* pending: its requests and frames the render thread still counts (rt_pending); a client
     * that closes with nothing in flight has 0, so the line shows a frame never given back. */
    srv_log(sv, s, "closed: %s (%llu frames sent, %llu dropped, %d pending, %llu bytes, %.1f s)",
            reason, (unsigned long long)s->frames_sent, (unsigned long long)s->frames_dropped,
            sv->rt ? rt_pending(sv->rt, s->id) : 0, (unsigned long long)s->bytes_out,
            (double)(ev_now_ms() - s->t_connect_ms) / 1000.0);
    if (sv->rt) rt_client_close(sv->rt, s->id);
    s->next_dead = sv->dead;
    sv->dead = s;
}

static void on_stream_blocked(void *owner, sess *s, int blocked)
{
    srv *sv = owner;
    rt_set_stream_blocked(sv->rt, s->id, blocked);
}

/* The daemon's side of its sessions: dispatch.c handles their messages. */
static const sess_ops daemon_sess_ops = {
    .on_message = srv_handle,
    .on_decode_error = srv_decode_error,
    .on_close = on_sess_close,
    .release = srv_release_frame,
    .sending = srv_sending_frame,
    .sent = srv_sent_frame,
    .stream_blocked = on_stream_blocked,
};

static void free_dead(srv *sv)
{
    while (sv->dead) {
        sess *s = sv->dead;
        sv->dead = s->next_dead;
        uint32_t i = s->id & 0xffffu;
        if (sv->sessions[i] == s) {
            sv->sessions[i] = NULL;
            sv->nsess--;
        }
        sess_free(s, NULL, NULL); /* rt_client_close already forgot its frames */
    }
}

static void on_handshake_timeout(ev_loop *l, ev_timer *t, void *data)
{
    (void)l; (void)t;
    sess *s = data;
    srv *sv = s->owner;
    proto_buf b = {.version = s->version};
    char msg[128];
    snprintf(msg, sizeof msg, "no %sHELLO within %d s", sv->token.len ? "authenticated " : "",
             sv->o.handshake_ms / 1000);
    if (proto_enc_error(&b, 0, PROTO_E_AUTH_REQUIRED, msg) == 0 && sess_push(s, &b) == 0)
        sess_flush(s, NULL, NULL);
    proto_buf_free(&b);
    sess_close(s, msg);
}

/* refuse: a best-effort ERROR on a connection the daemon will not serve (an HTTP 503 with the
 * text on the browser listener), then close. Over TLS (both listeners have it when the daemon
 * has a certificate) the connection just closes: the client is in its handshake, and a
 * plaintext answer would read as a broken one. */
static void refuse(const srv *sv, int fd, int http, int code, const char *text)
{
    if (sv->tls) {
        close(fd);
        return;
    }
    if (http) {
        char r[512];
        int n = snprintf(r, sizeof r, "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain"
                         "\r\nContent-Length: %zu\r\nConnection: close\r\n\r\n%s\n",
                         strlen(text) + 1, text);
        if (n > 0 && (size_t)n < sizeof r) {
            ssize_t w = send(fd, r, (size_t)n, MSG_NOSIGNAL | MSG_DONTWAIT);
            (void)w;
        }
        close(fd);
        return;
    }
    proto_buf b = {0};
    if (proto_enc_error(&b, 0, (uint32_t)code, text) == 0) {
        ssize_t w = send(fd, b.data, b.len, MSG_NOSIGNAL | MSG_DONTWAIT);
        (void)w;
    }
    proto_buf_free(&b);
    close(fd);
}

void srv_answer_and_close(srv *sv, sess *s, uint32_t seq, int code, const char *text)
{
    srv_log(sv, s, "error %s (seq %u): %s", proto_err_name(code), seq, text);
    proto_buf b = {.version = s->version};
    if (proto_enc_error(&b, seq, (uint32_t)code, text) == 0) sess_send(s, &b);
    else proto_buf_free(&b);
    if (s->dead) return;
    s->close_after = 1;
    snprintf(s->close_reason, sizeof s->close_reason, "after error %s", proto_err_name(code));
    sess_kick(s);
}

/* authfail_entry: the failure record of host, made (replacing the stalest) when missing. */
static srv_authfail *authfail_entry(srv *sv, const char *host, uint64_t now)
{
    srv_authfail *stalest = &sv->authfail[0];
    for (int i = 0; i < SRV_AUTHFAIL_SLOTS; i++) {
        srv_authfail *a = &sv->authfail[i];
        if (a->fails && !strcmp(a->host, host)) {
            if (now - a->last_ms > SRV_AUTHFAIL_FORGET_MS) a->fails = 0;
            return a;
        }
        if (!a->fails || a->last_ms < stalest->last_ms) stalest = a;
        if (!stalest->fails) break;
    }
    memset(stalest, 0, sizeof *stalest);
    snprintf(stalest->host, sizeof stalest->host, "%s", host);
    return stalest;
}

static void on_auth_fail_due(ev_loop *l, ev_timer *t, void *data)
{
    (void)l; (void)t;
    sess *s = data;
    srv_answer_and_close(s->owner, s, s->fail_seq, PROTO_E_AUTH_FAILED,
                     s->fail_noproof ? "no authentication proof; the server needs one"
                                     : "wrong authentication proof");
}

void srv_auth_failed(srv *sv, sess *s, uint32_t seq, int noproof)
{
    char host[NET_ADDR_LEN];
    srv_addr_host(s->addr, host, sizeof host);
    uint64_t now = ev_now_ms();
    srv_authfail *a = authfail_entry(sv, host, now);
    a->fails++;
    a->last_ms = now;
    uint32_t shift = a->fails - 1 < SRV_AUTHFAIL_MAX_SHIFT ? a->fails - 1 : SRV_AUTHFAIL_MAX_SHIFT;
    uint64_t delay = (uint64_t)sv->o.auth_delay_ms << shift;
    /* The delay slows down guessing a token over the network. By default it spares loopback
     * clients, which local tools and test suites use to try many proofs in a row; an explicit
     * --auth-fail-delay covers them as well. */
    if (!sv->o.auth_delay_local && net_host_is_loopback(host)) delay = 0;
    srv_log(sv, s, "authentication failed (%u from this address in a row); answering in %llu ms",
            a->fails, (unsigned long long)delay);
    /* Nothing more is read from this client; the connection keeps its unauthenticated slot
     * (and its place in --max-per-addr) until the answer, so an address cannot guess faster
     * than its connections allow. The handshake timer becomes the delay. */
    s->fail_seq = seq;
    s->fail_noproof = noproof;
    s->auth_failing = 1;
    s->paused = 1;
    ev_timer_start(sv->loop, &s->hs_timer, delay, on_auth_fail_due, s);
}

/* srv_adopt_conn (srv.h): serves the accepted socket c from addr as a session under the caps;
 * http: the browser listener's, whose sessions speak through ws_conn. */
int srv_adopt_conn(srv *sv, int c, const char *addr, int http)
{
    char host[NET_ADDR_LEN], why[200];
    const char *text = NULL;
    srv_addr_host(addr, host, sizeof host);
    int room = srv_room(sv, c, host, why, sizeof why, &text);
    if (room == SRV_ROOM_LOBBY) {
        srv_lobby_hold(sv, c, addr, http);
        return 0;
    }
    if (room != 0) {
        srv_log(sv, NULL, "%s refused: %s", addr, why);
        refuse(sv, c, http, PROTO_E_BUSY, text);
        return SD_ELIMIT;
    }
    free_dead(sv); /* the slot of a connection closed to make room */
    int idx = -1;
    for (int i = 0; i < sv->nslots; i++)
        if (!sv->sessions[i]) { idx = i; break; }
    if (idx < 0) {
        srv_log(sv, NULL, "%s refused: no free connection slot", addr);
        refuse(sv, c, http, PROTO_E_BUSY, "too many clients; retry later");
        return SD_ELIMIT;
    }
    if (++sv->gens[idx] == 0) sv->gens[idx] = 1;
    uint32_t id = ((uint32_t)sv->gens[idx] << 16) | (uint32_t)idx;
    sess *s = sess_new(id, c, addr, sv->loop, &daemon_sess_ops, sv);
    sd_err err = {0};
    if (!s || auth_challenge(s->challenge, &err) != 0 || rt_client_open(sv->rt, id) != 0) {
        srv_log(sv, NULL, "%s refused: %s", addr, s ? err.msg : "out of memory");
        sess_free(s, NULL, NULL);
        refuse(sv, c, http, PROTO_E_INTERNAL, "the server cannot take a connection now");
        return SD_ENOMEM;
    }
    /* The session's transport: TLS when the daemon has a certificate, under HTTP + WebSocket on
     * the browser listener (https and wss). */
    void *tls = sv->tls ? tls_conn_new(sv->tls, c) : NULL, *tctx = tls;
    const net_transport *tr = sv->tls ? &tls_transport : NULL;
    if (http) {
        tr = &ws_transport;
        tctx = sv->tls && !tls ? NULL
             : ws_conn_new(&sv->http_cfg, tls ? &tls_transport : &net_tcp, tls);
        if (!tctx && tls) tls_transport.close(tls, 0);
    }
    if (tr && !tctx) {
        srv_log(sv, NULL, "%s refused: out of memory for its %s state", addr, tr->name);
        sess_free(s, NULL, NULL);
        rt_client_close(sv->rt, id);
        refuse(sv, c, http, PROTO_E_INTERNAL, "the server cannot take a connection now");
        return SD_ENOMEM;
    }
    if (tr) sess_set_transport(s, tr, tctx);
    s->version = PROTO_VERSION;
    s->lim = &sv->lim;
    sv->sessions[idx] = s;
    sv->nsess++;
    srv_log(sv, s, http ? "connected (http)" : "connected");
    ev_timer_start(sv->loop, &s->hs_timer, (uint64_t)sv->o.handshake_ms, on_handshake_timeout, s);
    sess_kick(s);
    return 0;
}

int srv_adopt(srv *sv, int c, const char *addr)
{
    return srv_adopt_conn(sv, c, addr, 0);
}

/* accept_from: takes the pending connections of listener fd (at most 16 a wakeup). */
static void accept_from(srv *sv, int fd, int http)
{
    for (int n = 0; n < 16 && !sv->stopping; n++) {
        char addr[NET_ADDR_LEN];
        int c = net_accept(fd, addr, sizeof addr);
        if (c == -EAGAIN) return;
        if (c < 0) {
            srv_log(sv, NULL, "accept failed: %s", strerror(-c));
            return;
        }
        (void)srv_adopt_conn(sv, c, addr, http);
    }
}

static void on_accept(ev_loop *l, int fd, int mask, void *data)
{
    (void)l; (void)mask;
    accept_from(data, fd, 0);
}

static void on_accept_http(ev_loop *l, int fd, int mask, void *data)
{
    (void)l; (void)mask;
    accept_from(data, fd, 1);
}

/* ---- shutdown ---- */

static void on_stop_deadline(ev_loop *l, ev_timer *t, void *data)
{
    (void)t;
    srv *sv = data;
    srv_log(sv, NULL, "shutdown: frames still in flight after %d ms; exiting anyway", sv->o.shutdown_ms);
    ev_stop(l);
}

static void begin_shutdown(srv *sv, const char *why)
{
    if (sv->stopping) return;
    sv->stopping = 1;
    srv_log(sv, NULL, "%s: not accepting new connections; finishing frames in flight", why);
    if (sv->lfd >= 0) {
        ev_unwatch(sv->loop, sv->lfd);
        close(sv->lfd);
        sv->lfd = -1;
    }
    if (sv->http_lfd >= 0) {
        ev_unwatch(sv->loop, sv->http_lfd);
        close(sv->http_lfd);
        sv->http_lfd = -1;
    }
    rt_drop_requests(sv->rt);
    srv_lobby_free(sv); /* silent connections have nothing in flight */
    for (int i = 0; i < sv->nslots; i++) {
        sess *s = sv->sessions[i];
        if (!s || s->dead) continue;
        s->stream = 0;
        ev_timer_stop(sv->loop, &s->fps_timer);
        /* SHUTTING_DOWN goes after the answers already queued (the frames in flight are
         * finished and sent first), then the connection closes. */
        srv_answer_and_close(sv, s, 0, PROTO_E_SHUTTING_DOWN,
                         "the server is shutting down; reconnect later");
        if (!s->dead) snprintf(s->close_reason, sizeof s->close_reason, "server shutting down");
    }
    ev_timer_start(sv->loop, &sv->stop_timer, (uint64_t)sv->o.shutdown_ms, on_stop_deadline, sv);
}

static void on_signal(ev_loop *l, int fd, int mask, void *data)
{
    (void)l; (void)mask;
    srv *sv = data;
    struct signalfd_siginfo si;
    while (read(fd, &si, sizeof si) == (ssize_t)sizeof si)
        begin_shutdown(sv, si.ssi_signo == SIGINT ? "SIGINT" : "SIGTERM");
}

static void before_sleep(ev_loop *l, void *data)
{
    srv *sv = data;
    free_dead(sv);
    if (sv->stopping && sv->nsess == 0 && !rt_busy(sv->rt)) ev_stop(l);
}

static void on_wakeup(ev_loop *l, void *data)
{
    (void)l;
    srv_on_worker_events(data);
}

/* ---- start-up ---- */

static int write_port_file(const char *path, int port, int http_port)
{
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "w");
    if (!f) return -1;
    fprintf(f, "%d\n", port);
    if (http_port) fprintf(f, "%d\n", http_port);
    if (fclose(f) != 0 || rename(tmp, path) != 0) {
        unlink(tmp);
        return -1;
    }
    return 0;
}

/* start_http: the browser listener (--http): its embedded files, its WebSocket limits and
 * its socket. Returns 0, or 1 after printing why. */
static int start_http(srv *sv)
{
    sd_err err = {0};
    ws_file *files = sv->http_files;
    int n = 0;
    for (int i = 0; i < pages_embedded_count && n < SRV_HTTP_FILES; i++) {
        const page_src *p = &pages_embedded[i];
        const char *dot = strrchr(p->name, '.');
        ws_file *f = &files[n++];
        f->body = p->text;
        f->len = strlen(p->text);
        f->type = !dot ? "application/octet-stream"
                : !strcmp(dot, ".html") ? "text/html; charset=utf-8"
                : !strcmp(dot, ".js") ? "text/javascript; charset=utf-8"
                : !strcmp(dot, ".css") ? "text/css; charset=utf-8" : "application/octet-stream";
        /* viewer.html is the page at /; the others keep their names. */
        snprintf(sv->http_paths[n - 1], sizeof sv->http_paths[n - 1], "/%s",
                 !strcmp(p->name, "viewer.html") ? "" : p->name);
        f->path = sv->http_paths[n - 1];
    }
    sv->http_cfg = (ws_conn_cfg){
        .files = files, .nfiles = n, .ws_path = "/ws",
        /* Without a token, only loopback names in Host: a DNS-rebound name is refused. */
        .loopback_hosts_only = sv->token.len == 0,
        .https = sv->tls != NULL,
        /* One WebSocket message carries one protocol message: header + the largest request. */
        .max_message = PROTO_HEADER_LEN + PROTO_MAX_REQUEST,
    };
    if (net_listen(sv->o.http_host, sv->o.http_port, 128, &sv->http_lfd, &sv->http_bound_port,
                   &err) != 0 ||
        ev_watch(sv->loop, sv->http_lfd, EV_READ, on_accept_http, sv, &err) != 0) {
        fprintf(stderr, "splatd: --http: %s\n", err.msg);
        return 1;
    }
    return 0;
}

/* check_exposure: the rule for every listener: beyond loopback only with a token of at least
 * SRV_TOKEN_MIN bytes. Returns 0, or 1 after printing why (doing, verb: the
 * listener's activity, in two forms, for the message). */
static int check_exposure(const srv *sv, const char *host, const char *doing,
                          const char *verb)
{
    if (sv->o.token_file && !net_host_is_loopback(host) && sv->token.len < SRV_TOKEN_MIN) {
        /* Beyond loopback the token is all that stands between the network and the data, and
         * the delay per failure only slows guessing down: a short token would not last. */
        fprintf(stderr,
                "splatd: the token in %s is %zu bytes; %s on %s (not loopback) needs at "
                "least %d (head -c 32 /dev/urandom | base64 > F)\n", sv->o.token_file,
                sv->token.len, doing, host, SRV_TOKEN_MIN);
        return 1;
    }
    if (!sv->o.token_file && !net_host_is_loopback(host)) {
        fprintf(stderr,
                "splatd: refusing to %s on %s without authentication: anyone who can reach "
                "it could read your data. Use --token-file F (mode 0600), or listen on "
                "127.0.0.1.\n", verb, host);
        return 1;
    }
    return 0;
}

int srv_core_start(srv *sv, sd_err *err)
{
    struct rlimit rl;
    int max_fds = 4096;
    if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY && rl.rlim_cur < 65536)
        max_fds = (int)rl.rlim_cur > max_fds ? (int)rl.rlim_cur : max_fds;
    sv->loop = ev_create(max_fds, err);
    if (!sv->loop) return SD_EIO;
    /* Authenticated and unauthenticated connections have separate caps, so the table holds
     * both; ids keep the slot in 16 bits (8192 at most here). */
    sv->nslots = sv->o.max_clients + sv->o.max_unauth;
    if (!sv->o.max_per_addr) sv->o.max_per_addr = srv_per_addr_default(sv->o.max_clients);
    sv->lim = (sess_limits){.idle_ms = (uint32_t)sv->o.idle_ms, .read_ms = (uint32_t)sv->o.read_ms,
                            .write_ms = (uint32_t)sv->o.write_ms};
    sv->sessions = calloc((size_t)sv->nslots, sizeof *sv->sessions);
    sv->gens = calloc((size_t)sv->nslots, sizeof *sv->gens);
    sv->pre = calloc((size_t)sv->nslots, sizeof *sv->pre);
    long lc = (long)sv->o.max_unauth * SRV_LOBBY_PER_UNAUTH;
    sv->nlobby_cap = lc < 64 ? 64 : lc > 4096 ? 4096 : (int)lc;
    sv->lobby = calloc((size_t)sv->nlobby_cap, sizeof *sv->lobby);
    if (!sv->sessions || !sv->gens || !sv->pre || !sv->lobby)
        return sd_errf(err, SD_ENOMEM, "out of memory");
    for (int i = 0; i < sv->nlobby_cap; i++) sv->lobby[i].fd = -1;
    ev_timer_init(&sv->lobby_timer);
    if (!sv->max_w) sv->max_w = 8192;
    if (!sv->max_h) sv->max_h = 8192;
    rt_desc rd = {
        .rnd = {.backend = sv->o.backend, .shader_dir = sv->o.shader_dir,
                .max_width = sv->max_w, .max_height = sv->max_h, .gpu_memory = sv->o.gpu_memory,
                .lod_uploads = sv->o.lod_uploads},
        .max_clients = sv->nslots, .cache_dir = sv->o.cache_dir,
        /* splatd --mpi partitions flat clouds across the ranks; the LOD form is rank 0's own */
        .lod_mode = sv->hooks ? LOD_NEVER : sv->o.lod_mode, .prep_memory = sv->o.prep_memory,
        .frame_budget = sv->o.max_frame_bytes,
        .preview_points = sv->hooks ? 0 : sv->o.preview_points,
        .pack = srv_pack_frame, .pack_user = sv, .hooks = sv->hooks,
    };
    sd_err rerr = {0};
    sv->rt = rt_create(&rd, sv->loop, &rerr);
    if (!sv->rt) return sd_errf(err, rerr.code ? rerr.code : SD_EIO, "cannot start the renderer: %s", rerr.msg);
    ev_set_before_sleep(sv->loop, before_sleep, sv);
    ev_set_wakeup(sv->loop, on_wakeup, sv);
    ev_timer_init(&sv->stop_timer);
    return 0;
}

/* start: everything before the loop runs. Returns 0, or 1 after printing why. */
static int start(srv *sv)
{
    sd_err err = {0};
    if (dd_check_dir(sv->o.data_dir, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    if (sv->o.token_file && auth_token_load(sv->o.token_file, &sv->token, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    if (check_exposure(sv, sv->o.host, "listening", "listen") != 0 ||
        (sv->o.http_host[0] &&
         check_exposure(sv, sv->o.http_host, "serving HTTP", "serve HTTP") != 0))
        return 1;
    if (!sv->o.tls_cert != !sv->o.tls_key) {
        fprintf(stderr, "splatd: --tls-cert and --tls-key go together (given: only %s)\n",
                sv->o.tls_cert ? "--tls-cert" : "--tls-key");
        return 1;
    }
    /* Without TLS, anyone on the path reads the frames and cloud names and can take over
     * an authenticated connection: beyond loopback it is not an option, on either listener. */
    for (int l = 0; l < 2 && !sv->o.tls_cert; l++) {
        const char *h = l ? sv->o.http_host : sv->o.host;
        if (!h[0] || net_host_is_loopback(h)) continue;
        fprintf(stderr,
                "splatd: refusing to %s on %s without TLS: beyond loopback the frames, cloud "
                "names and the session itself would travel in the clear. Give --tls-cert F and "
                "--tls-key F (and --token-file F), or %s on 127.0.0.1.\n",
                l ? "serve HTTP" : "listen", h, l ? "serve HTTP" : "listen");
        return 1;
    }
    struct stat kst;
    if (sv->o.tls_key && stat(sv->o.tls_key, &kst) == 0 && (kst.st_mode & (S_IRWXG | S_IRWXO))) {
        fprintf(stderr, "splatd: --tls-key %s has mode %04o: a private key must not be "
                "accessible to group or others (chmod 600 %s)\n", sv->o.tls_key,
                (unsigned)(kst.st_mode & 07777), sv->o.tls_key);
        return 1;
    }
    if (sv->o.tls_cert && tls_server_new(sv->o.tls_cert, sv->o.tls_key, &sv->tls, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    /* Temporary files of cache writes interrupted by a crash or kill -9 (the O_EXCL fallback
     * where O_TMPFILE is missing) are removed before anything is prepared. */
    char cdir[PATH_MAX];
    int swept = 0;
    if (cache_dir_for(sv->o.cache_dir, cdir, sizeof cdir) == 0) cache_sweep(cdir, &swept);
    if (swept) srv_log(sv, NULL, "removed %d temporary file(s) of interrupted cache writes from %s",
                       swept, cdir);
    /* Block the stop signals before any thread starts, so only the signalfd sees them. */
    sigset_t ss;
    sigemptyset(&ss);
    sigaddset(&ss, SIGTERM);
    sigaddset(&ss, SIGINT);
    pthread_sigmask(SIG_BLOCK, &ss, NULL);
    signal(SIGPIPE, SIG_IGN);
    sv->sigfd = signalfd(-1, &ss, SFD_NONBLOCK | SFD_CLOEXEC);
    if (sv->sigfd < 0) {
        fprintf(stderr, "splatd: signalfd: %s\n", strerror(errno));
        return 1;
    }
    if (srv_core_start(sv, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    srv_log(sv, NULL, "renderer: %s (%s); cloud buffers held to %llu MiB of GPU memory, frames "
            "to %llu MiB (--max-frame-bytes)", rt_renderer_string(sv->rt), rt_backend_name(sv->rt),
            (unsigned long long)(rt_gpu_budget(sv->rt) >> 20),
            (unsigned long long)(rt_frame_budget(sv->rt) >> 20));
    for (int i = 0; i < sv->o.npreload; i++) {
        if (srv_preload(sv, sv->o.preload[i], &err) != 0) {
            fprintf(stderr, "splatd: --preload %s: %s\n", sv->o.preload[i], err.msg);
            return 1;
        }
        srv_log(sv, NULL, "preloading %s", sv->o.preload[i]);
    }
    if (net_listen(sv->o.host, sv->o.port, 128, &sv->lfd, &sv->bound_port, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    if (ev_watch(sv->loop, sv->lfd, EV_READ, on_accept, sv, &err) != 0 ||
        ev_watch(sv->loop, sv->sigfd, EV_READ, on_signal, sv, &err) != 0) {
        fprintf(stderr, "splatd: %s\n", err.msg);
        return 1;
    }
    if (sv->o.http_host[0] && start_http(sv) != 0) return 1;
    int v6 = strchr(sv->o.host, ':') != NULL;
    fprintf(stderr, "listening on %s%s%s:%d\n", v6 ? "[" : "", sv->o.host, v6 ? "]" : "", sv->bound_port);
    fflush(stderr);
    if (sv->http_lfd >= 0) {
        v6 = strchr(sv->o.http_host, ':') != NULL;
        fprintf(stderr, "http on %s://%s%s%s:%d/\n", sv->tls ? "https" : "http",
                v6 ? "[" : "", sv->o.http_host, v6 ? "]" : "", sv->http_bound_port);
        fflush(stderr);
    }
    if (sv->o.port_file &&
        write_port_file(sv->o.port_file, sv->bound_port, sv->http_bound_port) != 0) {
        fprintf(stderr, "splatd: cannot write the port file %s: %s\n", sv->o.port_file, strerror(errno));
        return 1;
    }
    srv_log(sv, NULL, "at most %d clients (--max-clients), %d connections not yet authenticated "
            "(--max-unauth), %d connections from one address (--max-per-addr)",
            sv->o.max_clients, sv->o.max_unauth, sv->o.max_per_addr);
    if (sv->token.len) srv_log(sv, NULL, "clients must authenticate (token from %s)", sv->o.token_file);
    if (sv->tls) srv_log(sv, NULL, "TLS only, certificate %s", tls_server_subject(sv->tls));
    return 0;
}

/* srv_teardown (srv.h): closes every session and frees everything, except when a cloud preparation is
 * still running (see rt_stop_for_exit): then the workers' context and the loop stay as they
 * are, and the process exits without waiting for it. */
int srv_teardown(srv *sv)
{
    for (int i = 0; sv->sessions && i < sv->nslots; i++)
        if (sv->sessions[i] && !sv->sessions[i]->dead) sess_close(sv->sessions[i], "server stopped");
    if (sv->sessions) free_dead(sv);
    if (rt_stop_for_exit(sv->rt)) {
        srv_log(sv, NULL, "a cloud is still being prepared; exiting without waiting for it");
        return 1;
    }
    if (sv->loop) srv_lobby_free(sv);
    if (sv->lfd >= 0) close(sv->lfd);
    if (sv->http_lfd >= 0) close(sv->http_lfd);
    if (sv->sigfd >= 0) close(sv->sigfd);
    ev_destroy(sv->loop);
    for (int i = 0; i < sv->nclouds; i++) free(sv->clouds[i].waiters);
    free(sv->clouds);
    free(sv->sessions);
    free(sv->gens);
    free(sv->pre);
    memset(&sv->token, 0, sizeof sv->token);
    tls_server_free(sv->tls);
    sv->tls = NULL;
    return 0;
}

int cmd_daemon(int argc, char **argv)
{
    return daemon_run(argc, argv, NULL);
}

int daemon_run(int argc, char **argv, const rt_hooks *hooks)
{
    srv sv = {.lfd = -1, .sigfd = -1, .http_lfd = -1, .hooks = hooks};
    int rc = parse_opts(argc, argv, &sv.o);
    if (rc != 0) return rc > 0 ? 0 : 2;
    rc = start(&sv);
    int ran = rc == 0;
    if (ran && ev_run(sv.loop) != 0) {
        srv_log(&sv, NULL, "event loop failed: %s", strerror(errno));
        rc = 1;
    }
    int abandoned = srv_teardown(&sv);
    if (ran && rc == 0) srv_log(&sv, NULL, "stopped");
    if (abandoned) {
        /* The prep thread is still running: leave at once, without exit()'s library
         * destructors (FLANN is C++) running under its feet. */
        fflush(NULL);
        _exit(rc);
    }
    return rc;
}
