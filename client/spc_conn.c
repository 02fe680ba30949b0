/* spc_conn.c — libsplatclient's connection layer: connect, version negotiation and
 * authentication, blocking send/receive with deadlines, error bookkeeping (see
 * spc_internal.h and splat_client.h). */
#include "spc_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* The public codes are the negated wire codes: checked here, once. */
#define SPC_CHECK_(name, val, fatal, text) \
    _Static_assert(SPC_E_##name == -(val), "SPC_E_" #name " must equal -PROTO_E_" #name);
PROTO_ERRORS(SPC_CHECK_)
#undef SPC_CHECK_

const char *spc_strerror(int code) { return proto_err_name(code); }

int spc_error_fatal(int code) { return proto_err_fatal(code); }

uint64_t spc__now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

uint64_t spc__deadline(const spc_client *c)
{
    if (c->timeout_ms < 0) return UINT64_MAX;
    return spc__now_us() + (uint64_t)c->timeout_ms * 1000u;
}

uint32_t spc__next_seq(spc_client *c)
{
    if (++c->seq == 0) c->seq = 1;
    return c->seq;
}

static void close_fd(spc_client *c)
{
    spc__tls_end(c, 0);
    if (c->fd >= 0) close(c->fd);
    c->fd = -1;
}

int spc__fail(spc_client *c, int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->errmsg, sizeof c->errmsg, fmt, ap);
    va_end(ap);
    if (proto_err_fatal(code)) close_fd(c);
    return code;
}

int spc__buffered(const spc_client *c) { return c->rpos < c->rlen || spc__tls_pending(c); }

int spc__wait_fd(spc_client *c, short ev, uint64_t deadline)
{
    for (;;) {
        int ms = -1;
        if (deadline != UINT64_MAX) {
            uint64_t now = spc__now_us();
            if (now >= deadline)
                return spc__fail(c, SPC_E_TIMEOUT, "no %s from the server within the timeout "
                                 "of %d ms", ev == POLLIN ? "answer" : "progress sending",
                                 c->timeout_ms);
            ms = (int)((deadline - now + 999) / 1000);
        }
        struct pollfd p = {c->fd, ev, 0};
        int rc = poll(&p, 1, ms);
        if (rc > 0) return 0;
        if (rc < 0 && errno != EINTR)
            return spc__fail(c, SPC_E_IO, "poll on the connection failed: %s", strerror(errno));
    }
}

int spc__flush(spc_client *c, uint64_t deadline)
{
    if (c->fd < 0) {
        c->out.len = 0;
        return spc__fail(c, SPC_E_CLOSED, "the connection is closed");
    }
    size_t off = 0;
    while (off < c->out.len) {
        if (c->ssl) {
            size_t done = 0;
            short ev = POLLOUT;
            int t = spc__tls_io(c, 1, c->out.data + off, c->out.len - off, &done, &ev);
            if (t < 0 || t == 2) {
                c->out.len = 0;
                return t < 0 ? t : spc__fail(c, SPC_E_CLOSED, "the server closed the connection");
            }
            if (t == 1 && (t = spc__wait_fd(c, ev, deadline)) < 0) return t;
            off += done;
            continue;
        }
        ssize_t n = send(c->fd, c->out.data + off, c->out.len - off, MSG_NOSIGNAL);
        if (n > 0) {
            off += (size_t)n;
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) {
            int rc = spc__wait_fd(c, POLLOUT, deadline);
            if (rc < 0) return rc;
            continue;
        }
        c->out.len = 0;
        return spc__fail(c, SPC_E_IO, "sending to the server failed: %s",
                         n < 0 ? strerror(errno) : "no progress");
    }
    c->out.len = 0;
    return 0;
}

