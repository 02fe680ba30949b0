/* tls.c — the daemon's TLS transport over OpenSSL (see tls.h). */
#include "tls.h"

#include <errno.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>

#include "ev.h"

struct tls_server {
    SSL_CTX *ctx;
    char subject[512];
};

typedef struct tls_conn {
    SSL *ssl;
    int checked;                  /* the first byte was looked at (a TLS record or not) */
    int failed;                   /* a fatal error: no close_notify */
} tls_conn;

/* ossl_reason: OpenSSL's queued errors as one short text (the last one is the most precise),
 * queue cleared. */
static void ossl_reason(char *out, size_t len)
{
    unsigned long e, last = 0;
    while ((e = ERR_get_error()) != 0) last = e;
    if (last) ERR_error_string_n(last, out, len);
    else snprintf(out, len, "no reason given by OpenSSL");
}

int tls_server_new(const char *cert_file, const char *key_file, tls_server **out, sd_err *err)
{
    *out = NULL;
    char why[256];
    tls_server *t = calloc(1, sizeof *t);
    if (!t) return sd_errf(err, SD_ENOMEM, "out of memory for the TLS context");
    ERR_clear_error();
    t->ctx = SSL_CTX_new(TLS_server_method());
    if (!t->ctx) {
        ossl_reason(why, sizeof why);
        free(t);
        return sd_errf(err, SD_EIO, "cannot create a TLS context: %s", why);
    }
    SSL_CTX_set_min_proto_version(t->ctx, TLS1_2_VERSION);
    /* Partial writes and a moving buffer: the session retries a write from its queue after
     * NET_AGAIN, and a large frame leaves in records as the socket takes them. */
    SSL_CTX_set_mode(t->ctx, SSL_MODE_ENABLE_PARTIAL_WRITE | SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER |
                                 SSL_MODE_RELEASE_BUFFERS);
    SSL_CTX_set_session_cache_mode(t->ctx, SSL_SESS_CACHE_OFF);
    SSL_CTX_set_options(t->ctx, SSL_OP_NO_RENEGOTIATION | SSL_OP_NO_TICKET);
    SSL_CTX_set_num_tickets(t->ctx, 0); /* nothing to resume: no TLS 1.3 tickets either */
    if (SSL_CTX_use_certificate_chain_file(t->ctx, cert_file) != 1) {
        ossl_reason(why, sizeof why);
        tls_server_free(t);
        return sd_errf(err, SD_EIO, "--tls-cert %s: cannot load a PEM certificate: %s",
                       cert_file, why);
    }
    if (SSL_CTX_use_PrivateKey_file(t->ctx, key_file, SSL_FILETYPE_PEM) != 1) {
        unsigned long e = ERR_peek_last_error();
        ossl_reason(why, sizeof why);
        tls_server_free(t);
        if (ERR_GET_REASON(e) == X509_R_KEY_VALUES_MISMATCH)
            return sd_errf(err, SD_EIO, "--tls-key %s does not belong to the certificate in %s",
                           key_file, cert_file);
        return sd_errf(err, SD_EIO, "--tls-key %s: cannot load a PEM private key: %s", key_file,
                       why);
    }
    if (SSL_CTX_check_private_key(t->ctx) != 1) {
        ossl_reason(why, sizeof why);
        tls_server_free(t);
        return sd_errf(err, SD_EIO, "--tls-key %s does not belong to the certificate in %s: %s",
                       key_file, cert_file, why);
    }
    X509 *x = SSL_CTX_get0_certificate(t->ctx);
    char name[400] = "?";
    if (x) X509_NAME_oneline(X509_get_subject_name(x), name, sizeof name);
    snprintf(t->subject, sizeof t->subject, "%s", name);
    *out = t;
    return 0;
}

void tls_server_free(tls_server *t)
{
    if (!t) return;
    SSL_CTX_free(t->ctx);
    free(t);
}

const char *tls_server_subject(const tls_server *t) { return t->subject; }

