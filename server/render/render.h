/* render.h — the renderer: one GL context (EGL or OSMesa), clouds uploaded once, pipelines.
 *
 * Threading: a rnd_ctx and everything it owns belong to the thread that created it (the
 * daemon's render thread); nothing here is thread-safe. Clouds are referred to by ids
 * (index + generation, 0 invalid) so that stale ids are caught, not dereferenced. */
#pragma once
#include <stdint.h>

#include "framing.h"
#include "params.h"
#include "lod.h"
#include "prepared.h"
#include "sd_err.h"

typedef enum { RND_BACKEND_AUTO = 0, RND_BACKEND_EGL, RND_BACKEND_OSMESA } rnd_backend_kind;

/* Pipeline options that tests and benchmarks set (never read from the environment). */
typedef struct rnd_pipe_opts {
    int points_raster;        /* RND_RASTER_*: the points pipeline's form (default auto) */
    int splat_fixed;          /* 1: fixed-point accumulation even with float atomics */
    int splat_stripe_rows;    /* rows per accumulation stripe, 0 = as many as fit */
    int soft_proj_gl;         /* 1: with the host paths, soft's discs still projected by the GL
                                 (test_soft_proj compares the two) */
} rnd_pipe_opts;

enum { RND_RASTER_AUTO = 0, RND_RASTER_PACKED, RND_RASTER_EXACT, RND_RASTER_GL };

/* rnd_desc.software and .host_paths: as the GL back end reports (RND_CAP_AUTO), or forced. */
enum { RND_CAP_AUTO = 0, RND_CAP_ON, RND_CAP_OFF };

enum { RND_DEFAULT_WIDTH = SP_DEFAULT_WIDTH, RND_DEFAULT_HEIGHT = SP_DEFAULT_HEIGHT };

/* Default LOD point budgets (README "Huge scans"): llvmpipe on the 2-core machine, in a quiet
 * moment, drew 1M points of the 1M / 10M / 100M synthetic scans at 1280x720 in 81 / 96 / 94 ms
 * with splat (the default pipeline) and 53 / 55 / 62 ms with points: 1M keeps splat near 10
 * frames/s. The GPU value is not measured here (no GPU was available): Potree's 1M default
 * scaled by the compute rasteriser's throughput, to be checked on a GPU. */
#define RND_LOD_BUDGET_SOFTWARE 1000000u
#define RND_LOD_BUDGET_GPU 3000000u

typedef struct rnd_desc {
    rnd_backend_kind backend; /* default AUTO: EGL, then OSMesa */
    const char *shader_dir;   /* default NULL: the shaders compiled into the binary */
    int max_width;            /* default 8192: largest frame accepted */
    int max_height;           /* default 8192 */
    uint64_t gpu_memory;      /* bytes of cloud buffers kept on the GPU; default 0: sized to
                                 the device (3/4 of its dedicated memory where the driver says,
                                 a quarter of system memory on a software renderer, else 1 GiB) */
    uint32_t max_set_points;  /* default 0: points per buffer set as the driver allows
                                 (GL_MAX_TEXTURE_BUFFER_SIZE / 3); tests set less */
    rnd_pipe_opts pipe;
    int lod_uploads;          /* default 4: LOD nodes loading at once (the loader thread's
                                 slots); a frame draws a missing node's ancestor instead */
    uint32_t lod_pool_points; /* default 0: points of a LOD cloud's GPU node pool: 6M, less
                                 when the driver's buffer limit or the GPU budget says so */
    uint64_t lod_budget;      /* default 0: the point budget of LOD frames whose point_budget
                                 is 0, per back end: RND_LOD_BUDGET_SOFTWARE on a software
                                 renderer, RND_LOD_BUDGET_GPU on a GPU */
    int software;             /* RND_CAP_*: default AUTO, as the back end reports
                                 (gl_backend.h): whether the GL paths take their tunings for a
                                 software rasteriser (compute invocations doing runs of points,
                                 ewa=auto's split form, the LOD and memory budgets) */
    int host_paths;           /* RND_CAP_*: default AUTO, on exactly where `software` is: the
                                 pipelines' host paths (pipe.h rnd_host: kawata's passes 1-3,
                                 soft's compositor); ON / OFF force them on any back end
                                 (tests compare both; render_bench --host-ab) */
} rnd_desc;

