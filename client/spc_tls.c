/* spc_tls.c — libsplatclient's TLS layer (OpenSSL libssl): the handshake with certificate and
 * host-name verification, and the reads and writes of a TLS connection (see spc_internal.h).
 *
 * The socket is driven through a BIO of our own rather than OpenSSL's socket BIO: it sends with
 * MSG_NOSIGNAL (a library must not raise SIGPIPE in its caller's process) and remembers the
 * first bytes the server sent, so that a server answering in the plaintext protocol is named
 * as such instead of as a broken TLS record. */
#include "spc_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>

/* The BIO's state: the socket and the first bytes read from it. */
struct spc_tls_io {
    int fd;
    uint8_t first[4];
    size_t nfirst;
};

static int bio_write(BIO *b, const char *buf, int len)
{
    struct spc_tls_io *io = BIO_get_data(b);
    BIO_clear_retry_flags(b);
    ssize_t n = send(io->fd, buf, (size_t)len, MSG_NOSIGNAL);
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) BIO_set_retry_write(b);
    return (int)n;
}

static int bio_read(BIO *b, char *buf, int len)
{
    struct spc_tls_io *io = BIO_get_data(b);
    BIO_clear_retry_flags(b);
    ssize_t n = recv(io->fd, buf, (size_t)len, 0);
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) BIO_set_retry_read(b);
    for (ssize_t i = 0; i < n && io->nfirst < sizeof io->first; i++)
        io->first[io->nfirst++] = (uint8_t)buf[i];
    return (int)n;
}

static long bio_ctrl(BIO *b, int cmd, long num, void *ptr)
{
    (void)b; (void)num; (void)ptr;
    return cmd == BIO_CTRL_FLUSH ? 1 : 0; /* nothing is buffered here */
}

static int bio_create(BIO *b)
{
    BIO_set_init(b, 1);
    return 1;
}

/* ossl_reason: the last queued OpenSSL error as text; queue cleared. */
static void ossl_reason(char *out, size_t len)
{
    unsigned long e, last = 0;
    while ((e = ERR_get_error()) != 0) last = e;
    if (last) ERR_error_string_n(last, out, len);
    else snprintf(out, len, "no reason given by OpenSSL");
}

/* handshake_error: the failure of SSL_connect r on c, named for a person. */
static int handshake_error(spc_client *c, int r, const char *name, const char *ca_file)
{
    int e = SSL_get_error(c->ssl, r);
    long v = SSL_get_verify_result(c->ssl);
    static const uint8_t magic[4] = {'S', 'P', 'L', 'T'};
    char why[256];
    ossl_reason(why, sizeof why);
    if (c->tls_io->nfirst == 4 && !memcmp(c->tls_io->first, magic, 4))
        return spc__fail(c, SPC_E_IO, "the server answered in plaintext, not TLS: it listens "
                         "without TLS (connect without --tls, or give the server --tls-cert and "
                         "--tls-key)");
    if (v != X509_V_OK)
        return spc__fail(c, SPC_E_IO, "the server's certificate was refused for '%s': %s "
                         "(verified against %s%s)", name, X509_verify_cert_error_string(v),
                         ca_file ? "the CA file " : "the system's trusted certificates",
                         ca_file ? ca_file : "");
    if (e == SSL_ERROR_SYSCALL || e == SSL_ERROR_ZERO_RETURN)
        return spc__fail(c, SPC_E_IO, "the server closed the connection during the TLS "
                         "handshake%s%s (a TLS server that is full, or has too many connections "
                         "from your address, closes new ones at once: retry later)",
                         errno ? ": " : "", errno ? strerror(errno) : "");
    return spc__fail(c, SPC_E_IO, "TLS handshake with the server failed: %s", why);
}

