/* sd_hash.h — the 64-bit hash for change detection (cache keys and cache corruption checks),
 * not for security: XXH3-64 from libxxhash (Debian libxxhash-dev), which runs at memory
 * bandwidth, so hashing a source file on every cached load stays cheap. A thin layer so that
 * callers name one hash and the cache's version says which one its keys were made with. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#define XXH_STATIC_LINKING_ONLY /* XXH3_state_t by value: a state on the caller's stack */
#include <xxhash.h>

/* sd_hash64: XXH3_64bits_withSeed(data, len, seed). */
uint64_t sd_hash64(const void *data, size_t len, uint64_t seed);

/* The same hash over data given in pieces (a file read in chunks): sd_hash64_final after
 * updates with the pieces of a buffer in order equals sd_hash64 of the whole buffer. */
typedef struct sd_hash_state {
    XXH3_state_t st;
} sd_hash_state;

void sd_hash64_init(sd_hash_state *s, uint64_t seed);
void sd_hash64_update(sd_hash_state *s, const void *data, size_t len);
uint64_t sd_hash64_final(const sd_hash_state *s);