int spc__recv(spc_client *c, proto_msg *m, uint64_t deadline)
{
    for (;;) {
        if (c->fd < 0) return spc__fail(c, SPC_E_CLOSED, "the connection is closed");
        if (c->rpos < c->rlen) {
            size_t used = 0;
            proto_error e = {0};
            int rc = proto_decode(&c->dec, c->rbuf + c->rpos, c->rlen - c->rpos, &used, m, &e);
            c->rpos += used;
            if (rc == PROTO_ONE_MSG) return 0;
            if (rc < 0) return spc__fail(c, -e.code ? -e.code : SPC_E_MALFORMED,
                                         "bad message from the server: %s", e.msg);
            /* NEED_MORE: everything was consumed */
        }
        c->rpos = c->rlen = 0;
        if (c->ssl) {
            size_t done = 0;
            short ev = POLLIN;
            int t = spc__tls_io(c, 0, c->rbuf, sizeof c->rbuf, &done, &ev);
            if (t < 0) return t;
            if (t == 2) return spc__fail(c, SPC_E_CLOSED, "the server closed the connection");
            if (t == 1 && (t = spc__wait_fd(c, ev, deadline)) < 0) return t;
            c->rlen = done;
            continue;
        }
        ssize_t n = recv(c->fd, c->rbuf, sizeof c->rbuf, 0);
        if (n > 0) {
            c->rlen = (size_t)n;
            continue;
        }
        if (n == 0)
            return spc__fail(c, SPC_E_CLOSED, "the server closed the connection");
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
            int rc = spc__wait_fd(c, POLLIN, deadline);
            if (rc < 0) return rc;
            continue;
        }
        return spc__fail(c, SPC_E_IO, "receiving from the server failed: %s", strerror(errno));
    }
}

int spc__server_error(spc_client *c, const proto_msg *m)
{
    proto_errmsg em;
    proto_error e = {0};
    c->errseq = m->h.seq;
    if (proto_parse_error(m->payload, m->len, &em, &e) < 0)
        return spc__fail(c, -e.code, "unreadable ERROR from the server: %s", e.msg);
    int code = em.code >= 1 && em.code < 100 ? -(int)em.code : SPC_E_INTERNAL;
    const char *name = proto_err_name((int)em.code);
    /* A server that follows PROTOCOL.md has closed after a fatal code; so do we. */
    return spc__fail(c, code, "server error %s (code %u, request %u): %s", name, em.code,
                     m->h.seq, em.text[0] ? em.text : proto_err_text((int)em.code));
}

int spc__wait(spc_client *c, uint32_t seq, unsigned type, proto_msg *m, spc_progress_fn progress,
              void *user)
{
    uint64_t deadline = spc__deadline(c);
    for (;;) {
        int rc = spc__recv(c, m, deadline);
        if (rc < 0) return rc;
        if (m->h.type == PROTO_MSG_ERROR) return spc__server_error(c, m);
        if (m->h.type == PROTO_MSG_PROGRESS && m->h.seq == seq) {
            proto_progress p;
            proto_error e = {0};
            if (proto_parse_progress(m->payload, m->len, &p, &e) < 0)
                return spc__fail(c, -e.code, "bad PROGRESS from the server: %s", e.msg);
            if (progress) progress(user, proto_phase_name(p.phase), p.fraction, p.text);
            deadline = spc__deadline(c);
            continue;
        }
        if (m->h.type == type && m->h.seq == seq) return 0;
        spc__note(c, m);
        /* anything else (a streamed frame, the answer to a request nobody waits for) is
         * skipped: the protocol answers in order, so what we wait for comes later */
    }
}

int spc__read_token(const char *path, uint8_t *buf, size_t cap, char *err, size_t errlen)
{
    /* O_NONBLOCK: a FIFO in the token's place must not block; it is refused below */
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        snprintf(err, errlen, "cannot open token file %s: %s", path, strerror(errno));
        return SPC_E_TOKEN;
    }
    struct stat st;
    int rc = SPC_E_TOKEN;
    if (fstat(fd, &st) < 0) {
        snprintf(err, errlen, "cannot stat token file %s: %s", path, strerror(errno));
    } else if (!S_ISREG(st.st_mode)) {
        snprintf(err, errlen, "token file %s is not a regular file", path);
    } else if (st.st_mode & (S_IRWXG | S_IRWXO)) {
        snprintf(err, errlen, "token file %s has mode %04o: a shared secret must not be "
                 "accessible to group or others (chmod 600 %s)", path,
                 (unsigned)(st.st_mode & 07777), path);
    } else {
        /* the daemon's rule (auth.h): at most cap + 2 bytes (a token and its line end), less
         * the trailing CR and LF; the bytes past cap go to tail */
        uint8_t tail[3];
        size_t n = 0;
        int ok = 1;
        while (n < cap + sizeof tail) {
            ssize_t k = n < cap ? read(fd, buf + n, cap - n)
                                : read(fd, tail + (n - cap), cap + sizeof tail - n);
            if (k < 0 && errno == EINTR) continue;
            if (k < 0) {
                snprintf(err, errlen, "cannot read token file %s: %s", path, strerror(errno));
                ok = 0;
                break;
            }
            if (k == 0) break;
            n += (size_t)k;
        }
        if (ok && n == cap + sizeof tail) {
            snprintf(err, errlen, "token file %s holds more than %zu bytes (a token of at most "
                     "%zu and its line end)", path, cap + 2, cap);
            ok = 0;
        }
#define TOKEN_BYTE(i) ((i) < cap ? buf[i] : tail[(i) - cap])
        while (ok && n > 0 && (TOKEN_BYTE(n - 1) == '\n' || TOKEN_BYTE(n - 1) == '\r')) n--;
#undef TOKEN_BYTE
        if (ok && n > cap)
            snprintf(err, errlen, "token file %s: the token is longer than %zu bytes", path, cap);
        else if (ok && n == 0)
            snprintf(err, errlen, "token file %s is empty", path);
        else if (ok)
            rc = (int)n;
        memset(tail, 0, sizeof tail);
    }
    close(fd);
    return rc;
}

