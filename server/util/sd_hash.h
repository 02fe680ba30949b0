/* sd_hash.h — a fast non-cryptographic 64-bit hash for change detection (cache keys and cache
 * corruption checks), not for security. Four independent multiply-rotate lanes over 8-byte
 * words run at memory bandwidth, so hashing a source file on every cached load stays cheap. */
#pragma once
#include <stddef.h>
#include <stdint.h>

uint64_t sd_hash64(const void *data, size_t len, uint64_t seed);

/* The same hash over data given in pieces (a file read in chunks): sd_hash64_final after
 * updates with the pieces of a buffer in order equals sd_hash64 of the whole buffer. */
typedef struct sd_hash_state {
    uint64_t a, b, c, d;  /* the four lanes */
    uint64_t len;         /* bytes given so far */
    uint8_t tail[32];     /* bytes not yet consumed by the lanes (fewer than 32) */
    size_t ntail;
} sd_hash_state;

void sd_hash64_init(sd_hash_state *s, uint64_t seed);
void sd_hash64_update(sd_hash_state *s, const void *data, size_t len);
uint64_t sd_hash64_final(const sd_hash_state *s);
