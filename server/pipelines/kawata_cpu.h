/* kawata_cpu.h — passes 1 and 2 of the `kawata` pipeline on the host (the host paths, host.h:
 * a software renderer; pipe_kawata.c). On llvmpipe the GL is the CPU, and its compute
 * path pays for every instruction of every SIMD lane of the raster shader (kawata_raster.comp)
 * plus its atomics lane by lane; the same work in C over every core costs a fraction of it.
 *
 * What kawata_raster.comp computes: every point is projected with the shader's operations in
 * the shader's order, each product and sum rounded (this file is compiled without contraction,
 * -std=c11), the division IEEE's; pass 1 keeps each pixel's least key (float bits of the eye
 * depth), pass 2 the least cloud-wide index among the points with exactly that key and the
 * greatest (1 + quantised step) << index_bits | index among those behind it by at most gamma.
 * A GPU may order the matrix product's sums otherwise and divide within 2.5 units in the last
 * place (GLSL 4.50, 4.7.1), so a point within that of a pixel's edge, or of another's depth,
 * may be decided otherwise there; test_render_kawata's test_host_vs_gl bounds where.
 * Minima and maxima do not depend on the order the points are met in, so neither do the
 * results, whatever the thread count.
 *
 * How, on every core (prep_par_for; blocks of points handed out in turn): the points are
 * projected eight at a time (AVX2 where the CPU has it, simd.h), pixel and key a point kept in
 * two arrays, and each thread keeps pass 1's least key a pixel in a depth array of its own
 * (without branches: the keys' order is unpredictable); the threads' arrays are merged by bands
 * of rows; pass 2 reads the kept projections with the merged depth into each thread's own near
 * and far, merged the same way into the job's (a point at the least key, about one a pixel,
 * takes a branch to near, the others go on to far: 3.9 ms of CPU on the 1M scan, against 5.3
 * with no branch at all). No atomics (with a compare-and-swap a point,
 * pass 1 cost 12 ms of CPU on the 1M scan instead of 4.3) and no two threads on one word.
 * Keeping a run of points on one pixel in registers was slower (7.9 ms instead of 4.3: the
 * runs are short, the test mispredicted). More visible points than KAWATA_CPU_BATCH are done a
 * batch at a time, pass 2's batches
 * projected again (the arrays stay bounded).
 */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* Points a batch; threads at most; visible points a thread at least (and listed pixels of the
 * resolve): each parallel step waits for its threads to be scheduled, which on a loaded machine
 * cost a small cloud more wall-clock time than its work (bunnyData.pts, 30k points, two
 * threads: 30-36 ms a frame against the GL path's 18-23, for ~0.3 ms of work; one thread: 11.6
 * against 12.3). Bytes of per-thread arrays at most. */
enum {
    KAWATA_CPU_BATCH = 1 << 23,
    KAWATA_CPU_MAX_THREADS = 16,
    KAWATA_CPU_THREAD_POINTS = 1 << 17,
    KAWATA_CPU_THREAD_PIXELS = 1 << 13
};
#define KAWATA_CPU_PRIV_BYTES ((uint64_t)256 << 20)

/* A run of visible points: points [first, first + count) of a buffer set whose positions are
 * pos (x y z floats a point, set-local index), cloud-wide index base + set-local index. */
typedef struct kawata_cpu_seg {
    const float *pos;
    uint64_t base;
    uint32_t first, count;
} kawata_cpu_seg;

/* Working memory kept between frames (grown as needed). */
typedef struct kawata_cpu_mem {
    uint32_t *pix, *key;       /* per projected point: buffer pixel (relative to row y0; ~0u:
                                  none) and depth key */
    uint64_t *segk;            /* per segment: the number of visible points before it */
    uint32_t *priv;            /* threads 1..: their own depth, near and far */
    size_t pix_cap, key_cap, segk_cap, priv_cap;
} kawata_cpu_mem;

typedef struct kawata_cpu_job {
    const kawata_cpu_seg *segs;
    uint32_t nsegs;
    float viewproj[16];        /* column-major, as the shader's u_viewproj */
    int bw, bh;                /* image buffer size */
    float znear, zfar;
    float gamma, qscale;       /* as pipe_kawata.c's uniforms */
    uint32_t ibits, qmax;
    int x0, x1, y0, y1;        /* the rectangle written: [x0, x1) x [y0, y1) */
    /* rows [y0, y1) of the three arrays (bw words a row): depth, near and far of the shader */
    uint32_t *depth, *near, *far;
    int threads;
    size_t batch;              /* points a batch; 0: KAWATA_CPU_BATCH (tests make it small) */
    size_t thread_points;      /* points a thread at least; 0: KAWATA_CPU_THREAD_POINTS (tests) */
    kawata_cpu_mem *mem;
} kawata_cpu_job;

/* kawata_cpu_raster: writes the rectangle [x0, x1) x [y0, y1) of depth, near and far as passes
 * 1 and 2 leave them after the GL path's clear (depth and near ~0u, far 0), and nothing else.
 * Points landing outside it are left out: the GL passes after it treat pixels outside the
 * cloud's rectangle as empty (the GL path writes such points into pixels nobody reads; the
 * rectangle, from the cloud's bounds grown by a pixel, holds every point). Returns 0, or -1 when
 * the working memory cannot grow (the arrays are then not written). */
int kawata_cpu_raster(const kawata_cpu_job *job);
void kawata_cpu_mem_free(kawata_cpu_mem *m);

/* ---- the list and the first half of pass 3 (kawata_fit.comp STAGE 0 and 1) ----
 * On the host too when the passes above are: the covered buffer pixels of the rectangle in row
 * order, and for each its nearest point and the farthest within gamma to eye space with their
 * colours, as STAGE 1 writes them (vec4(view * vec4(p, 1.0)).xyz, 1.0), the colour vec4(rgb,
 * 1.0), zeros for "no point"). On llvmpipe that compute pass cost ~10 ms of CPU on the 1M scan
 * for ~65k pixels, bound by its scattered reads; here it is a small part of that. The colour
 * sources: RGBA8 (unpackUnorm4x8: each byte / 255.0) or the intensity's float clamped to
 * [0, 1]; color=field (a polynomial colour map) stays with the GL (pipe_kawata.c). The rest of
 * pass 3 and pass 4 (STAGE 2, the fit) run in the GL. */

/* A buffer set: its positions and colour source (NULL when none of its points is visible),
 * cloud-wide index of its first point, points. */
typedef struct kawata_cpu_set {
    const float *pos;
    const uint32_t *src;
    uint64_t base;
    uint32_t n;
} kawata_cpu_set;

typedef struct kawata_cpu_resolve_job {
    const kawata_cpu_set *sets; /* by base, ascending */
    uint32_t nsets;
    float view[16];            /* local -> eye, column-major (u_view) */
    int intensity;             /* 1: the sources are intensities; 0: RGBA8 */
    int bw;
    int x0, x1, y0, y1;        /* the rectangle listed: [x0, x1) x [y0, y1) */
    uint32_t ibits;            /* far's index bits */
    const uint32_t *near, *far; /* rows [y0, y1) as kawata_cpu_raster left them */
    uint32_t *list;            /* out: x | y << 16 a covered pixel, row order (room for the
                                  rectangle) */
    float *pts;                /* out: rows [y0, y1), 16 floats a buffer pixel (P1, P2, their
                                  colours), written for the listed ones */
    int threads;
} kawata_cpu_resolve_job;

/* kawata_cpu_resolve: lists and resolves; returns the number of listed pixels. */
uint32_t kawata_cpu_resolve(const kawata_cpu_resolve_job *job);
