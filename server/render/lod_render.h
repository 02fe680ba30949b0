/* lod_render.h — a LOD cloud on the GPU (internal to the renderer): a node pool and the
 * per-frame choice of nodes under a point budget.
 *
 * The pool is one group of buffers (one per attribute, plus radius_lod) holding `cap` points;
 * resident nodes occupy ranges of it (first fit), least recently wanted evicted first, nodes of
 * the current frame pinned. The pipelines see two buffer sets over the same buffers: set 0 with
 * the radius, set 1 with radius_lod in its place, so a node drawn without its children (its
 * children missing, not visible or not within the budget) covers its level's spacing; every
 * pipeline draws the frame's chunks as it draws a flat cloud's.
 *
 * A frame: nodes by priority (projected size of their subtree's bounding sphere: radius over
 * distance) from the root, those outside the frustum skipped, until the next would exceed the
 * point budget (or the pool). Missing ones are read by the cloud's loader thread, at most k
 * at a time in priority order, into memory of their own (the disk reads and the checksum
 * happen there, never on the render thread); a frame uploads the nodes the loader finished
 * and that it still wants. A node is drawn when it and all its ancestors are resident, so a
 * missing node is drawn by its ancestor. complete = every wanted node was drawn. */
#pragma once
#include <stdint.h>

#include "lod.h"
#include "pipe.h"

typedef struct rnd_lod rnd_lod;

/* rnd__lod_new: the pool state for c (owned from now on; freed with the state). Fills g (n =
 * cap, bounds, sigma, radius median, centroid, sets: none yet). */
rnd_lod *rnd__lod_new(lod_cloud *c, uint32_t cap, int k, rnd_gpu_cloud *g, sd_err *err);
void rnd__lod_free(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g);

/* rnd__lod_pool_bytes: the GPU bytes of a pool of cap points. */
uint64_t rnd__lod_pool_bytes(uint32_t cap);

/* rnd__lod_make_pool: allocates the pool buffers (g->sets) when absent. Returns 0 or SD_EGL. */
int rnd__lod_make_pool(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, sd_err *err);
/* rnd__lod_drop_pool: deletes the pool (every node leaves the GPU). */
void rnd__lod_drop_pool(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g);

typedef struct rnd_lod_frame {
    const rnd_chunk *chunks;  /* the nodes to draw, by set then first */
    uint32_t nchunks;
    uint64_t points;          /* points in them */
    uint32_t wanted, drawn, uploaded, evicted, broken, loading;
    int complete;
    int changed;              /* residency changed: pipelines' per-cloud data must be remade */
} rnd_lod_frame;

/* rnd__lod_wait: waits up to timeout_ms until the loader has a node ready; returns how many
 * are (0 when none was loading or the time ran out). */
int rnd__lod_wait(rnd_lod *l, int timeout_ms);

/* rnd__lod_prefetch: the nodes views[0..n) would draw within budget (0: the pool) that are not
 * resident become the prefetch queue (replacing the previous one): the loader reads them in
 * their order whenever a frame leaves slots free, and frames or idle steps upload them.
 * Returns the queue's length. No GL. */
int rnd__lod_prefetch(rnd_lod *l, const rnd_view *views, int n, uint64_t budget);

/* rnd__lod_idle: between frames, uploads the prefetched nodes the loader finished and hands it
 * the next ones; *pending = 1 while the queue or the loader has work left. Nothing happens
 * before the first frame made the pool. out's counters as a frame's. Returns 0. */
int rnd__lod_idle(rnd_lod *l, const gl_api *gl, rnd_lod_frame *out, int *pending);

/* rnd__lod_settle: makes the nodes view v wants (within budget) resident before a frame that
 * must be complete: uploads them as the loader reads them, without drawing, until none is
 * missing, timeout_ms passed, or nothing is loading (a view the pool cannot hold). out->complete
 * says whether all arrived; out->changed whether the pool changed. Returns 0 or SD_EGL. */
int rnd__lod_settle(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, const rnd_view *v,
                    uint64_t budget, int timeout_ms, rnd_lod_frame *out, sd_err *err);

/* rnd__lod_frame: chooses, uploads and lists the frame's nodes. budget 0: no limit but the
 * pool. Returns 0 or a negative SD_E*. */
int rnd__lod_frame(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, const rnd_view *v,
                   uint64_t budget, rnd_lod_frame *out, sd_err *err);
