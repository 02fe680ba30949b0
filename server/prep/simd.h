/* simd.h — the 8-wide vector types prep's hot loops are written in (GCC vector extensions) and
 * PREP_CLONES, which compiles such a loop twice on x86-64: for AVX2 and for the baseline (where
 * each 8-wide operation becomes two SSE ones); the loader picks one for the CPU at hand. */
#pragma once

typedef float prep_v8f __attribute__((vector_size(32)));
typedef int prep_v8i __attribute__((vector_size(32)));

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define PREP_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define PREP_CLONES
#endif
