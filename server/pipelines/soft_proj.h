/* soft_proj.h — soft_bin.comp's PASS 0 on the host (the host paths, host.h), for the host
 * compositor (soft_cpu.h) on a software renderer: each soft disc projected (centre and radius
 * in window pixels, eye depth, shaded colour, W of eq. 22) from the buffer set's own buffers,
 * mapped for reading (on llvmpipe the GL's memory: no copy), into the 8 floats a disc
 * soft_cpu_seg reads, where the GL path pays a dispatch plus the read-back of every disc
 * (docs/performance.md, "Host paths").
 *
 * The shader's float operations in the shader's order (compiled without contraction, -std=c11),
 * for the colour modes rgb, intensity, depth and normal; color=field's colour map is a shader
 * polynomial and stays in the GL. A GL may fuse a product into a sum, divide within 2.5 ulp and
 * has its own inversesqrt and pow, so the results are the shader's within what the GLSL
 * specification allows it, not word for word (test_soft_proj states the tolerances). */
#pragma once
#include <stdint.h>

typedef struct soft_proj_job {
    /* the set's buffers, by set-local point index i: positions and normals (3 floats a point),
     * radius, colour source (RGBA8 packed, or float bits of the intensity), F */
    const float *pos, *nrm, *rad, *f;
    const uint32_t *src;
    const uint32_t *idx;       /* soft point j in point order -> i */
    uint32_t n;                /* soft points */
    float view[16], proj[16];  /* column-major, as the shader's u_view, u_proj */
    int width, height;
    float scale, znear, zfar, t, lm;
    int color;                 /* SP_COLOR_*, not SP_COLOR_FIELD */
    float light[3];            /* unit, eye space */
    float *out;                /* 8 floats per j (soft_cpu_seg's proj) */
    int threads;
} soft_proj_job;

/* soft_proj_run: fills job->out for every j in [0, n). */
void soft_proj_run(const soft_proj_job *job);