/* A camera in the cloud file's coordinates (doubles, so georeferenced eyes keep precision).
 * fov_deg = vertical field of view. znear/zfar <= 0: derived from the cloud's bounds. */
typedef struct rnd_camera {
    double eye[3], target[3], up[3];
    float fov_deg;
    float znear, zfar;
    int width, height;
} rnd_camera;

/* rnd_camera_frame: the default camera of a cloud whose default view is v (INFO's; the rule of
 * protocol/framing.h, sp_frame_fit, shared with the clients) for a width x height frame of
 * vertical field of view fov_deg (0: SP_DEFAULT_FOV). */
void rnd_camera_frame(const sp_view *v, int width, int height, double fov_deg, rnd_camera *cam);

typedef struct rnd_frame {
    int width, height;
    uint8_t *rgba8;           /* width*height*4, rows bottom-up (GL order) */
    uint16_t *rgba16f;        /* width*height*4 half floats, or NULL (filled when want_float) */
    float *depth;             /* width*height eye-space distance along -z, or NULL; +inf where empty */
    uint64_t render_us;       /* GPU work up to glFinish */
    uint64_t readback_us;
    uint64_t points_drawn;    /* after frustum culling and the point budget */
    uint64_t splats_drawn;    /* kawata: splats of its image buffer drawn; 0 for the others */
    int buffer_w, buffer_h;   /* kawata: its image buffer's size; 0 for the others */
    uint32_t flags;           /* RND_FRAME_*: 0 for a frame drawn as asked */
    int complete;             /* 1: every node the view wants was drawn (always 1 for a flat
                                 cloud); 0: a later frame of the same view draws more */
    uint32_t lod_wanted, lod_drawn, lod_uploaded; /* LOD clouds: nodes this frame */
    /* kawata with rnd_set_kawata_probe on: its image buffer's arrays after passes 1-4
     * (pipe_kawata.c), each buffer_w x buffer_h entries, one after the other: depth, near and
     * far (a word a pixel), then pts (16 words a pixel: the nearest and the farthest point in
     * eye space, their colours, as float bits) for the pixels with a nearest point, then the
     * splats (8 words a pixel: frame x, y, depth, 1, colour, 1; 0 for none), all inside the
     * cloud's buffer rectangle; then the 8x8 tiles' marks ((buffer_w + 7) / 8 x
     * (buffer_h + 7) / 8 words, the tile rows within reach of the rectangle); everything else
     * 0 (the rest of the buffer is not used by a frame). NULL otherwise. */
    uint32_t *kawata_arrays;
} rnd_frame;

/* rnd_frame.flags (the FRAME message's flags, PROTOCOL.md). */
enum {
    /* soft, model=base|concentric: past the fragment memory cap (soft_frag_mib) some soft
     * samples were dropped, or a pixel had more overlapping spheres than the Base-Model's
     * blend holds (soft_lists.h says which and how) */
    RND_FRAME_SOFT_TRUNCATED = 1u << 0,
};

typedef struct rnd_ctx rnd_ctx;

/* rnd_create: opens the GL back end and compiles the shaders. Returns NULL with err filled. */
rnd_ctx *rnd_create(const rnd_desc *desc, sd_err *err);
void rnd_destroy(rnd_ctx *r);

/* rnd_renderer_string: "egl: llvmpipe (LLVM 15.0.6, 256 bits)" and so on. */
const char *rnd_renderer_string(const rnd_ctx *r);
/* rnd_host_paths: 1 when frames take the pipelines' host paths (rnd_desc.host_paths). */
int rnd_host_paths(const rnd_ctx *r);
const char *rnd_backend_name(const rnd_ctx *r);
/* rnd_pipeline_name: the name the implementation of pipeline i (SP_PIPE_*) gives itself, or
 * NULL when i is not one (tests check it against the parameter's value names). */
