/* pipe.h — what a pipeline sees of the renderer (internal to server/; see render.h for the
 * public side). render.c owns the context, the clouds and their GPU residency, the output
 * target and the read-back; pipe_kit.c holds what every pipeline shares; each pipe_NAME.c
 * implements one rnd_pipeline, listed once in protocol/pipelines.h.
 *
 * A cloud reaches a pipeline as draw chunks: runs of points in buffer sets (GPU buffers, one
 * per attribute). A cloud uploaded whole is split into as many sets as the driver's limits
 * need (one for clouds under GL_MAX_TEXTURE_BUFFER_SIZE / 3 points), its batches are the
 * chunks, and each frame's view lists the chunks that survived culling and the point budget.
 * The level-of-detail octree supplies its nodes through the same interface.
 *
 * GL calls go through gl_api (gl_api.h), a function table loaded from the active back end
 * (eglGetProcAddress or OSMesaGetProcAddress): libOSMesa and libOpenGL both export gl*
 * symbols, so direct calls would reach the wrong library for one of the two back ends. */
#pragma once
#include <stdint.h>

#include "bindings.h"
#include "gl_api.h"
#include "params.h"
#include "pipelines.h"
#include "prepared.h"
#include "render.h"
#include "sd_err.h"

/* The attributes a cloud has on the GPU, one buffer each, every component 4 bytes:
 *   id, name, components, buffer texture format (lib_fetch.glsl reads 3-component ones as
 *   three R32F texels) */
#define RND_ATTR_LIST(X)                                                                      \
    X(POS, "position", 3, GL_R32F)     /* local coordinates (file coordinates - offset) */    \
    X(NORMAL, "normal", 3, GL_R32F)    /* unit */                                             \
    X(RADIUS, "radius", 1, GL_R32F)    /* splat radius */                                     \
    X(RGBA, "rgba", 1, GL_R32UI)       /* RGBA8 packed, r in the low byte; white if absent */ \
    X(FIELD, "field", 1, GL_R32UI)     /* float bits of F in [0,1] */                         \
    X(INTENSITY, "intensity", 1, GL_R32UI) /* float bits, normalised to [0,1]; 0 if absent */ \
    X(CLASS, "class", 1, GL_R32UI)     /* LAS classification 0-255; one word if absent */     \
    X(SCALAR, "scalar", 1, GL_R32UI)   /* float bits of the file's scalar property, normalised \
                                          to [0,1] by its range; one word if absent */         \
    X(SCAN, "scan", 1, GL_R32UI)       /* float bits of the scan index over the largest one;   \
                                          one word if absent */

enum {
#define RND_ATTR_ENUM_(id, name, comps, fmt) RND_ATTR_##id,
    RND_ATTR_LIST(RND_ATTR_ENUM_)
#undef RND_ATTR_ENUM_
    RND_ATTR_COUNT
};

typedef struct rnd_attr_info {
    const char *name;
    int components;     /* 4-byte components per point */
    GLenum texel;       /* buffer texture format */
} rnd_attr_info;
extern const rnd_attr_info rnd_attrs[RND_ATTR_COUNT];

/* One buffer set: points [base, base + n) of a cloud, one buffer per attribute (indexed by
 * RND_ATTR_*). Buffers are SSBO-capable (usable as vertex buffers too). */
typedef struct rnd_bufset {
    uint64_t base;             /* the cloud-wide index of the set's first point */
    uint32_t n;
    GLuint buf[RND_ATTR_COUNT];
} rnd_bufset;

/* A draw chunk: points [first, first + count) of buffer set `set`, and their bounds (local
 * coordinates). */
typedef struct rnd_chunk {
    uint32_t set, first, count;
    uint32_t level;            /* octree level; 0 for the batches of a cloud uploaded whole */
    float bmin[3], bmax[3];
} rnd_chunk;

/* A resident cloud. */
typedef struct rnd_gpu_cloud {
    uint64_t n;
    uint32_t attrs;            /* PC_ATTR_* the file had (normals, radius, F always) */
    char scalar_name[32];      /* the file property RND_ATTR_SCALAR holds ("" if none) */
    double offset[3];          /* file coordinates = local + offset */
    float bmin[3], bmax[3];    /* local bounds */
    float sigma, radius_median;
    float centroid[3];         /* local; the mean of the points (kawata's eq. 3) */
    uint32_t nsets;
    rnd_bufset *sets;
    uint64_t nchunks;
    rnd_chunk *chunks;         /* every chunk, in set order then point order (for culling) */
} rnd_gpu_cloud;

