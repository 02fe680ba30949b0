/* admit.c — who gets a connection: the caps (--max-per-addr, --max-clients, --max-unauth)
 * applied to each accepted socket, and what happens when the pool of connections not yet
 * authenticated is full.
 *
 * The policy. A full pool is what a flood of sockets that connect and say nothing looks like.
 * Refusing every newcomer then would lock everyone out until the handshake deadline; closing
 * the oldest of the pool for each newcomer (what splatd did) lets a fast flood push out a
 * client in the middle of its TLS handshake, since a client needs a moment after connecting
 * before its first bytes arrive, and a flood of newcomers is faster. Every client of splatd
 * speaks first (a HELLO, a TLS ClientHello, an HTTP request), so, as nginx's `listen
 * ... deferred` (TCP_DEFER_ACCEPT) has the kernel hold a connection until its first data, a
 * newcomer that finds the pool full waits in the lobby until it speaks:
 *
 *   lobby    a silent newcomer's socket, watched for its first bytes, costing an fd and a few
 *            bytes (no session, no buffers, no TLS state): SRV_LOBBY_PER_UNAUTH x --max-unauth
 *            of them (1024 by default). The first bytes take it to the pool as a newcomer
 *            that has spoken (below); a lobby socket still silent at --handshake-timeout is closed,
 *            and a full lobby closes its oldest.
 *
 * A newcomer that has spoken (bytes waiting in its socket) takes the place of one of the pool,
 * chosen by what each has sent:
 *
 *   quiet    nothing received for SRV_QUIET_MS: since it connected (it never spoke), or since
 *            its last bytes (it stalled). Goes first.
 *   young    connected less than SRV_QUIET_MS ago and has sent nothing yet (bytes waiting in
 *            its socket, not read by the loop yet, count as sent). Goes next.
 *   spoken   bytes within SRV_QUIET_MS: a client in its TLS handshake, HELLO or proof, or one
 *            trickling bytes. The one connected the longest goes: a handshake takes a few
 *            round trips, so a client in the middle of one is among the newest, and a
 *            connection still unauthenticated long after connecting is not making progress.
 *   kept     a wrong proof waiting for its delayed answer (srv_auth_failed): never closed, so
 *            that a flood cannot learn failures faster than the delay allows; with only such
 *            connections in the pool the newcomer is refused (BUSY).
 *
 * Within a kind, fairness across addresses comes first: the connection whose address holds
 * the most of the pool goes first (the newcomer counted with its own address), so a flood from
 * few addresses pays before anyone else. A silent flood thus never reaches the pool once it is
 * full, and a client that speaks displaces silent connections before any that has spoken; a
 * flood that speaks too displaces the oldest of the pool first, not the client that connected
 * last. --max-per-addr counts an address's lobby sockets with its sessions. Event-loop thread
 * only. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include "srv.h"

void srv_addr_host(const char *addr, char *out, size_t len)
{
    const char *colon = strrchr(addr, ':');
    size_t n = colon ? (size_t)(colon - addr) : strlen(addr);
    if (n >= 2 && addr[0] == '[' && addr[n - 1] == ']') {
        addr++;
        n -= 2;
    }
    if (n >= len) n = len - 1;
    memcpy(out, addr, n);
    out[n] = 0;
}

/* has_input: 1 when bytes wait unread in socket fd. */
static int has_input(int fd)
{
    int n = 0;
    return ioctl(fd, FIONREAD, &n) == 0 && n > 0;
}

/* census: the live sessions past and before authentication, and the connections (sessions and
 * lobby sockets) from host (NULL: not counted). One pass over the tables: O(slots + lobby) per
 * accepted connection, simpler than counts kept in step with every state change. */
static void census(const srv *sv, const char *host, int *authed, int *unauth, int *from_host)
{
    char h[NET_ADDR_LEN];
    *authed = *unauth = *from_host = 0;
    for (int i = 0; i < sv->nslots; i++) {
        sess *s = sv->sessions[i];
        if (!s || s->dead) continue;
        if (s->authed) ++*authed;
        else ++*unauth;
        if (host) {
            srv_addr_host(s->addr, h, sizeof h);
            *from_host += !strcmp(h, host);
        }
    }
    for (int i = 0; host && i < sv->nlobby_cap; i++) {
        if (sv->lobby[i].fd < 0) continue;
        srv_addr_host(sv->lobby[i].addr, h, sizeof h);
        *from_host += !strcmp(h, host);
    }
}