int spc__tls_start(spc_client *c, const char *host, const char *name, const char *ca_file,
                   uint64_t deadline)
{
    if (!name) name = host;
    char why[256];
    ERR_clear_error();
    c->tls_io = calloc(1, sizeof *c->tls_io);
    c->tls_meth = BIO_meth_new(BIO_get_new_index() | BIO_TYPE_SOURCE_SINK, "splat socket");
    c->tls_ctx = SSL_CTX_new(TLS_client_method());
    if (!c->tls_io || !c->tls_meth || !c->tls_ctx)
        return spc__fail(c, SPC_E_NOMEM, "cannot set up TLS (out of memory)");
    c->tls_io->fd = c->fd;
    BIO_meth_set_write(c->tls_meth, bio_write);
    BIO_meth_set_read(c->tls_meth, bio_read);
    BIO_meth_set_ctrl(c->tls_meth, bio_ctrl);
    BIO_meth_set_create(c->tls_meth, bio_create);
    SSL_CTX_set_min_proto_version(c->tls_ctx, TLS1_2_VERSION);
    SSL_CTX_set_verify(c->tls_ctx, SSL_VERIFY_PEER, NULL);
    SSL_CTX_set_mode(c->tls_ctx, SSL_MODE_ENABLE_PARTIAL_WRITE |
                                     SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER);
    int ok = ca_file ? SSL_CTX_load_verify_locations(c->tls_ctx, ca_file, NULL)
                     : SSL_CTX_set_default_verify_paths(c->tls_ctx);
    if (ok != 1) {
        ossl_reason(why, sizeof why);
        if (ca_file)
            return spc__fail(c, SPC_E_INVALID_ARG, "cannot load the CA certificates in %s: %s",
                             ca_file, why);
        return spc__fail(c, SPC_E_IO, "cannot load the system's trusted certificates: %s", why);
    }
    c->ssl = SSL_new(c->tls_ctx);
    BIO *bio = c->ssl ? BIO_new(c->tls_meth) : NULL;
    if (!bio) return spc__fail(c, SPC_E_NOMEM, "cannot set up TLS (out of memory)");
    BIO_set_data(bio, c->tls_io);
    SSL_set_bio(c->ssl, bio, bio);
    /* The name the certificate must carry: an IP address is matched against its IP entries, a
     * host name against its DNS entries (and sent as SNI). */
    unsigned char addr[16];
    X509_VERIFY_PARAM *vp = SSL_get0_param(c->ssl);
    X509_VERIFY_PARAM_set_hostflags(vp, X509_CHECK_FLAG_NO_PARTIAL_WILDCARDS);
    if (inet_pton(AF_INET, name, addr) == 1 || inet_pton(AF_INET6, name, addr) == 1) {
        ok = X509_VERIFY_PARAM_set1_ip_asc(vp, name);
    } else {
        ok = SSL_set1_host(c->ssl, name) == 1 && SSL_set_tlsext_host_name(c->ssl, name) == 1;
    }
    if (ok != 1)
        return spc__fail(c, SPC_E_INVALID_ARG, "'%s' cannot be checked against a certificate",
                         name);
    for (;;) {
        ERR_clear_error();
        errno = 0;
        int r = SSL_connect(c->ssl);
        if (r == 1) break;
        int e = SSL_get_error(c->ssl, r);
        if (e != SSL_ERROR_WANT_READ && e != SSL_ERROR_WANT_WRITE)
            return handshake_error(c, r, name, ca_file);
        int rc = spc__wait_fd(c, e == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT, deadline);
        if (rc < 0) return rc;
    }
    return 0;
}

int spc__tls_io(spc_client *c, int writing, void *buf, size_t len, size_t *done, short *ev)
{
    if (len > INT32_MAX) len = INT32_MAX;
    ERR_clear_error();
    errno = 0;
    int r = writing ? SSL_write(c->ssl, buf, (int)len) : SSL_read(c->ssl, buf, (int)len);
    if (r > 0) {
        *done = (size_t)r;
        return 0;
    }
    char why[256];
    switch (SSL_get_error(c->ssl, r)) {
    case SSL_ERROR_WANT_READ: *ev = POLLIN; return 1;
    case SSL_ERROR_WANT_WRITE: *ev = POLLOUT; return 1;
    case SSL_ERROR_ZERO_RETURN: return 2;
    case SSL_ERROR_SYSCALL:
        ERR_clear_error();
        if (errno == 0) return 2; /* EOF without close_notify */
        return spc__fail(c, SPC_E_IO, "%s the server failed: %s",
                         writing ? "sending to" : "receiving from", strerror(errno));
    default:
        ossl_reason(why, sizeof why);
        if (!writing && strstr(why, "unexpected eof")) return 2;
        return spc__fail(c, SPC_E_IO, "TLS %s failed: %s", writing ? "write" : "read", why);
    }
}

int spc__tls_pending(const spc_client *c) { return c->ssl && SSL_has_pending(c->ssl); }

void spc__tls_end(spc_client *c, int graceful)
{
    if (c->ssl && graceful) {
        ERR_clear_error();
        (void)SSL_shutdown(c->ssl); /* close_notify, best effort, not waited for */
    }
    SSL_free(c->ssl); /* frees the BIO too */
    SSL_CTX_free(c->tls_ctx);
    BIO_meth_free(c->tls_meth);
    free(c->tls_io);
    ERR_clear_error();
    c->ssl = NULL;
    c->tls_ctx = NULL;
    c->tls_meth = NULL;
    c->tls_io = NULL;
}