/* tcp_connect: a connected, non-blocking TCP socket with TCP_NODELAY, or -1 with err. */
static int tcp_connect(const char *host, int port, int timeout_ms, char *err, size_t errlen)
{
    char ps[16];
    snprintf(ps, sizeof ps, "%d", port);
    struct addrinfo hints = {0}, *res = NULL;
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_NUMERICSERV;
    int g = getaddrinfo(host, ps, &hints, &res);
    if (g != 0) {
        snprintf(err, errlen, "cannot resolve %s: %s", host, gai_strerror(g));
        return -1;
    }
    int fd = -1;
    snprintf(err, errlen, "cannot connect to %s:%d", host, port);
    for (struct addrinfo *a = res; a; a = a->ai_next) {
        fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, a->ai_protocol);
        if (fd < 0) continue;
        int rc = connect(fd, a->ai_addr, a->ai_addrlen);
        if (rc < 0 && errno == EINPROGRESS) {
            struct pollfd p = {fd, POLLOUT, 0};
            int pr;
            do pr = poll(&p, 1, timeout_ms < 0 ? -1 : timeout_ms);
            while (pr < 0 && errno == EINTR);
            int soerr = 0;
            socklen_t sl = sizeof soerr;
            if (pr == 0) {
                errno = ETIMEDOUT;
            } else if (pr > 0 && getsockopt(fd, SOL_SOCKET, SO_ERROR, &soerr, &sl) == 0) {
                errno = soerr;
                if (soerr == 0) rc = 0;
            }
        }
        if (rc == 0) {
            int one = 1;
            setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
            break;
        }
        snprintf(err, errlen, "cannot connect to %s:%d: %s", host, port, strerror(errno));
        close(fd);
        fd = -1;
    }
    freeaddrinfo(res);
    return fd;
}

/* hello: sends HELLO (with proof when given) and waits for WELCOME into *w. */
static int hello(spc_client *c, const char *name, const uint8_t *proof, proto_welcome *w)
{
    proto_hello h = {.min_version = PROTO_VERSION_MIN, .max_version = PROTO_VERSION_MAX};
    snprintf(h.client, sizeof h.client, "%s", name);
    if (proof) {
        h.proof_len = PROTO_AUTH_LEN;
        memcpy(h.proof, proof, PROTO_AUTH_LEN);
    }
    uint32_t seq = spc__next_seq(c);
    if (proto_enc_hello(&c->out, seq, &h) < 0)
        return spc__fail(c, SPC_E_NOMEM, "cannot encode HELLO");
    int rc = spc__flush(c, spc__deadline(c));
    if (rc < 0) return rc;
    proto_msg m;
    rc = spc__wait(c, seq, PROTO_MSG_WELCOME, &m, NULL, NULL);
    if (rc < 0) return rc;
    proto_error e = {0};
    if (proto_parse_welcome(m.payload, m.len, w, &e) < 0)
        return spc__fail(c, -e.code, "bad WELCOME from the server: %s", e.msg);
    if (w->version < PROTO_VERSION_MIN || w->version > PROTO_VERSION_MAX)
        return spc__fail(c, SPC_E_BAD_VERSION, "the server chose protocol version %u; this "
                         "client speaks %u to %u", w->version, PROTO_VERSION_MIN,
                         PROTO_VERSION_MAX);
    c->dec.version = w->version;
    c->out.version = w->version;
    return 0;
}