/* The view of one frame, in the cloud's local coordinates (camera eye - offset), column-major. */
typedef struct rnd_view {
    float view[16], proj[16], viewproj[16];
    float eye[3];              /* local coordinates */
    float znear, zfar, fov_y;  /* radians */
    int width, height;
    /* The chunks to draw after frustum culling and the point budget, in set order then point
     * order, adjacent runs of one set merged. */
    uint32_t nchunks;
    const rnd_chunk *chunks;
    uint64_t points_visible;
} rnd_view;

/* The output every pipeline writes: fbo with colour attachment 0 = color (linear colour,
 * alpha = coverage) and, as draw buffer 1, depth_eye (eye-space distance along the view axis,
 * +inf where nothing was drawn; fragment output location 1), plus a 24-bit depth renderbuffer for raster pipelines, which
 * the renderer does NOT clear: a pipeline that depth-tests clears it
 * (glClearBufferfv(GL_DEPTH, 0, &one)); on llvmpipe that clear costs ~5 ms at 1280x720.
 * Two kinds, picked per frame by the renderer:
 *   is_float  color RGBA16F, depth_eye R32F (frames with float colour and depth: EXR);
 *   8-bit     color RGBA8, depth_eye R32F that draw buffer 1 reaches only in frames with
 *             shading=edl (else it is GL_NONE and depth output is dropped: no cost), alpha already cleared to 1 and write-masked (glColorMaski) so that
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

/* ---- the kit: what every pipeline shares (pipe_kit.c) --------------------------------- */

/* The host paths: the passes that a software rasteriser, whose GL is the CPU, runs faster as
 * C on the host over every core than through its GL (each kept because it measured so:
 * docs/performance.md, "Host paths"). They sit behind one table (server/pipelines/host.h),
 * chosen once, by rnd_kit_init: rnd_host_cpu where the back end reports a software renderer
 * (or rnd_desc.host_paths says so), NULL elsewhere. A pipeline asks the table whether a pass is
 * on the host and calls it there; nothing asks what the renderer is called. */
typedef struct rnd_host rnd_host;
extern const rnd_host rnd_host_cpu;

typedef struct rnd_kit {
    const gl_api *gl;
    const rnd_shaders *sh;
    rnd_pipe_opts opts;
    int software;              /* the back end rasterises on the CPU (gl_backend.h; or
                                  rnd_desc.software): the GL paths' tunings for that */
    const rnd_host *host;      /* the host paths, or NULL: every pass in the GL */
    int float_atomics;         /* GL_NV_shader_atomic_float is there */
    GLint64 max_ssbo;          /* GL_MAX_SHADER_STORAGE_BLOCK_SIZE */
    GLint64 max_texels;        /* GL_MAX_TEXTURE_BUFFER_SIZE */
    const rnd_exchange *exchange; /* sort-last frames (render.h), or NULL */
    int kawata_probe;          /* rnd_set_kawata_probe: kawata reads back its arrays */
    /* private to pipe_kit.c */
    GLuint cloud_tex[4];       /* buffer textures on RND_T_POS, NRM, RAD, SRC */
    GLuint range_buf, range_tex;
    uint64_t range_bytes;
    uint32_t *range_tmp;
    uint32_t range_cap;
} rnd_kit;

/* rnd_kit_init: takes the back end's capability (software: 1 for a software rasteriser;
 * host: 1 to take the host paths), queries the driver (extensions, limits) and makes the
 * shared textures. Returns 0 or SD_EGL. rnd_kit_free releases them; safe on a zeroed kit. */
int rnd_kit_init(rnd_kit *k, const gl_api *gl, const rnd_shaders *sh, const rnd_pipe_opts *o,
                 int software, int host, sd_err *err);
void rnd_kit_free(rnd_kit *k);

/* rnd_kit_has_extension: whether the current context lists extension name. */
int rnd_kit_has_extension(const gl_api *gl, const char *name);

/* rnd_kit_program: gl_program_build (shaders.h) through the kit's shader lookup. */
GLuint rnd_kit_program(const rnd_kit *k, const char *const *names, int n, const char *defines,
                       sd_err *err);

/* rnd_kit_ensure_ssbo: makes *buf (created when 0) hold at least bytes, growing it (contents
 * lost) when *have is smaller; *have tracks its size. Returns 1 when it was (re)allocated. */
int rnd_kit_ensure_ssbo(const gl_api *gl, GLuint *buf, uint64_t *have, uint64_t bytes);

/* rnd_kit_color_source: the attribute the colour mode reads per point (RND_ATTR_RGBA, FIELD
 * INTENSITY or SCAN; RGBA for the modes that read none). */
int rnd_kit_color_source(int color);

/* rnd_kit_bind_set: binds buffer set s's position, normal, radius and colour-source buffers
 * as buffer textures on RND_T_POS, NRM, RAD and SRC. */
