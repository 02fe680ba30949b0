/* sd_hash.c — see sd_hash.h. */
#include "sd_hash.h"

#include <string.h>

#define P1 0x9E3779B185EBCA87ull
#define P2 0xC2B2AE3D27D4EB4Full
#define P3 0x165667B19E3779F9ull

static inline uint64_t rotl(uint64_t x, int r) { return (x << r) | (x >> (64 - r)); }

static inline uint64_t lane(uint64_t acc, uint64_t w)
{
    acc += w * P2;
    acc = rotl(acc, 31);
    return acc * P1;
}

static inline uint64_t rd64(const uint8_t *p)
{
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
}

uint64_t sd_hash64(const void *data, size_t len, uint64_t seed)
{
    /* One pass of the streaming form: update hashes whole stripes straight from data and
     * copies only the last (< 32) bytes, so the one-shot costs the same. */
    sd_hash_state s;
    sd_hash64_init(&s, seed);
    sd_hash64_update(&s, data, len);
    return sd_hash64_final(&s);
}

void sd_hash64_init(sd_hash_state *s, uint64_t seed)
{
    memset(s, 0, sizeof *s);
    s->a = seed + P1 + P2;
    s->b = seed + P2;
    s->c = seed;
    s->d = seed - P1;
}

static void stripe(sd_hash_state *s, const uint8_t *p)
{
    s->a = lane(s->a, rd64(p));
    s->b = lane(s->b, rd64(p + 8));
    s->c = lane(s->c, rd64(p + 16));
    s->d = lane(s->d, rd64(p + 24));
}

void sd_hash64_update(sd_hash_state *s, const void *data, size_t len)
{
    const uint8_t *p = data;
    s->len += len;
    if (s->ntail) {
        size_t take = 32 - s->ntail < len ? 32 - s->ntail : len;
        memcpy(s->tail + s->ntail, p, take);
        s->ntail += take;
        p += take;
        len -= take;
        if (s->ntail < 32) return;
        stripe(s, s->tail);
        s->ntail = 0;
    }
    while (len >= 32) {
        stripe(s, p);
        p += 32;
        len -= 32;
    }
    memcpy(s->tail, p, len);
    s->ntail = len;
}

uint64_t sd_hash64_final(const sd_hash_state *s)
{
    /* The tail of sd_hash64, on the bytes the lanes left (fewer than 32). */
    const uint8_t *p = s->tail;
    size_t n = s->ntail;
    uint64_t h = rotl(s->a, 1) + rotl(s->b, 7) + rotl(s->c, 12) + rotl(s->d, 18) + s->len;
    while (n >= 8) {
        h ^= lane(0, rd64(p));
        h = rotl(h, 27) * P1 + P3;
        p += 8;
        n -= 8;
    }
    while (n--) {
        h ^= (*p++) * P3;
        h = rotl(h, 11) * P1;
    }
    h ^= h >> 33;
    h *= P2;
    h ^= h >> 29;
    h *= P3;
    h ^= h >> 32;
    return h;
}