/* ---- the pool: who makes room for a newcomer that has spoken ---- */

enum { PRE_QUIET, PRE_YOUNG, PRE_SPOKEN, PRE_KEPT };

/* weigh: p's kind and quiet time (ms) at now; a session with bytes waiting in its socket is
 * taken as having spoken now. */
static void weigh(srv_pre *p, uint64_t now)
{
    sess *s = p->s;
    if (!s->last_in_ms && has_input(s->fd)) s->last_in_ms = now;
    p->quiet = now - (s->last_in_ms ? s->last_in_ms : s->t_connect_ms);
    if (s->auth_failing) p->kind = PRE_KEPT;
    else if (p->quiet >= SRV_QUIET_MS) p->kind = PRE_QUIET;
    else p->kind = s->last_in_ms ? PRE_SPOKEN : PRE_YOUNG;
}

static int by_host(const void *a, const void *b)
{
    return strcmp(((const srv_pre *)a)->host, ((const srv_pre *)b)->host);
}

/* worse: whether pool entry a should make room before b (same kind): the address holding more
 * of the pool; then, quiet ones, the longer quiet; then the one connected first. */
static int worse(const srv_pre *a, const srv_pre *b)
{
    if (a->count != b->count) return a->count > b->count;
    if (a->kind == PRE_QUIET && a->quiet != b->quiet) return a->quiet > b->quiet;
    return a->s->t_connect_ms != b->s->t_connect_ms ? a->s->t_connect_ms < b->s->t_connect_ms
                                                    : a->s->id < b->s->id;
}

/* give_way: the session of the pool that makes room for a newcomer from host, or NULL when
 * every one is kept. */
static const srv_pre *give_way(srv *sv, const char *host, uint64_t now)
{
    int n = 0;
    for (int i = 0; i < sv->nslots; i++) {
        sess *s = sv->sessions[i];
        if (!s || s->dead || s->authed) continue;
        srv_pre *p = &sv->pre[n++];
        p->s = s;
        srv_addr_host(s->addr, p->host, sizeof p->host);
    }
    /* Per-address counts: sorted by address, each run's length (the newcomer's own included). */
    qsort(sv->pre, (size_t)n, sizeof *sv->pre, by_host);
    for (int i = 0; i < n;) {
        int j = i;
        while (j < n && !strcmp(sv->pre[j].host, sv->pre[i].host)) j++;
        int own = !strcmp(sv->pre[i].host, host);
        for (int k = i; k < j; k++) sv->pre[k].count = j - i + own;
        i = j;
    }
    const srv_pre *best = NULL;
    for (int i = 0; i < n; i++) {
        srv_pre *p = &sv->pre[i];
        weigh(p, now);
        if (p->kind == PRE_KEPT) continue;
        if (!best || p->kind < best->kind || (p->kind == best->kind && worse(p, best))) best = p;
    }
    return best;
}

int srv_room(srv *sv, int fd, const char *host, char *why, size_t whylen,
             const char **client_text)
{
    int authed, unauth, from_host;
    census(sv, host, &authed, &unauth, &from_host);
    if (from_host >= sv->o.max_per_addr) {
        snprintf(why, whylen, "%d connections from %s already (--max-per-addr)", from_host, host);
        *client_text = "too many connections from your address; retry later";
        return SD_ELIMIT;
    }
    if (authed >= sv->o.max_clients) {
        snprintf(why, whylen, "%d clients already connected (--max-clients)", authed);
        *client_text = "too many clients; retry later";
        return SD_ELIMIT;
    }
    if (unauth < sv->o.max_unauth) return 0;
    if (!has_input(fd)) return SRV_ROOM_LOBBY;
    const srv_pre *p = give_way(sv, host, ev_now_ms());
    if (!p) {
        snprintf(why, whylen, "%d connections not yet authenticated, each waiting for the "
                 "answer to a wrong proof (--max-unauth)", unauth);
        *client_text = "too many connections in their handshake; retry later";
        return SD_ELIMIT;
    }
    char r[160];
    if (p->kind == PRE_SPOKEN)
        snprintf(r, sizeof r, "unauthenticated %.1f s after connecting, closed for a newer "
                 "connection (--max-unauth)", (double)(ev_now_ms() - p->s->t_connect_ms) / 1e3);
    else
        snprintf(r, sizeof r, "unauthenticated and %s for %llu ms, closed for a newer "
                 "connection (--max-unauth)", p->s->last_in_ms ? "stalled" : "silent",
                 (unsigned long long)p->quiet);
    sess_close(p->s, r);
    return 0;
}

