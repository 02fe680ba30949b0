/* tlscert.c — self-signed test certificates (see tlscert.h). */
#include "tlscert.h"

#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/rand.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <stdio.h>
#include <sys/stat.h>

/* add_ext: one v3 extension given in openssl.cnf syntax. 0 or -1. */
static int add_ext(X509 *x, int nid, const char *value)
{
    X509V3_CTX ctx;
    X509V3_set_ctx_nodb(&ctx);
    X509V3_set_ctx(&ctx, x, x, NULL, NULL, 0);
    X509_EXTENSION *e = X509V3_EXT_conf_nid(NULL, &ctx, nid, value);
    if (!e) return -1;
    int ok = X509_add_ext(x, e, -1);
    X509_EXTENSION_free(e);
    return ok ? 0 : -1;
}

int tu_make_cert(const char *dir, const char *name, const char *cn, const char *ip,
                 const char *dns, char *cert, char *key, size_t len)
{
    snprintf(cert, len, "%s/%s.crt", dir, name);
    snprintf(key, len, "%s/%s.key", dir, name);
    EVP_PKEY *pk = EVP_EC_gen("P-256");
    X509 *x = X509_new();
    int rc = -1;
    if (!pk || !x) goto out;
    unsigned char r[4];
    if (RAND_bytes(r, sizeof r) != 1) goto out;
    ASN1_INTEGER_set(X509_get_serialNumber(x), 1 + (long)(((unsigned)r[0] << 16) | (r[1] << 8) | r[2]));
    X509_set_version(x, 2);
    X509_gmtime_adj(X509_getm_notBefore(x), -3600);
    X509_gmtime_adj(X509_getm_notAfter(x), 86400);
    X509_set_pubkey(x, pk);
    X509_NAME *n = X509_get_subject_name(x);
    X509_NAME_add_entry_by_txt(n, "CN", MBSTRING_ASC, (const unsigned char *)cn, -1, -1, 0);
    X509_set_issuer_name(x, n);
    char san[512] = "";
    if (ip && dns) snprintf(san, sizeof san, "IP:%s,DNS:%s", ip, dns);
    else if (ip) snprintf(san, sizeof san, "IP:%s", ip);
    else if (dns) snprintf(san, sizeof san, "DNS:%s", dns);
    if (add_ext(x, NID_basic_constraints, "critical,CA:TRUE") != 0 ||
        add_ext(x, NID_key_usage, "critical,keyCertSign,digitalSignature") != 0 ||
        add_ext(x, NID_subject_key_identifier, "hash") != 0 ||
        (san[0] && add_ext(x, NID_subject_alt_name, san) != 0))
        goto out;
    if (!X509_sign(x, pk, EVP_sha256())) goto out;
    FILE *f = fopen(cert, "w");
    if (!f) goto out;
    int ok = PEM_write_X509(f, x);
    if (fclose(f) != 0 || !ok) goto out;
    f = fopen(key, "w");
    if (!f) goto out;
    chmod(key, 0600);
    ok = PEM_write_PrivateKey(f, pk, NULL, NULL, 0, NULL, NULL);
    if (fclose(f) != 0 || !ok) goto out;
    rc = 0;
out:
    X509_free(x);
    EVP_PKEY_free(pk);
    return rc;
}
