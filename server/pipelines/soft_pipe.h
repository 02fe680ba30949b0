/* soft_pipe.h — the `soft` pipeline's state and per-cloud data, shared by its two files:
 * pipe_soft.c (the split, the GL passes, the pipeline itself) and soft_host.c (the glue to the
 * host paths' compositor, soft_cpu.h). Internal to the
 * pipeline: nothing else includes it. */
#pragma once
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "pipe.h"
#include "soft_cpu.h"
#include "soft_field.h"
#include "soft_lists.h"

/* Uniform slots of the sprite program (soft.vert/.frag), looked up by name. */
#define SOFT_UNIFORMS(X)                                                                     \
    X(SIZE, "u_size") X(MAXSIZE, "u_maxsize") X(STRIPE, "u_stripe") X(KEYS_ON, "u_keys_on")    \
    X(LAMBDA, "u_lambda") X(BASE, "u_base") X(N, "u_n") X(REV, "u_rev")

enum {
#define SOFT_U_ENUM_(id, name) SU_##id,
    SOFT_UNIFORMS(SOFT_U_ENUM_)
#undef SOFT_U_ENUM_
    SU_COUNT
};

/* The compositor's programs. */
enum { C_PROJ = 0, C_BIN1, C_BIN3, C_SCAN, C_BLEND, C_RESOLVE, C_COUNT };

typedef struct soft_state {
    void *splat;               /* the splat passes' own state (splat__create) */
    GLuint prog;
    GLint loc[SU_COUNT];
    GLuint vao;                /* empty: the vertex shader pulls everything */
    GLuint f_tex, idx_tex;     /* buffer textures on RND_T_SOFT_F and RND_T_SOFT_IDX */
    GLuint solid_tex;          /* buffer texture on RND_T_SOFT_SOLID */
    float max_point;           /* GL_POINT_SIZE_RANGE's upper end */
    rnd_chunk *chunks;         /* the frame's solid chunks */
    uint64_t chunks_cap;
    /* the compositor of order=tile (see the file comment) */
    GLuint cprog[C_COUNT];
    GLuint proj_buf, cells_buf, list_buf, layer_buf;
    uint64_t proj_bytes, cells_bytes, list_bytes, layer_bytes;
    GLuint proj_tex, cells_tex, list_tex, layer_tex;
    soft_lists lists;          /* model=base|concentric (soft_lists.h) */
    /* the host compositor (soft_cpu.h through k->host, kept here for the binning thread): the
     * projected discs of every set read back, their segments, the draw-order scratch, the
     * stripe's keys and the layer, all on the host */
    const rnd_host *host;
    float *h_proj, *h_layer;
    uint32_t *h_keys;
    uint32_t *h_fkeys;         /* rnd_draw.host_after: the frame's keys, every stripe's rows */
    size_t h_proj_cap, h_layer_cap, h_keys_cap, h_fkeys_cap;   /* in elements */
    int after_keys;            /* soft__after: h_fkeys holds keys (else no solid surface) */
    soft_cpu_job bin_job;      /* rnd_draw.host_after: the discs binned on bin_th ... */
    pthread_t bin_th;          /* ... while the splat passes make the keys */
    int bin_on;                /* bin_th runs (or ran) and has not been joined */
    int bin_rc;
    soft_cpu_mem mem;
    soft_cpu_seg segs[64];
    int nsegs;
    int threads;
} soft_state;

/* Per buffer set of a cloud: what the split needs on the CPU and the soft index arrays. */
typedef struct soft_set {
    uint32_t n;
    uint32_t *sorted[3];       /* point indices sorted along x, y, z */
    uint32_t *runs;            /* solid runs: (first, count) pairs, in point order */
    uint32_t nruns;
    uint32_t nsoft;            /* soft points for the current split */
    GLuint idx_buf;            /* 4 * nsoft uint32: the soft points, then of sorted[0..2] */
    uint32_t *idx;             /* the same on the host (the host compositor) */
    uint32_t *solid;           /* a cloud in one set: its n - nsoft solid points, in point order */
    GLuint solid_buf;          /* the same, on RND_T_SOFT_SOLID (SPLAT_SOLID_LIST) */
    float centre[3];           /* mean of the set's bounds: the order of sets */
} soft_set;

typedef struct soft_cloud {
    uint32_t nsets;
    soft_set *sets;
    soft_fields fields;        /* F per point (soft_field.h) */
    int have_split;            /* the split below has been made for fields' current F */
    float t;
} soft_cloud;

typedef struct soft_order {
    int axis, rev;             /* the sorted array, and whether it is read backwards */
    uint32_t set_order[64];    /* sets back to front (clouds of up to 64 sets; more: set order) */
} soft_order;


/* pipe_soft.c, for soft_host.c */
/* soft__buf_tex: makes *buf hold at least bytes and tex a buffer texture of format fmt over it. */
void soft__buf_tex(const gl_api *gl, GLuint *buf, uint64_t *have, uint64_t bytes, GLuint tex,
                   GLenum fmt);
/* soft__project_set: soft_bin.comp PASS 0 over set si's soft discs into s->proj_buf. Returns 0
 * or SD_E*. */
int soft__project_set(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                      const soft_order *o, uint32_t si, sd_err *err);
/* soft__resolve_layer: soft_resolve puts the layer (rows [y0, y0 + n)) over the target. */
void soft__resolve_layer(rnd_kit *k, soft_state *s, const rnd_draw *d, int y0, int n);

/* soft_host.c, for pipe_soft.c: the host compositor */
/* soft__bin_start: soft_cpu_bin(&s->bin_job) on a thread of its own (here, now, without one);
 * soft__bin_join waits for it and returns its result (0 when none ran). */
void soft__bin_start(soft_state *s);
int soft__bin_join(soft_state *s);
/* soft__cpu_project: the soft discs of every set projected into s->h_proj, one segment per set
 * in o's order (s->segs, s->nsegs). Returns 0 or SD_E*. */
int soft__cpu_project(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                      const soft_order *o, sd_err *err);
/* soft__cpu_blend: the discs over rows [y0, y0 + n) through an uploaded layer; keys says
 * whether the stripe's visibility keys (rows [yb, yb + nb)) test them. Returns 0 or SD_E*. */
int soft__cpu_blend(rnd_kit *k, soft_state *s, const rnd_draw *d, int keys, int y0, int n,
                    int yb, int nb, sd_err *err);
/* soft__keep_keys: rnd_draw.host_after, the stripe's rows of its keys kept for soft__after. */
int soft__keep_keys(rnd_kit *k, soft_state *s, const rnd_draw *d, int y0, int n, int yb,
                    sd_err *err);
/* soft__after: the pipeline's `after` hook (rnd_pipeline.after). */
int soft__after(rnd_kit *k, void *state, const rnd_draw *d, uint8_t *rgba8, sd_err *err);
