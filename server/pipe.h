/* pipe.h — what a pipeline sees of the renderer (internal to server/; see render.h for the
 * public side). render.c owns the context, the uploaded clouds, the output target and the
 * read-back; each pipe_*.c implements one rnd_pipeline and draws into the target.
 *
 * GL calls go through gl_api (gl_api.h), a function table loaded from the active back end
 * (eglGetProcAddress or OSMesaGetProcAddress): libOSMesa and libOpenGL both export gl*
 * symbols, so direct calls would reach the wrong library for one of the two back ends. */
#pragma once
#include <stdint.h>

#include "gl_api.h"
#include "params.h"
#include "prepared.h"
#include "sd_err.h"

/* A cloud on the GPU. Buffers are SSBO-capable (usable as vertex buffers too).
 * Sizes are split so no single buffer passes llvmpipe's 128 MiB SSBO limit for 10M points. */
typedef struct rnd_gpu_cloud {
    uint64_t n;
    GLuint pos;       /* 3 floats per point, tightly packed (read as float[] in SSBOs) */
    GLuint normal;    /* 3 floats per point */
    GLuint radius;    /* 1 float per point */
    GLuint rgba;      /* 1 uint per point: RGBA8 packed (r in the low byte); white if absent */
    GLuint field;     /* 1 float per point: F in [0,1] */
    GLuint intensity; /* 1 float per point, normalised to [0,1]; 0 if absent */
    uint32_t attrs;
    double offset[3];          /* file coordinates = local + offset */
    float bmin[3], bmax[3];    /* local bounds */
    float sigma, radius_median;
    uint64_t nbatches;
    pc_batch *batches;         /* CPU copy, for culling */
} rnd_gpu_cloud;

/* The view of one frame, in the cloud's local coordinates (camera eye - offset), column-major. */
typedef struct rnd_view {
    float view[16], proj[16], viewproj[16];
    float eye[3];              /* local coordinates */
    float znear, zfar, fov_y;  /* radians */
    int width, height;
    /* Visible point ranges after frustum culling of batches (merged when adjacent). */
    uint32_t nranges;
    const uint32_t *range_first, *range_count;
    uint64_t points_visible;
} rnd_view;

/* The output every pipeline writes: fbo with colour attachment 0 = color (linear colour,
 * alpha = coverage) and, as draw buffer 1, depth_eye (eye-space distance along the view axis,
 * +inf where nothing was drawn), plus a 24-bit depth renderbuffer for raster pipelines, which
 * the renderer does NOT clear: a pipeline that depth-tests clears it
 * (glClearBufferfv(GL_DEPTH, 0, &one)); on llvmpipe that clear costs ~5 ms at 1280x720.
 * Two kinds, picked per frame by the renderer:
 *   is_float  color RGBA16F, depth_eye R32F (frames with float colour and depth: EXR);
 *   8-bit     color RGBA8, depth_eye 0 (draw buffer 1 is GL_NONE, so depth output is
 *             dropped), alpha already cleared to 1 and write-masked (glColorMaski) so that
 *             frames are opaque: pipelines leave the colour mask alone.
 * Compute pipelines may bind color and depth_eye as images (rgba16f or rgba8, r32f). */
typedef struct rnd_target {
    GLuint fbo, color, depth_eye, depth_rb;
    int width, height;
    int is_float;
} rnd_target;

typedef struct rnd_shaders rnd_shaders; /* shader source lookup (embedded or --shader-dir) */

/* gl_program_from: compiles and links a program from named shader files (e.g. "points.vert",
 * "points.frag", or one "x.comp"); NULL-terminated list. Returns the program or 0 with err
 * filled (the GL info log and the file name). The files are shaders/NAME.STAGE.glsl (the
 * ".glsl" may be left out of the name); shaders.h has the lookup and the naming rules. */
GLuint gl_program_from(const gl_api *gl, const rnd_shaders *sh, sd_err *err, ...);

typedef struct rnd_pipeline {
    const char *name;
    /* create: compiles programs, allocates state; returns 0 or SD_E*. */
    int (*create)(const gl_api *gl, const rnd_shaders *sh, void **state, sd_err *err);
    void (*destroy)(const gl_api *gl, void *state);
    /* render: draws cloud c seen through v with params p into t (already bound, cleared to the
     * background, depth_eye to +inf when t has one). Returns 0 or SD_E*. */
    int (*render)(const gl_api *gl, void *state, const rnd_gpu_cloud *c, const rnd_view *v,
                  const sp_params *p, const rnd_target *t, sd_err *err);
} rnd_pipeline;

/* pipe_<name> for every row of protocol/pipelines.h. */
#define RND_PIPE_EXTERN_(id, name) extern const rnd_pipeline pipe_##name;
SP_PIPELINE_LIST(RND_PIPE_EXTERN_)
#undef RND_PIPE_EXTERN_