void rnd_kit_bind_set(rnd_kit *k, const rnd_bufset *s, int color);

/* rnd_kit_set_ranges: the chunks of v in buffer set `set` as the range table of
 * lib_ranges.glsl, uploaded and bound on RND_T_RANGES: (first point, first visible index)
 * per chunk, visible indices counted from 0 within the set. Sets *nranges and *first (the
 * first point of the first range) and returns the set's visible points, 0 when it has none,
 * or a negative SD_E* code. */
int64_t rnd_kit_set_ranges(rnd_kit *k, const rnd_view *v, uint32_t set, uint32_t *nranges,
                           uint32_t *first, sd_err *err);

/* rnd_kit_over_rows: draws 6 vertices with the bound program and vertex array vao (two
 * full-frame triangles, e.g. soft_resolve.vert) into target t over rows [y0, y0 + n) of a
 * width x height frame with the premultiplied "over" (ONE, ONE_MINUS_SRC_ALPHA), no depth test
 * and no writes to draw buffer 1 (the eye depth); restores that state. */
void rnd_kit_over_rows(rnd_kit *k, GLuint vao, const rnd_target *t, int width, int height, int y0,
                       int n);

/* rnd_kit_unbind: unbinds every texture unit of bindings.h. */
void rnd_kit_unbind(rnd_kit *k);

/* ---- pipelines -------------------------------------------------------------------------- */

/* What a pipeline may report about a frame (zero when it has nothing to say). */
typedef struct rnd_draw_out {
    uint64_t splats;           /* kawata: splats drawn (valid image-buffer pixels) */
    int buffer_w, buffer_h;    /* kawata: the image buffer's size */
    uint32_t flags;            /* RND_FRAME_* (render.h): how the frame was degraded */
    uint32_t *probe;           /* kawata under kit.kawata_probe: rnd_frame.kawata_arrays
                                  (malloc'd; the renderer takes it) */
    int after;                 /* 1: the frame is not finished; the renderer calls the
                                  pipeline's `after` on its read-back pixels (only when
                                  rnd_draw.host_after allowed it) */
} rnd_draw_out;

/* What one frame asks of a pipeline. */
typedef struct rnd_draw {
    const rnd_gpu_cloud *cloud;
    void *cloud_data;          /* what the pipeline's attach made for this cloud, or NULL */
    const rnd_view *view;
    const sp_params *params;
    const rnd_target *target;  /* bound, cleared to the background (depth_eye to +inf) */
    rnd_draw_out *out;         /* zeroed by the renderer; never NULL */
    int host_after;            /* 1: the pipeline may leave the end of the frame to its `after`
                                  hook on the host: the frame is an opaque 8-bit one and no GL
                                  pass follows the pipeline's (no GL Eye-Dome Lighting) */
} rnd_draw;

typedef struct rnd_pipeline {
    const char *name;
    uint32_t needs;            /* bits (1 << RND_ATTR_*) of the attributes it reads */
    /* create: compiles programs, allocates state; returns 0 or SD_E*. */
    int (*create)(rnd_kit *k, void **state, sd_err *err);
    void (*destroy)(rnd_kit *k, void *state);
    /* attach (may be NULL): derives per-cloud data when a cloud becomes resident, before its
     * first frame with this pipeline; detach frees it when the cloud leaves the GPU. */
    int (*attach)(rnd_kit *k, void *state, const rnd_gpu_cloud *c, void **cloud_data,
                  sd_err *err);
    void (*detach)(rnd_kit *k, void *state, void *cloud_data);
    /* render: draws d into d->target. Returns 0 or SD_E*. */
    int (*render)(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err);
    /* after (may be NULL): when render set d->out->after, finishes the frame on the host over
     * its read-back pixels rgba8 (width * height RGBA, row y at 4 width y: window rows, as
     * glReadPixels gives them), before the host Eye-Dome Lighting pass. Returns 0 or SD_E*. */
    int (*after)(rnd_kit *k, void *state, const rnd_draw *d, uint8_t *rgba8, sd_err *err);
    /* trim (may be NULL): frees the scratch buffers sized by the frames drawn so far, which its
     * next render makes again at that frame's size (rnd_release_targets: an idle daemon gives a
     * large frame's memory back). */
    void (*trim)(rnd_kit *k, void *state);
} rnd_pipeline;

/* pipe_<name> for every row of protocol/pipelines.h. */
#define RND_PIPE_EXTERN_(id, name) extern const rnd_pipeline pipe_##name;
SP_PIPELINE_LIST(RND_PIPE_EXTERN_)
#undef RND_PIPE_EXTERN_
