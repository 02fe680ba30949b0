/* splat_passes.h — the `splat` pipeline's passes (pipe_splat.c), for pipelines that compose
 * them instead of copying them (soft draws its solid points through them, olt its opaque
 * ones). Internal to the renderer.
 *
 * A composing pipeline makes its own splat state with splat__create and, per frame:
 *
 *     splat_frame f;
 *     int n = splat__frame_begin(k, st, d, &f, err);   // < 0 error, 0 nothing to draw
 *     for (int i = 0; i < n; i++) {
 *         splat__stripe_begin(k, st, &f, i);           // rows [f.y0, f.y0 + f.n)
 *         splat__visibility(k, st, &f, err);            // pass 1: nearest depth per pixel
 *         splat__attributes(k, st, &f, err);            // pass 2: weighted sums
 *         splat__resolve(k, st, &f);                    // pass 3: into d->target
 *         ... its own passes for the stripe, reading splat__keys_texture(st) ...
 *     }
 *     splat__frame_end(k, st, err);
 *
 * d->view's chunks decide which points take part (a composing pipeline passes a view of its
 * solid chunks). Between the passes the splat buffers stay bound on their binding points
 * (bindings.h RND_B_SPLAT_*, RND_T_SPLAT_*). */
#pragma once
#include "pipe.h"

typedef struct splat_frame {
    const rnd_draw *d;
    int rows, nstripes;   /* rows per stripe, and how many */
    int y0, n;            /* the current stripe's first row and row count */
    int one_set;          /* one buffer set, bound once for the frame */
    int64_t total;        /* its visible points */
} splat_frame;

int splat__create(rnd_kit *k, void **state, sd_err *err);
/* splat__create_filtered: the same passes, whose raster programs draw part of the points by
 * their field value F (float bits on RND_T_SOFT_F, soft_field.h) and splat__set_filter's mode:
 * the `soft` pipeline's solid points, the `olt` pipeline's layers. The resolve is splat's. */
int splat__create_filtered(rnd_kit *k, void **state, sd_err *err);
enum {
    SPLAT_SKIP_SOFT = 0,  /* points with F > t are skipped (t >= 1 skips none) */
    SPLAT_SKIP_SOLID = 1, /* points with F <= t are skipped */
    SPLAT_PEEL = 2,       /* soft points within the first soft layer are skipped: their centre
                             depth within the depth tolerance of the keys on RND_T_OLT_KEYS
                             (a copy of an earlier soft-only pass's keys of the same stripe) */
    SPLAT_SOLID_LIST = 3  /* nothing is skipped, but the view's chunks count entries of the list
                             on RND_T_SOFT_SOLID (R32UI, the solid points in point order), not
                             points: entry j draws point list[j]. The passes then spend nothing
                             on soft points, which the filter (mode 0) still reads one by one
                             and which leave SIMD lanes idle among the solid ones */
};
/* splat__set_filter: after splat__frame_begin, the filter mode and threshold of a
 * splat__create_filtered state. */
void splat__set_filter(rnd_kit *k, void *state, int mode, float t);
/* splat__set_set_hook: fn(user, set) runs whenever the passes make buffer set `set` current
 * (before its points are drawn), so a filtered state's caller can bind that set's field
 * buffer; NULL: none. */
void splat__set_set_hook(void *state, void (*fn)(void *user, uint32_t set), void *user);
/* splat__keys_buffer: the storage buffer behind splat__keys_texture, and its bytes. */
GLuint splat__keys_buffer(const void *state, uint64_t *bytes);
void splat__destroy(rnd_kit *k, void *state);

/* splat__frame_begin: sizes the buffers and sets the frame's uniforms. Returns the number of
 * stripes (0: nothing visible) or a negative SD_E* code. */
int splat__frame_begin(rnd_kit *k, void *state, const rnd_draw *d, splat_frame *f, sd_err *err);
/* splat__stripe_begin: clears the sums, keys and rectangle for stripe i. */
void splat__stripe_begin(rnd_kit *k, void *state, splat_frame *f, int i);
/* splat__visibility, splat__attributes: passes 1 and 2 of the stripe over every buffer set;
 * 0 or SD_E*. */
int splat__visibility(rnd_kit *k, void *state, splat_frame *f, sd_err *err);
int splat__attributes(rnd_kit *k, void *state, splat_frame *f, sd_err *err);
/* splat__resolve: pass 3 of the stripe (normalise, low-pass, shade) into the target. */
void splat__resolve(rnd_kit *k, void *state, splat_frame *f);
/* splat__frame_end: unbinds; returns 0 or the GL error of the passes (debug builds). */
int splat__frame_end(rnd_kit *k, void *state, sd_err *err);
/* splat__keys_texture: the current stripe's visibility keys (R32UI, ~floatBits(eye depth), 0
 * empty) as a buffer texture. */
GLuint splat__keys_texture(const void *state);