/* handshake: version negotiation, then authentication when the server asks for it. */
static int handshake(spc_client *c, const spc_options *o)
{
    const char *name = o->client_name ? o->client_name : "libsplatclient";
    proto_welcome w;
    int rc = hello(c, name, NULL, &w);
    if (rc < 0) return rc;
    memcpy(c->challenge, w.challenge, PROTO_AUTH_LEN);
    if (w.auth_required && !w.authenticated) {
        if (!o->token_file)
            return spc__fail(c, SPC_E_AUTH_REQUIRED, "the server requires a token: give a "
                             "token file (--token-file)");
        uint8_t tok[4096];
        char err[600];
        int n = spc__read_token(o->token_file, tok, sizeof tok, err, sizeof err);
        if (n < 0) return spc__fail(c, n, "%s", err);
        uint8_t proof[EVP_MAX_MD_SIZE];
        unsigned plen = 0;
        if (!HMAC(EVP_sha256(), tok, n, c->challenge, PROTO_AUTH_LEN, proof, &plen) ||
            plen != PROTO_AUTH_LEN) {
            memset(tok, 0, sizeof tok);
            return spc__fail(c, SPC_E_INTERNAL, "HMAC-SHA256 failed in libcrypto");
        }
        memset(tok, 0, sizeof tok);
        rc = hello(c, name, proof, &w);
        if (rc < 0) return rc;
        if (!w.authenticated)
            return spc__fail(c, SPC_E_AUTH_FAILED, "the server did not accept the token");
    } else if (!w.authenticated) {
        return spc__fail(c, SPC_E_AUTH_FAILED, "the server says neither authenticated nor "
                         "auth required");
    }
    c->server.version = w.version;
    c->server.auth_required = w.auth_required;
    snprintf(c->server.server, sizeof c->server.server, "%s", w.server);
    snprintf(c->server.backend, sizeof c->server.backend, "%s", w.backend);
    snprintf(c->server.renderer, sizeof c->server.renderer, "%s", w.renderer);
    c->server.max_width = w.max_width;
    c->server.max_height = w.max_height;
    return 0;
}

int spc_connect(const spc_options *opt, spc_client **out, char *err, size_t errlen)
{
    spc_options o = {0};
    if (opt) o = *opt;
    if (!o.host) o.host = "127.0.0.1";
    if (!o.port) o.port = SPC_DEFAULT_PORT;
    if (!o.timeout_ms) o.timeout_ms = 30000;
    if (!o.max_frame_bytes) o.max_frame_bytes = PROTO_MAX_FRAME;
    *out = NULL;
    if (o.port < 1 || o.port > 65535) {
        snprintf(err, errlen, "port %d is out of range 1..65535", o.port);
        return SPC_E_INVALID_ARG;
    }
    spc_client *c = calloc(1, sizeof *c);
    if (!c) {
        snprintf(err, errlen, "out of memory");
        return SPC_E_NOMEM;
    }
    c->timeout_ms = o.timeout_ms;
    proto_decoder_init(&c->dec, PROTO_S2C);
    c->dec.max_payload = o.max_frame_bytes;
    sp_params_defaults(&c->params);
    c->fd = tcp_connect(o.host, o.port, o.timeout_ms, err, errlen);
    if (c->fd < 0) {
        spc_close(c);
        return SPC_E_IO;
    }
    int rc = 0;
    if (o.tls || o.tls_ca || o.tls_name)
        rc = spc__tls_start(c, o.host, o.tls_name, o.tls_ca, spc__deadline(c));
    if (rc == 0) rc = handshake(c, &o);
    if (rc < 0) {
        snprintf(err, errlen, "%s:%d: %s", o.host, o.port, c->errmsg);
        spc_close(c);
        return rc;
    }
    *out = c;
    return 0;
}

void spc_close(spc_client *c)
{
    if (!c) return;
    if (c->fd >= 0 && c->server.version) {
        c->out.len = 0;
        if (proto_enc_empty(&c->out, PROTO_MSG_BYE, spc__next_seq(c)) == 0)
            (void)spc__flush(c, spc__now_us() + 200000); /* best effort, 200 ms */
    }
    if (c->fd >= 0) spc__tls_end(c, 1);
    close_fd(c);
    proto_decoder_free(&c->dec);
    proto_buf_free(&c->out);
    fd_destroy(c->fdec);
    free(c);
}

const char *spc_errmsg(const spc_client *c) { return c ? c->errmsg : ""; }

uint32_t spc_errseq(const spc_client *c) { return c ? c->errseq : 0; }

const spc_server_info *spc_server(const spc_client *c) { return &c->server; }

void spc_set_timeout(spc_client *c, int timeout_ms) { c->timeout_ms = timeout_ms; }

int spc_fd(const spc_client *c) { return c ? c->fd : -1; }
