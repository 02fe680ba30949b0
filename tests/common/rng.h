/* rng.h — the deterministic random numbers of the tests and the synthetic cloud generator:
 * splitmix64, so a seed gives the same cloud on every machine and C library. Header-only. */
#pragma once
#include <math.h>
#include <stdint.h>

typedef struct rng {
    uint64_t s;
} rng;

/* splitmix64: the next 64 random bits. */
static inline uint64_t next64(rng *r)
{
    uint64_t z = (r->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* Uniform in [0, 1). */
static inline double uni(rng *r)
{
    return (double)(next64(r) >> 11) * (1.0 / 9007199254740992.0);
}

/* Standard normal (Box-Muller, one value per call for simplicity). */
static inline double gauss(rng *r)
{
    double u = uni(r), v = uni(r);
    return sqrt(-2.0 * log(1.0 - u)) * cos(6.283185307179586 * v);
}
