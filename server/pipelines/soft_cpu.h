/* soft_cpu.h — the Express-Model's soft discs composited on the CPU (the host paths, host.h:
 * order=auto on a software renderer, pipe_soft.c).
 *
 * On a software renderer the GL is the CPU, and what costs there is not the blending but the
 * GL's way to it: ~1 us of set-up per point sprite on llvmpipe's one front-end thread
 * (order=axis), or a compute compositor whose per-pixel loop over every disc of its tile does
 * three times the work the discs cover (order=tile). This compositor takes the discs as
 * soft_bin.comp PASS 0 projects them (read back: centre and radius in window pixels, eye depth,
 * shaded colour, W of eq. 22), in the same back-to-front order (the axis-sorted arrays), and for
 * each disc visits only the pixels whose centres lie inside it: the fragments soft.frag would get,
 * with soft.frag's opacity (eq. 19, modulated by eq. 22) and its test against the solid
 * surface's visibility keys, blended with the premultiplied "over" in float.
 *
 * The discs come in axis order, which jumps about the frame: blending them so would miss the
 * cache at nearly every row a disc touches. So they are first binned into 64x64-pixel tiles by
 * a counting sort that keeps the draw order within each tile (count, prefix sum, fill in
 * order; each tile's discs copied after one another, so that the blend walks memory in
 * sequence; the gather, the counts and the copies by every core, each a consecutive part of
 * the draw order), and the threads take whole tiles. Each thread blends a tile's discs into
 * planes of its own (R, G, B, A and the solid depth from the keys, 64 x 64 floats each, in
 * cache), 8 pixels at a time (8-wide vectors, AVX2 where the CPU has it), then writes the tile
 * into the layer or puts it over the frame's 8-bit pixels. A pixel's discs are the same, in the
 * same order, whatever the thread count. */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* The discs of one buffer set: proj holds 8 floats per disc j (x, y, r in window pixels, eye
 * depth, shaded r, g, b, W); the k-th back to front is j = order[k] (rev: order[n - 1 - k]). */
typedef struct soft_cpu_seg {
    const float *proj;
    const uint32_t *order;
    uint32_t n;
    int rev;
} soft_cpu_seg;

/* The compositor's working memory, kept between frames (grown as needed). */
typedef struct soft_cpu_mem {
    float *discs;              /* 8 floats per disc, in draw order */
    float *tiled;              /* the tiles' discs, each tile's copied contiguous (8 floats a
                                * disc, in draw order): the blend reads them in sequence */
    uint32_t *first;           /* where each tile's discs start in tiled (in discs) */
    uint16_t *rect;            /* 4 per disc in draw order: its tiles' columns and rows */
    uint32_t *cnt;             /* per thread and tile: discs counted, then where they go */
    float *tbuf;               /* per thread: the blend's 5 planes of 64x64 floats (R, G, B, A, depth) */
    size_t discs_cap, tiled_cap, first_cap, rect_cap, cnt_cap, tbuf_cap;
} soft_cpu_mem;

typedef struct soft_cpu_job {
    const soft_cpu_seg *segs;  /* back to front: the sets in their order */
    int nsegs;
    float lambda;
    int width;                 /* frame width */
    int y0, rows;              /* the window rows composited: [y0, y0 + rows) */
    const uint32_t *keys;      /* visibility keys of rows [kb, kb + nk) (width each), ~floatBits
                                * of the solid eye depth, 0 where empty; NULL: no solid surface */
    int kb, nk;
    float *layer;              /* width * rows * 4: premultiplied RGBA, written here; or: */
    uint8_t *rgba8;            /* when not NULL (layer unused): the frame's opaque 8-bit RGBA
                                * pixels, row y at 4 width y (window rows, as glReadPixels
                                * gives them), over which each tile's layer is put (the "over"
                                * soft_resolve makes, in float, rounded to nearest) */
    soft_cpu_mem *mem;
    int threads;               /* 1 to 16 (more are taken as 16) */
    int touched[2];            /* out: the first and last row any disc reached (-1: none) */
    int binned;                /* set by soft_cpu_bin: the discs are in mem's tiles */
} soft_cpu_job;

/* soft_cpu_composite: fills job->layer (cleared first), or blends over job->rgba8, and
 * job->touched. Returns 0, or -1 when the working memory cannot grow (the layer is then left
 * cleared, rgba8 untouched). It is soft_cpu_bin then soft_cpu_blend, which may be called
 * apart: the binning needs only the discs (segs, nsegs, width, y0, rows, mem, threads), so it
 * can run while the keys are being made; the blend then uses the job as binned (with its keys,
 * layer or rgba8 and lambda filled in). soft_cpu_bin returns 0 or -1 (out of memory: then
 * nothing is binned and the blend draws nothing); soft_cpu_blend returns 0. */
int soft_cpu_composite(soft_cpu_job *job);
int soft_cpu_bin(soft_cpu_job *job);
int soft_cpu_blend(soft_cpu_job *job);
void soft_cpu_mem_free(soft_cpu_mem *m);

/* soft_cpu_grow: makes the array *p of *cap elements of sz bytes hold n (doubling, from 4096),
 * for the compositor's host buffers. Returns 0, or -1 (nothing changed) when out of memory. */
int soft_cpu_grow(void **p, size_t *cap, size_t n, size_t sz);
