/* sd_hash.c — XXH3-64 through libxxhash (see sd_hash.h). */
#include "sd_hash.h"

uint64_t sd_hash64(const void *data, size_t len, uint64_t seed)
{
    return XXH3_64bits_withSeed(data, len, seed);
}

void sd_hash64_init(sd_hash_state *s, uint64_t seed) { XXH3_64bits_reset_withSeed(&s->st, seed); }

void sd_hash64_update(sd_hash_state *s, const void *data, size_t len)
{
    XXH3_64bits_update(&s->st, data, len);
}

uint64_t sd_hash64_final(const sd_hash_state *s) { return XXH3_64bits_digest(&s->st); }
