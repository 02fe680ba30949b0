/* bindings.h — every binding point the shaders use, declared once.
 *
 * Storage blocks get RND_B_<NAME> and texture units RND_T_<NAME>, numbered in list order, so no
 * two share a number. The shaders see the same names without the RND_ prefix (B_<NAME>,
 * T_<NAME>) through the include "lib_bindings.glsl", which shaders.c generates from these lists
 * (it is not a file in shaders/): `layout(std430, binding = B_SPLAT_KEYS) buffer ...` and
 * `layout(binding = T_POS) uniform samplerBuffer u_pos;`. A binding is added here, and only
 * here. The cloud's units (POS, NRM, RAD, SRC, RANGES) are bound by pipe_kit.c for every
 * pipeline; the others belong to one pipeline each. */
#pragma once

#define RND_STORAGE_BLOCKS(X)                                                                 \
    X(SPLAT_KEYS)    /* splat: uint per pixel, the visibility keys (~depth bits, atomicMax) */ \
    X(SPLAT_SUMS)    /* splat: struct Px per pixel, the weighted sums (atomicAdd) */           \
    X(SPLAT_BIG)     /* splat: dispatch header + splats with a big pixel box */                \
    X(SPLAT_RAS)     /* splat: dispatch header + sampled (not deposited) splats */             \
    X(SPLAT_RECT)    /* splat: ivec4, the pixels pass 1 touched */                             \
    X(SOFT_FILL)     /* soft base/concentric: uint per pixel, store cursors; + lost spheres */ \
    X(SOFT_FRAGS)    /* soft base/concentric: vec4 per sample (soft_frag.comp) */              \
    X(POINTS_DEPTH)  /* points: uint per pixel, the packed key or the depth bits */            \
    X(POINTS_INDEX)  /* points: uint per pixel, the exact form's winning point */ \
    X(KAWATA_DEPTH)  /* kawata: uint per buffer pixel, pass 1's nearest depth (float bits) */ \
    X(KAWATA_NEAR)   /* kawata: uint per buffer pixel, the nearest point (cloud-wide index) */ \
    X(KAWATA_FAR)    /* kawata: uint per buffer pixel, pass 2's key (depth step, index) */    \
    X(KAWATA_PTS)    /* kawata: 4 vec4 per buffer pixel: P1, P2 (eye, valid), their colours */ \
    X(KAWATA_SPLATS) /* kawata: 2 vec4 per buffer pixel: the splat (frame x, y, depth), colour */\
    X(KAWATA_LIST)   /* kawata: uint per covered buffer pixel, x | y << 16 (the list pass) */ \
    X(KAWATA_TILES)  /* kawata: uint per 8x8 buffer pixels, 1 where a splat may reach them */ \
    X(KAWATA_COUNT)  /* kawata: 2 uint, the splats drawn and the covered buffer pixels */     \
    X(SOFT_PROJ)     /* soft: 2 vec4 per soft point in draw order: (x, y, r px, depth), (rgb, W) */\
    X(SOFT_CELLS)    /* soft: uint per (tile, block): counts, then offsets; + the total */     \
    X(SOFT_LIST)     /* soft: uint per tile entry: draw-order numbers, tile by tile */          \
    X(SOFT_LAYER)    /* soft: vec4 per stripe pixel: the soft layer, premultiplied */

#define RND_TEXTURE_UNITS(X)                                                                  \
    X(POS)           /* R32F: x y z per point (lib_fetch.glsl) */                              \
    X(NRM)           /* R32F: nx ny nz per point */                                            \
    X(RAD)           /* R32F: splat radius per point */                                        \
    X(SRC)           /* R32UI: rgba8, or the float bits of the field or intensity */           \
    X(RANGES)        /* RG32UI: (first point, first visible index) per range (lib_ranges) */   \
    X(SPLAT_SUMS)    /* splat: the sums as RGBA32F or RGBA32UI texels, 2 a pixel */            \
    X(SPLAT_KEYS)    /* splat: the keys as R32UI */                                            \
    X(POINTS_DEPTH)  /* points: POINTS_DEPTH as R32UI */                                       \
    X(POINTS_INDEX)  /* points: POINTS_INDEX as R32UI */                                     \
    X(KAWATA_DEPTH)  /* kawata: KAWATA_DEPTH as R32UI */                                       \
    X(KAWATA_NEAR)   /* kawata: KAWATA_NEAR as R32UI */                                        \
    X(KAWATA_FAR)    /* kawata: KAWATA_FAR as R32UI */                                         \
    X(KAWATA_PTS)    /* kawata: KAWATA_PTS as RGBA32F, 4 texels a buffer pixel */             \
    X(KAWATA_SPLATS) /* kawata: KAWATA_SPLATS as RGBA32F, 2 texels a buffer pixel */          \
    X(KAWATA_LIST)   /* kawata: KAWATA_LIST as R32UI */                                        \
    X(KAWATA_TILES)  /* kawata: KAWATA_TILES as R32UI */                                       \
    X(EDL_DEPTH)     /* EDL: a copy of the target's depth_eye as R32F */                      \
    X(SOFT_F)        /* soft: R32UI float bits of the field source (FIELD or INTENSITY) */    \
    X(SOFT_IDX)      /* soft: R32UI soft point indices, then their ranks along the 3 axes */  \
    X(SOFT_SOLID)    /* soft: R32UI the solid points in point order (SPLAT_SOLID_LIST) */     \
    X(SOFT_PROJ)     /* soft: SOFT_PROJ as RGBA32F */                                          \
    X(SOFT_LIST)     /* soft: SOFT_LIST as R32UI */                                             \
    X(SOFT_CELLS)    /* soft: SOFT_CELLS as R32UI */                                            \
    X(SOFT_LAYER)    /* soft: SOFT_LAYER as RGBA32F */                                        \
    X(OLT_KEYS)      /* olt: R32UI, the first soft layer's visibility keys (splat's layout) */ \
    X(OLT_COLOR)     /* olt: sampler2D, the first soft layer's resolved colour */

enum {
#define RND_B_ENUM_(name) RND_B_##name,
    RND_STORAGE_BLOCKS(RND_B_ENUM_)
#undef RND_B_ENUM_
    RND_B_COUNT
};

enum {
#define RND_T_ENUM_(name) RND_T_##name,
    RND_TEXTURE_UNITS(RND_T_ENUM_)
#undef RND_T_ENUM_
    RND_T_COUNT
};

#include <stddef.h>

/* rnd_bindings_glsl: writes the text of "lib_bindings.glsl" (one "#define B_<NAME> n" or
 * "#define T_<NAME> n" line per binding) into buf. Returns its length, or -1 when len is too
 * small. */
int rnd_bindings_glsl(char *buf, size_t len);