const char *rnd_pipeline_name(int i);

/* Residency. Cloud buffers on the GPU are held to a byte budget (rnd_desc.gpu_memory): a cloud
 * the renderer owns the data of (rnd_adopt) may leave the GPU, least recently rendered first,
 * when another needs the room, and comes back when it is rendered again; a cloud uploaded
 * from data the caller keeps (rnd_upload) stays. */

/* rnd_upload: copies a prepared cloud to GPU buffers, to stay there until rnd_release; returns
 * a cloud id > 0, or a negative SD_E* code (SD_ELIMIT when it does not fit the budget beside
 * the other clouds that must stay). The prepared cloud may be freed afterwards. */
int64_t rnd_upload(rnd_ctx *r, const pc_prepared *pc, sd_err *err);

/* rnd_adopt: takes a heap-allocated prepared cloud (freed by the renderer with
 * pc_prepared_free and free, on release or on failure) and uploads it, making room by evicting
 * the least recently rendered evictable clouds. Returns a cloud id > 0 or a negative SD_E*. */
int64_t rnd_adopt(rnd_ctx *r, pc_prepared *pc, sd_err *err);

/* rnd_adopt_lod: takes a heap-allocated LOD cloud (lod.h; freed by the renderer with
 * lod_cloud_free and free, on release or failure). Its nodes reach the GPU as frames want them,
 * into a node pool of rnd_desc.lod_pool_points points counted against the GPU budget (the pool
 * leaves the GPU like an adopted cloud when another cloud needs the room). Frames draw at most
 * params->point_budget points of it (0: as many as the pool holds). */
int64_t rnd_adopt_lod(rnd_ctx *r, lod_cloud *lc, sd_err *err);

/* rnd_lod_wait: waits up to timeout_ms until the loader of LOD cloud cloud_id has a node
 * ready for the next frame; returns how many are (0: none loading, a flat cloud, timeout). */
int rnd_lod_wait(rnd_ctx *r, uint32_t cloud_id, int timeout_ms);

/* rnd_lod_prefetch: the server side of PREFETCH: the nodes LOD cloud cloud_id would draw for
 * the n cameras under params' point budget are read and uploaded ahead, between frames
 * (rnd_lod_idle) and in the slots frames leave free, replacing an earlier prefetch of that
 * cloud. A flat cloud: nothing to do (0). Returns the nodes queued or a negative SD_E*. */
int rnd_lod_prefetch(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cams, int n,
                     const sp_params *params, sd_err *err);

/* rnd_lod_settle: before a frame that must be complete (a RENDER without lod_first), loads
 * and uploads every node the camera wants, without drawing in between, for at most timeout_ms.
 * Returns 1 when all are resident (always for a flat cloud), 0 when not (time, or a view the
 * pool cannot hold: the caller's frames refine as before), or a negative SD_E*. */
int rnd_lod_settle(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cam,
                   const sp_params *params, int timeout_ms, sd_err *err);

/* rnd_lod_idle: one step of every LOD cloud's prefetch (uploads what the loaders finished,
 * hands them the next nodes); returns 1 while any has work left (the caller waits a little,
 * rnd_lod_wait, and steps again), 0 when none has, or a negative SD_E*. */
int rnd_lod_idle(rnd_ctx *r, sd_err *err);

/* rnd_release: removes a cloud (its GPU buffers, its pipelines' data, adopted data). */
void rnd_release(rnd_ctx *r, uint32_t cloud_id);

typedef struct rnd_stats {
    uint64_t budget;          /* bytes */
    uint64_t resident_bytes;  /* cloud buffers on the GPU now */
    uint32_t clouds, resident;/* clouds known, and on the GPU */
    uint64_t uploads, evictions; /* since rnd_create */
    uint64_t lod_prefetched;  /* LOD nodes uploaded between frames (rnd_lod_idle) */
} rnd_stats;