int srv_admit(srv *sv, sess *s, uint32_t seq)
{
    int authed, unauth, from_host;
    census(sv, NULL, &authed, &unauth, &from_host);
    if (authed >= sv->o.max_clients) {
        srv_log(sv, s, "refused: %d clients already connected (--max-clients)", authed);
        srv_answer_and_close(sv, s, seq, PROTO_E_BUSY, "too many clients; retry later");
        return 0;
    }
    sess_set_authed(s);
    return 1;
}

/* ---- the lobby: silent newcomers while the pool is full ---- */

static void lobby_drop(srv *sv, srv_lobby_ent *e, int close_fd)
{
    ev_unwatch(sv->loop, e->fd);
    if (close_fd) close(e->fd);
    e->fd = -1;
    sv->nlobby--;
    if (!sv->nlobby) ev_timer_stop(sv->loop, &sv->lobby_timer);
}

/* on_lobby_io: a lobby socket is readable: its first bytes (it goes to the pool as a newcomer
 * that has spoken), or its end. */
static void on_lobby_io(ev_loop *l, int fd, int mask, void *data)
{
    (void)l; (void)mask;
    srv_lobby_ent *e = data;
    srv *sv = e->sv;
    char addr[NET_ADDR_LEN];
    snprintf(addr, sizeof addr, "%s", e->addr);
    int http = e->http;
    lobby_drop(sv, e, 0);
    if (!has_input(fd)) { /* closed (or failed) without a word */
        close(fd);
        return;
    }
    srv_adopt_conn(sv, fd, addr, http);
}

/* on_lobby_timer: closes lobby sockets silent for --handshake-timeout; runs while the lobby
 * holds any. */
static void on_lobby_timer(ev_loop *l, ev_timer *t, void *data)
{
    srv *sv = data;
    uint64_t now = ev_now_ms();
    for (int i = 0; i < sv->nlobby_cap; i++) {
        srv_lobby_ent *e = &sv->lobby[i];
        if (e->fd >= 0 && now - e->t_ms >= (uint64_t)sv->o.handshake_ms) lobby_drop(sv, e, 1);
    }
    if (sv->nlobby) ev_timer_start(l, t, SRV_LOBBY_SWEEP_MS, on_lobby_timer, sv);
}

void srv_lobby_hold(srv *sv, int fd, const char *addr, int http)
{
    srv_lobby_ent *slot = NULL, *oldest = NULL;
    for (int i = 0; i < sv->nlobby_cap; i++) {
        srv_lobby_ent *e = &sv->lobby[i];
        if (e->fd < 0) {
            if (!slot) slot = e;
        } else if (!oldest || e->t_ms < oldest->t_ms) {
            oldest = e;
        }
    }
    if (!slot && oldest) { /* full: the one silent the longest goes */
        lobby_drop(sv, oldest, 1);
        slot = oldest;
    }
    if (!slot) {
        close(fd);
        return;
    }
    *slot = (srv_lobby_ent){.sv = sv, .fd = fd, .http = http, .t_ms = ev_now_ms()};
    snprintf(slot->addr, sizeof slot->addr, "%s", addr);
    if (ev_watch(sv->loop, fd, EV_READ, on_lobby_io, slot, NULL) != 0) {
        slot->fd = -1;
        close(fd);
        return;
    }
    if (!sv->nlobby++)
        ev_timer_start(sv->loop, &sv->lobby_timer, SRV_LOBBY_SWEEP_MS, on_lobby_timer, sv);
}

void srv_lobby_free(srv *sv)
{
    for (int i = 0; sv->lobby && i < sv->nlobby_cap; i++)
        if (sv->lobby[i].fd >= 0) lobby_drop(sv, &sv->lobby[i], 1);
    free(sv->lobby);
    sv->lobby = NULL;
    sv->nlobby_cap = 0;
}
