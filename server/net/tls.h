/* tls.h — TLS for the daemon's connections (OpenSSL libssl), as a transport (transport.h):
 * the listener's certificate and key are loaded once into a tls_server; each accepted socket
 * gets a tls_conn whose handshake runs inside its first reads (the session's handshake
 * deadline bounds it). TLS 1.2 or newer; the client's certificate is not asked for (clients
 * prove themselves with the token, inside the encrypted connection). Event-loop thread, except
 * tls_server_new/free at start-up and exit. */
#pragma once
#include "sd_err.h"
#include "transport.h"

typedef struct tls_server tls_server;

/* tls_server_new: loads the PEM certificate chain cert_file and the private key key_file and
 * checks that they match. Returns 0 and *out, or SD_EIO/SD_ENOMEM with err naming the file and
 * OpenSSL's reason. */
int tls_server_new(const char *cert_file, const char *key_file, tls_server **out, sd_err *err);
/* tls_server_free: NULL is allowed. */
void tls_server_free(tls_server *t);
/* tls_server_subject: the certificate's subject and validity, one line for the log. */
const char *tls_server_subject(const tls_server *t);

/* tls_conn_new: the server side of a TLS connection on the accepted non-blocking socket fd
 * (which stays the caller's). Returns the transport context for tls_transport, or NULL when
 * out of memory. */
void *tls_conn_new(tls_server *t, int fd);

/* tls_transport: read/write/pending/close of a tls_conn_new context. A first byte that is not
 * a TLS handshake record (a plaintext client) makes read return NET_NOT_TLS with nothing
 * consumed, so the caller may answer in plaintext. */
extern const net_transport tls_transport;
