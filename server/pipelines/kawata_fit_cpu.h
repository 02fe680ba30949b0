/* kawata_fit_cpu.h — the rest of kawata's pass 3 and pass 4 on the host (kawata_fit.comp
 * STAGE 2), after the host's passes 1-2, list and resolve (kawata_cpu.h): for every listed
 * buffer pixel the average of its two points, the least-squares plane over the up to 18 points
 * of its 3x3 neighbourhood within the depth tolerance (the support test, the second round
 * without the points beyond 2.5 RMS of the first plane), the shading, the splat pass 5 reads,
 * and the marks of the 8x8 tiles within its reach. On llvmpipe that compute pass cost ~10.3 ms
 * of CPU on the 1M scan (74k listed pixels) and its clears ~1.2; here both ~8.2 (a scalar first
 * version 18.6; eight pixels a vector, 8.4; what remains is mostly the reads of the 9
 * neighbours' points and the scalar tail: colour, projection, marks).
 *
 * The same words as the shader's: every float operation is the shader's, in its order (the
 * shader's are `precise`: its determinants and the normal's length are written out there, not
 * the built-ins, whose expansion is the compiler's), without contraction (-std=c11), so each
 * splat, colour and mark is the GL path's word for word (test_render_kawata's
 * test_host_equals_gpu, test_kawata_cpu). Every core (prep_par_for), bands of rows, each band
 * clearing its rows' splats first; the marks are idempotent stores of 1 (relaxed atomics). */
#pragma once
#include <stdint.h>

typedef struct kawata_fit_job {
    int bw, bh;                /* image buffer */
    int fw, fh;                /* frame */
    int x0, x1, y0, y1;        /* the rectangle: [x0, x1) x [y0, y1) */
    const uint32_t *near;      /* rows [y0, y1) (bw words a row): ~0u where no point */
    const float *pts;          /* rows [y0, y1), 16 floats a buffer pixel (kawata_cpu_resolve) */
    const uint32_t *list;      /* the n covered pixels, x | y << 16, row order */
    uint32_t n;
    float view[16], proj[16];  /* column-major, u_view and u_proj */
    float gamma, slope;        /* depth tolerance gamma + slope * depth */
    float znear, zfar;
    float light[3];            /* unit, eye space */
    int min_support;
    int color;                 /* SP_COLOR_*: 2 normal, 3 depth, else Lambert-shaded colour */
    float *splats;             /* out: rows [y0, y1), 8 floats a buffer pixel; the rectangle's
                                  columns are written (0 where no splat) */
    uint32_t *tiles;           /* out: (bw + 7) / 8 words a row of tiles, all rows; marks set
                                  to 1, nothing cleared */
    int threads;
    uint32_t thread_pixels;    /* listed pixels a thread at least; 0: KAWATA_CPU_THREAD_PIXELS */
} kawata_fit_job;

/* kawata_fit_cpu: writes the splats and the marks; returns the number of splats. */
uint32_t kawata_fit_cpu(const kawata_fit_job *job);