/* rnd_get_stats: the residency counters. rnd_cloud_resident: 1 when cloud_id's buffers are on
 * the GPU, 0 when not, -1 for an unknown id. */
void rnd_get_stats(const rnd_ctx *r, rnd_stats *st);
int rnd_cloud_resident(const rnd_ctx *r, uint32_t cloud_id);

/* Sort-last rendering (splatd --mpi, server/mpi/): a pipeline whose per-pixel state must see
 * every rank's points before it resolves (splat: the nearest depth of pass 1, the weighted sums
 * of pass 2) hands that state over between its passes. Each callback is a collective over the
 * ranks: every rank calls it once per frame, also when it failed (rc < 0, data NULL) or has
 * nothing to draw (data all zero), so that no rank waits for one that will not come. */
typedef struct rnd_exchange {
    void *user;
    /* keys: after the visibility pass: keys[n] (per pixel, rows of width, larger = nearer,
     * 0 = empty) and rect (x0, y0, x1, y1 of the pixels touched, inclusive; x0 > x1: none)
     * become those of all ranks (the maximum, the union; keys and sums outside the union's
     * rows are zero on every rank, so an exchange may leave them out). Returns 0, or SD_E* when any rank failed (err says which). */
    int (*keys)(void *user, int rc, uint32_t *keys, size_t n, int width, int32_t rect[4],
                sd_err *err);
    /* sums: after the attribute pass: px[8 n] (per pixel 7 sums, floats when is_float, else
     * 32-bit integers that wrap, then a pad word) become the sums of all ranks on the rank
     * that resolves the frame. Returns 1 on that rank, 0 on the others, or SD_E*. */
    int (*sums)(void *user, int rc, uint32_t *px, size_t n, int is_float, sd_err *err);
} rnd_exchange;

/* rnd_set_exchange: makes the following frames sort-last (x stays the caller's; NULL: back to
 * a single process). Pipelines without per-pixel state to exchange (points) ignore it. */
void rnd_set_exchange(rnd_ctx *r, const rnd_exchange *x);

/* rnd_set_coverage: on: the following 8-bit frames keep coverage in alpha as float frames do
 * (the target's alpha cleared to 0 and written by the pipeline: 1 where an opaque surface was
 * drawn, the accumulated "over" of soft discs and layers elsewhere) instead of being opaque;
 * RGB is drawn exactly as without it. For compositing the ranks' images of soft and olt
 * (server/mpi). off (the default): opaque 8-bit frames. */
void rnd_set_coverage(rnd_ctx *r, int on);

/* rnd_set_kawata_probe: on: the following kawata frames also carry their image-buffer arrays
 * (rnd_frame.kawata_arrays), read back before pass 3's fit, so that the two places passes 1-3
 * can run (kawata_raster=gpu|cpu) can be compared array for array. For tests; costs a read-back.
 * off (the default): none. */
void rnd_set_kawata_probe(rnd_ctx *r, int on);

/* rnd_render: renders cloud_id through params->pipeline into frame (buffers allocated or
 * resized by the renderer; free with rnd_frame_free). want_float also fills rgba16f and depth.
 * Returns 0 or a negative SD_E* code. */
int rnd_render(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cam, const sp_params *params,
               int want_float, rnd_frame *frame, sd_err *err);
void rnd_frame_free(rnd_frame *f);

/* rnd_release_targets: frees the output framebuffers and the pipelines' per-pixel scratch
 * (their trim hooks), all made again at the size asked for by the next rnd_render: after a
 * large frame, an idle daemon gives their memory back (on a software renderer they are host
 * memory). The driver may hold what the last frame had bound until another frame binds
 * something else: a 1x1 frame after this call lets it go too. */
void rnd_release_targets(rnd_ctx *r);
