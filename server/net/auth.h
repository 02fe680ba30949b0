/* auth.h — the shared-token authentication of the daemon: token file checks, the random
 * challenge sent in WELCOME, and the HMAC-SHA256 proof check of HELLO (libcrypto).
 * Low-level: returns codes, never logs. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

enum { AUTH_CHALLENGE_LEN = 32, AUTH_PROOF_LEN = 32, AUTH_TOKEN_MAX = 4096 };

typedef struct auth_token {
    uint8_t bytes[AUTH_TOKEN_MAX];
    size_t len;          /* 0: no token configured (auth disabled) */
} auth_token;

/* auth_token_load: reads the token file path into t. Refuses (SD_EINVAL) a file that is not a
 * regular file or whose mode grants any permission to group or others (like ssh's private
 * keys: a shared secret others can read is no secret), an empty token (SD_EEMPTY) and one over
 * AUTH_TOKEN_MAX bytes or a file over AUTH_TOKEN_MAX + 2 bytes (SD_ELIMIT). Trailing newline and
 * carriage-return characters are not part of the token (so `echo secret > F` works). Returns 0
 * or the code with err naming the file. (The client's spc__read_token applies the same rule.) */
int auth_token_load(const char *path, auth_token *t, sd_err *err);

/* auth_challenge: fills c with AUTH_CHALLENGE_LEN random bytes (getrandom). Returns 0 or SD_EIO. */
int auth_challenge(uint8_t c[AUTH_CHALLENGE_LEN], sd_err *err);

/* auth_proof: writes HMAC-SHA256(token, challenge) into proof. Returns 0 or SD_EIO. */
int auth_proof(const auth_token *t, const uint8_t c[AUTH_CHALLENGE_LEN], uint8_t proof[AUTH_PROOF_LEN]);

/* auth_verify: 1 when proof (len bytes) equals HMAC-SHA256(token, challenge), compared in
 * constant time; 0 otherwise (including a wrong length). */
int auth_verify(const auth_token *t, const uint8_t c[AUTH_CHALLENGE_LEN], const uint8_t *proof,
                size_t len);
