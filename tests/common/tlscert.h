/* tlscert.h — self-signed certificates for the TLS tests, made with OpenSSL's C API (no
 * `openssl` tool needed): an EC P-256 key and a certificate valid for a day. */
#pragma once
#include <stddef.h>

/* tu_make_cert: writes DIR/NAME.crt (PEM certificate, CN = cn, subjectAltName IP:ip and
 * DNS:dns, either may be NULL) and DIR/NAME.key (PEM key, mode 0600); their paths go to cert
 * and key (len bytes each). The certificate is its own CA (basicConstraints CA:TRUE), so a
 * client may trust it directly. Returns 0 or -1. */
int tu_make_cert(const char *dir, const char *name, const char *cn, const char *ip,
                 const char *dns, char *cert, char *key, size_t len);