void *tls_conn_new(tls_server *t, int fd)
{
    tls_conn *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    c->ssl = SSL_new(t->ctx);
    if (!c->ssl || SSL_set_fd(c->ssl, fd) != 1) {
        SSL_free(c->ssl);
        free(c);
        ERR_clear_error();
        return NULL;
    }
    SSL_set_accept_state(c->ssl);
    return c;
}

/* io_result: maps the outcome r of SSL_read/SSL_write to the transport's codes. */
static ssize_t io_result(tls_conn *c, int r, int *want, const char *what, char *err,
                         size_t errlen)
{
    int e = SSL_get_error(c->ssl, r);
    char why[256];
    switch (e) {
    case SSL_ERROR_WANT_READ:
        *want = EV_READ;
        return NET_AGAIN;
    case SSL_ERROR_WANT_WRITE:
        *want = EV_WRITE;
        return NET_AGAIN;
    case SSL_ERROR_ZERO_RETURN:
        return 0; /* close_notify: the peer closed in order */
    case SSL_ERROR_SYSCALL:
        c->failed = 1;
        ERR_clear_error();
        if (errno == 0 || r == 0) {
            /* EOF without close_notify: for a reader, the peer went away */
            if (SSL_is_init_finished(c->ssl)) return 0;
            snprintf(err, errlen, "TLS handshake: the client closed the connection");
            return NET_ERR;
        }
        snprintf(err, errlen, "TLS %s failed: %s", what, strerror(errno));
        return NET_ERR;
    default:
        c->failed = 1;
        ossl_reason(why, sizeof why);
        snprintf(err, errlen, "TLS %s%s failed: %s", SSL_is_init_finished(c->ssl) ? "" : "handshake in ",
                 what, why);
        return NET_ERR;
    }
}

static ssize_t tls_read(void *ctx, int fd, void *buf, size_t len, int *want, char *err,
                        size_t errlen)
{
    tls_conn *c = ctx;
    if (!c->checked) {
        /* A TLS connection starts with a handshake record (content type 22). Anything else
         * is a client speaking plaintext, told so in plaintext by the caller. */
        unsigned char b0;
        ssize_t p = recv(fd, &b0, 1, MSG_PEEK);
        if (p < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) {
            *want = EV_READ;
            return NET_AGAIN;
        }
        if (p == 1 && b0 != 22) {
            c->failed = 1;
            snprintf(err, errlen, "not a TLS client (first byte 0x%02x): this listener requires "
                     "TLS", b0);
            return NET_NOT_TLS;
        }
        c->checked = 1; /* EOF and errors: SSL_read reports them */
    }
    if (len > INT32_MAX) len = INT32_MAX;
    ERR_clear_error();
    errno = 0;
    int r = SSL_read(c->ssl, buf, (int)len);
    if (r > 0) return r;
    return io_result(c, r, want, "read", err, errlen);
}

static ssize_t tls_write(void *ctx, int fd, const void *buf, size_t len, int *want, char *err,
                         size_t errlen)
{
    (void)fd;
    tls_conn *c = ctx;
    if (len > INT32_MAX) len = INT32_MAX;
    ERR_clear_error();
    errno = 0;
    int r = SSL_write(c->ssl, buf, (int)len);
    if (r > 0) return r;
    ssize_t rc = io_result(c, r, want, "write", err, errlen);
    if (rc == 0) {
        snprintf(err, errlen, "TLS write: the client closed the connection");
        rc = NET_ERR;
    }
    return rc;
}

static int tls_pending(void *ctx)
{
    tls_conn *c = ctx;
    return SSL_has_pending(c->ssl);
}

static void tls_close(void *ctx, int graceful)
{
    tls_conn *c = ctx;
    if (!c) return;
    /* One non-blocking close_notify after an orderly end; never waited for. */
    if (graceful && !c->failed && SSL_is_init_finished(c->ssl)) (void)SSL_shutdown(c->ssl);
    ERR_clear_error();
    SSL_free(c->ssl);
    free(c);
}

const net_transport tls_transport = {"tls", tls_read, tls_write, tls_pending, NULL, tls_close};
