/* auth.c — token file, challenge and HMAC-SHA256 proof (see auth.h). */
#include "auth.h"

#include <errno.h>
#include <fcntl.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

int auth_token_load(const char *path, auth_token *t, sd_err *err)
{
    memset(t, 0, sizeof *t);
    /* A symlink is followed (systemd credentials are symlinks); fstat checks its target.
     * O_NONBLOCK: a FIFO in its place must not block start-up; it is refused below. */
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return sd_errf(err, SD_EIO, "token file %s: cannot open: %s", path, strerror(errno));
    struct stat st;
    int rc = 0;
    if (fstat(fd, &st) < 0) {
        rc = sd_errf(err, SD_EIO, "token file %s: fstat: %s", path, strerror(errno));
    } else if (!S_ISREG(st.st_mode)) {
        rc = sd_errf(err, SD_EINVAL, "token file %s is not a regular file", path);
    } else if (st.st_mode & (S_IRWXG | S_IRWXO)) {
        rc = sd_errf(err, SD_EINVAL,
                     "token file %s has mode %04o: it must not be accessible by group or others "
                     "(chmod 600 %s)", path, (unsigned)(st.st_mode & 07777), path);
    } else if (st.st_size > AUTH_TOKEN_MAX + 2) {
        rc = sd_errf(err, SD_ELIMIT, "token file %s holds %lld bytes; the limit is %d", path,
                     (long long)st.st_size, AUTH_TOKEN_MAX);
    }
    if (rc == 0) {
        uint8_t buf[AUTH_TOKEN_MAX + 3];
        size_t n = 0;
        for (;;) {
            ssize_t r = read(fd, buf + n, sizeof buf - n);
            if (r < 0 && errno == EINTR) continue;
            if (r < 0) { rc = sd_errf(err, SD_EIO, "token file %s: read: %s", path, strerror(errno)); break; }
            if (r == 0) break;
            n += (size_t)r;
            if (n == sizeof buf) break;
        }
        while (rc == 0 && n > 0 && (buf[n - 1] == '\n' || buf[n - 1] == '\r')) n--;
        if (rc == 0 && n == 0) rc = sd_errf(err, SD_EEMPTY, "token file %s is empty", path);
        else if (rc == 0 && n > AUTH_TOKEN_MAX)
            rc = sd_errf(err, SD_ELIMIT, "token file %s: the token is longer than %d bytes", path, AUTH_TOKEN_MAX);
        if (rc == 0) { memcpy(t->bytes, buf, n); t->len = n; }
        OPENSSL_cleanse(buf, sizeof buf);
    }
    close(fd);
    return rc;
}

int auth_challenge(uint8_t c[AUTH_CHALLENGE_LEN], sd_err *err)
{
    size_t n = 0;
    while (n < AUTH_CHALLENGE_LEN) {
        ssize_t r = getrandom(c + n, AUTH_CHALLENGE_LEN - n, 0);
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) return sd_errf(err, SD_EIO, "getrandom: %s", strerror(errno));
        n += (size_t)r;
    }
    return 0;
}

int auth_proof(const auth_token *t, const uint8_t c[AUTH_CHALLENGE_LEN], uint8_t proof[AUTH_PROOF_LEN])
{
    unsigned int len = 0;
    if (!HMAC(EVP_sha256(), t->bytes, (int)t->len, c, AUTH_CHALLENGE_LEN, proof, &len) ||
        len != AUTH_PROOF_LEN)
        return SD_EIO;
    return 0;
}

int auth_verify(const auth_token *t, const uint8_t c[AUTH_CHALLENGE_LEN], const uint8_t *proof,
                size_t len)
{
    uint8_t want[AUTH_PROOF_LEN];
    if (len != AUTH_PROOF_LEN || auth_proof(t, c, want) != 0) return 0;
    int ok = CRYPTO_memcmp(want, proof, AUTH_PROOF_LEN) == 0;
    OPENSSL_cleanse(want, sizeof want);
    return ok;
}
