/* render.c — the renderer (render.h): the GL back end, the function table, the shaders, the
 * uploaded clouds (ids = index + generation), the output target, and one frame's sequence:
 * view, culling, clear, pipeline, glFinish, read-back. */
#include "render.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "camera.h"
#include "gl_api.h"
#include "gl_backend.h"
#include "gl_names.h"
#include "pipe.h"
#include "shaders.h"

/* Pipelines by params->pipeline, from the one list (protocol/pipelines.h). */
static const rnd_pipeline *const pipelines[] = {
#define RND_PIPE_ROW_(id, name) [SP_PIPE_##id] = &pipe_##name,
    SP_PIPELINE_LIST(RND_PIPE_ROW_)
#undef RND_PIPE_ROW_
};
enum { NPIPES = SP_PIPE_COUNT };
_Static_assert(sizeof pipelines / sizeof pipelines[0] == SP_PIPE_COUNT, "one row per pipeline");
enum { MAX_SLOTS = 0xFFFF, ID_INDEX_BITS = 16 };
enum { TARGET_8 = 0, TARGET_F = 1 };

typedef struct cloud_slot {
    rnd_gpu_cloud c;
    uint16_t gen;  /* bumped on each upload into the slot; never 0 in a live id */
    int used;
} cloud_slot;

struct rnd_ctx {
    const gl_backend_ops *ops;
    gl_backend *be;
    gl_api gl;
    rnd_shaders *sh;
    char renderer[320];
    int max_width, max_height;
    void *pstate[NPIPES];
    int pcreated[NPIPES];
    cloud_slot *slots;
    uint32_t nslots;
    /* The two targets (pipe.h), each made on first use and remade when the size changes:
     * [TARGET_8] RGBA8 for 8-bit frames, read back as it is; [TARGET_F] RGBA16F + R32F depth
     * for float frames, blitted into [TARGET_8] for their RGBA8 copy (glReadPixels of RGBA16F
     * as unsigned bytes takes Mesa's per-pixel conversion path, ~15 ms at 1280x720).
     * Rendering 8-bit frames straight into RGBA8 saves the float clear and that blit: ~10 ms
     * of a 1280x720 frame on llvmpipe. */
    rnd_target target[2];
    uint32_t *range_first, *range_count;
    uint64_t range_cap;
};

static uint64_t now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

/* Opens one back end and loads the GL table. Returns 0 or the back end's error. */
static int open_backend(rnd_ctx *r, const gl_backend_ops *ops, sd_err *err)
{
    int rc = ops->create(&r->be, err);
    if (rc < 0) return rc;
    r->ops = ops;
    rc = gl_api_load(&r->gl, ops->getproc, r->be, err);
    if (rc < 0) {
        ops->destroy(r->be);
        r->be = NULL;
        r->ops = NULL;
    }
    return rc;
}

rnd_ctx *rnd_create(const rnd_desc *desc, sd_err *err)
{
    rnd_desc d = desc ? *desc : (rnd_desc){0};
    if (!d.max_width) d.max_width = 8192;
    if (!d.max_height) d.max_height = 8192;
    if (d.max_width < 1 || d.max_height < 1 || d.backend < RND_BACKEND_AUTO ||
        d.backend > RND_BACKEND_OSMESA) {
        sd_errf(err, SD_EINVAL, "bad renderer description (backend %d, max size %dx%d)",
                (int)d.backend, d.max_width, d.max_height);
        return NULL;
    }
    rnd_ctx *r = calloc(1, sizeof *r);
    if (!r) {
        sd_errf(err, SD_ENOMEM, "out of memory for the renderer");
        return NULL;
    }
    r->max_width = d.max_width;
    r->max_height = d.max_height;
    int rc;
    if (d.backend == RND_BACKEND_EGL) {
        rc = open_backend(r, &gl_backend_egl, err);
    } else if (d.backend == RND_BACKEND_OSMESA) {
        rc = open_backend(r, &gl_backend_osmesa, err);
    } else {
        sd_err e1 = {0};
        rc = open_backend(r, &gl_backend_egl, &e1);
        if (rc < 0) {
            sd_err e2 = {0};
            rc = open_backend(r, &gl_backend_osmesa, &e2);
            if (rc < 0) sd_errf(err, rc, "no GL back end: %s; OSMesa: %s", e1.msg, e2.msg);
        }
    }
    if (rc < 0) goto fail;
    const char *ren = (const char *)r->gl.GetString(GL_RENDERER);
    snprintf(r->renderer, sizeof r->renderer, "%s: %s; %s", r->ops->name, ren ? ren : "?",
             r->ops->describe(r->be));
    r->sh = rnd_shaders_create(d.shader_dir, err);
    if (!r->sh) goto fail;
    /* Every pipeline is built now, so the first frame does not pay for shader compilation.
     * The baseline must build (broken shaders or a driver without compute shaders show at
     * start-up); another that fails is retried, and its error reported, when a frame asks
     * for it. */
    rc = pipelines[SP_PIPE_POINTS]->create(&r->gl, r->sh, &r->pstate[SP_PIPE_POINTS], err);
    if (rc < 0) goto fail;
    r->pcreated[SP_PIPE_POINTS] = 1;
    for (int i = 0; i < NPIPES; i++) {
        if (r->pcreated[i]) continue;
        sd_err ignored = {0};
        r->pcreated[i] = pipelines[i]->create(&r->gl, r->sh, &r->pstate[i], &ignored) == 0;
    }
    return r;
fail:
    rnd_destroy(r);
    return NULL;
}

static void target_free(const gl_api *gl, rnd_target *t)
{
    if (t->fbo) gl->DeleteFramebuffers(1, &t->fbo);
    GLuint tex[2] = {t->color, t->depth_eye};
    if (t->color || t->depth_eye) gl->DeleteTextures(2, tex);
    if (t->depth_rb) gl->DeleteRenderbuffers(1, &t->depth_rb);
    memset(t, 0, sizeof *t);
}

static void gpu_cloud_free(rnd_ctx *r, rnd_gpu_cloud *c)
{
    GLuint b[6] = {c->pos, c->normal, c->radius, c->rgba, c->field, c->intensity};
    r->gl.DeleteBuffers(6, b);
    free(c->batches);
    memset(c, 0, sizeof *c);
}

void rnd_destroy(rnd_ctx *r)
{
    if (!r) return;
    if (r->be) {
        r->ops->make_current(r->be, NULL);
        for (int i = 0; i < NPIPES; i++)
            if (r->pcreated[i]) pipelines[i]->destroy(&r->gl, r->pstate[i]);
        for (uint32_t i = 0; i < r->nslots; i++)
            if (r->slots[i].used) gpu_cloud_free(r, &r->slots[i].c);
        target_free(&r->gl, &r->target[TARGET_8]);
        target_free(&r->gl, &r->target[TARGET_F]);
        r->ops->destroy(r->be);
    }
    rnd_shaders_destroy(r->sh);
    free(r->slots);
    free(r->range_first);
    free(r->range_count);
    memset(r, 0, sizeof *r);
    free(r);
}

const char *rnd_renderer_string(const rnd_ctx *r)
{
    return r->renderer;
}

const char *rnd_pipeline_name(int i)
{
    return i >= 0 && i < NPIPES ? pipelines[i]->name : NULL;
}

const char *rnd_backend_name(const rnd_ctx *r)
{
    return r->ops->name;
}

/* Creates buffer *b (left bound to GL_SHADER_STORAGE_BUFFER) holding len bytes from data, or
 * zeros when data is NULL. */
static void make_buffer(const gl_api *gl, GLuint *b, uint64_t len, const void *data)
{
    gl->GenBuffers(1, b);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, *b);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)len, data, GL_STATIC_DRAW);
    if (!data) {
        const GLuint zero = 0;
        gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                            &zero);
    }
}

/* Uploads intensity normalised to [0,1] by the cloud's minimum and maximum, in chunks. */
static int upload_intensity(const gl_api *gl, GLuint b, const float *in, uint64_t n, sd_err *err)
{
    float lo = INFINITY, hi = -INFINITY;
    for (uint64_t i = 0; i < n; i++) {
        if (!isfinite(in[i])) continue;
        lo = fminf(lo, in[i]);
        hi = fmaxf(hi, in[i]);
    }
    float scale = hi > lo ? 1.0f / (hi - lo) : 0.0f; /* constant intensity: all 1 */
    enum { CHUNK = 1 << 16 };
    float *tmp = malloc(CHUNK * sizeof *tmp);
    if (!tmp) return sd_errf(err, SD_ENOMEM, "out of memory uploading intensities");
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, b);
    for (uint64_t i = 0; i < n; i += CHUNK) {
        uint64_t m = n - i < CHUNK ? n - i : CHUNK;
        for (uint64_t j = 0; j < m; j++) {
            float x = in[i + j];
            tmp[j] = isfinite(x) ? (scale > 0 ? (x - lo) * scale : 1.0f) : 0.0f;
        }
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(i * 4), (GLsizeiptr)(m * 4), tmp);
    }
    free(tmp);
    return 0;
}

int64_t rnd_upload(rnd_ctx *r, const pc_prepared *pc, sd_err *err)
{
    if (!pc || !pc->pos || pc->n == 0)
        return sd_errf(err, SD_EEMPTY, "cannot upload a cloud without points");
    if (pc->n >= ((uint64_t)1 << 31))
        return sd_errf(err, SD_ELIMIT, "a cloud of %llu points is over the renderer's limit of "
                       "2^31 - 1", (unsigned long long)pc->n);
    for (uint64_t i = 0; i < pc->nbatches; i++) {
        const pc_batch *b = &pc->batches[i];
        if ((uint64_t)b->first + b->count > pc->n)
            return sd_errf(err, SD_EFORMAT, "batch %llu [%u, +%u) reaches past the cloud's %llu "
                           "points", (unsigned long long)i, b->first, b->count,
                           (unsigned long long)pc->n);
    }
    uint32_t idx = 0;
    while (idx < r->nslots && r->slots[idx].used) idx++;
    if (idx == r->nslots) {
        if (r->nslots >= MAX_SLOTS)
            return sd_errf(err, SD_ELIMIT, "too many clouds uploaded (%u)", r->nslots);
        cloud_slot *s = realloc(r->slots, (r->nslots + 1) * sizeof *s);
        if (!s) return sd_errf(err, SD_ENOMEM, "out of memory for a cloud slot");
        r->slots = s;
        memset(&s[idx], 0, sizeof *s);
        r->nslots++;
    }
    cloud_slot *slot = &r->slots[idx];
    rnd_gpu_cloud *c = &slot->c;
    memset(c, 0, sizeof *c);
    uint64_t n = pc->n;
    c->n = n;
    c->attrs = pc->attrs;
    /* Batches: a cloud without them (made in memory) gets one covering everything. */
    c->nbatches = pc->nbatches ? pc->nbatches : 1;
    c->batches = malloc(c->nbatches * sizeof *c->batches);
    if (!c->batches) return sd_errf(err, SD_ENOMEM, "out of memory for the batch table");
    for (int i = 0; i < 3; i++) {
        c->offset[i] = pc->offset[i];
        c->bmin[i] = (float)(pc->bmin[i] - pc->offset[i]);
        c->bmax[i] = (float)(pc->bmax[i] - pc->offset[i]);
    }
    if (pc->nbatches) {
        memcpy(c->batches, pc->batches, c->nbatches * sizeof *c->batches);
    } else {
        c->batches[0] = (pc_batch){.first = 0, .count = (uint32_t)n};
        memcpy(c->batches[0].bmin, c->bmin, sizeof c->bmin);
        memcpy(c->batches[0].bmax, c->bmax, sizeof c->bmax);
    }
    c->sigma = pc->sigma;
    c->radius_median = pc->radius_median;

    const gl_api *gl = &r->gl;
    r->ops->make_current(r->be, NULL);
    int rc = 0;
    make_buffer(gl, &c->pos, n * 12, pc->pos);
    make_buffer(gl, &c->normal, n * 12, pc->normal);
    make_buffer(gl, &c->radius, n * 4, pc->radius);
    make_buffer(gl, &c->field, n * 4, pc->F);
    make_buffer(gl, &c->rgba, n * 4, (pc->attrs & PC_ATTR_RGB) ? pc->rgba : NULL);
    if (!(pc->attrs & PC_ATTR_RGB) || !pc->rgba) {
        const GLuint white = 0xFFFFFFFFu;
        gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                            &white);
    }
    make_buffer(gl, &c->intensity, n * 4, NULL);
    if ((pc->attrs & PC_ATTR_INTENSITY) && pc->intensity)
        rc = upload_intensity(gl, c->intensity, pc->intensity, n, err);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    if (rc == 0) rc = gl_check(gl, "uploading a cloud", err);
    if (rc < 0) {
        gpu_cloud_free(r, c);
        return rc;
    }
    if (c->nbatches > r->range_cap) {
        uint32_t *f = realloc(r->range_first, c->nbatches * sizeof *f);
        if (f) r->range_first = f;
        uint32_t *k = realloc(r->range_count, c->nbatches * sizeof *k);
        if (k) r->range_count = k;
        if (!f || !k) {
            gpu_cloud_free(r, c);
            return sd_errf(err, SD_ENOMEM, "out of memory for the range table");
        }
        r->range_cap = c->nbatches;
    }
    if (++slot->gen == 0) slot->gen = 1;
    slot->used = 1;
    return (int64_t)(((uint32_t)slot->gen << ID_INDEX_BITS) | (idx + 1));
}

/* The slot of a live id, or NULL for 0, an unknown index or a stale generation. */
static cloud_slot *lookup(rnd_ctx *r, uint32_t id)
{
    uint32_t idx = (id & ((1u << ID_INDEX_BITS) - 1)), gen = id >> ID_INDEX_BITS;
    if (idx == 0 || idx > r->nslots) return NULL;
    cloud_slot *s = &r->slots[idx - 1];
    return s->used && s->gen == gen ? s : NULL;
}

void rnd_release(rnd_ctx *r, uint32_t cloud_id)
{
    cloud_slot *s = lookup(r, cloud_id);
    if (!s) return;
    r->ops->make_current(r->be, NULL);
    gpu_cloud_free(r, &s->c);
    s->used = 0;
}

static GLuint make_texture(const gl_api *gl, GLenum format, int w, int h)
{
    GLuint tex = 0;
    gl->GenTextures(1, &tex);
    gl->BindTexture(GL_TEXTURE_2D, tex);
    gl->TexStorage2D(GL_TEXTURE_2D, 1, format, w, h);
    gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    gl->BindTexture(GL_TEXTURE_2D, 0);
    return tex;
}

/* Makes target `which` w x h (recreating its attachments when the size changes). Returns 0 or
 * SD_EGL. */
static int target_ensure(rnd_ctx *r, int which, int w, int h, sd_err *err)
{
    rnd_target *t = &r->target[which];
    if (t->fbo && t->width == w && t->height == h) return 0;
    const gl_api *gl = &r->gl;
    target_free(gl, t);
    int is_float = which == TARGET_F;
    t->color = make_texture(gl, is_float ? GL_RGBA16F : GL_RGBA8, w, h);
    if (is_float) t->depth_eye = make_texture(gl, GL_R32F, w, h);
    gl->GenRenderbuffers(1, &t->depth_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, t->depth_rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
    gl->BindRenderbuffer(GL_RENDERBUFFER, 0);
    gl->GenFramebuffers(1, &t->fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, t->color, 0);
    if (is_float)
        gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D,
                                 t->depth_eye, 0);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t->depth_rb);
    /* Fragment output 1 (eye depth) goes nowhere in the 8-bit target. */
    const GLenum bufs[2] = {GL_COLOR_ATTACHMENT0, is_float ? GL_COLOR_ATTACHMENT1 : GL_NONE};
    gl->DrawBuffers(2, bufs);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    GLenum st = gl->CheckFramebufferStatus(GL_FRAMEBUFFER);
    gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
    int rc = 0;
    char buf[32];
    if (st != GL_FRAMEBUFFER_COMPLETE)
        rc = sd_errf(err, SD_EGL, "the %dx%d %s output framebuffer is incomplete: %s", w, h,
                     is_float ? "RGBA16F" : "RGBA8", gl_error_name(st, buf, sizeof buf));
    if (rc == 0) rc = gl_check(gl, "creating the output framebuffer", err);
    if (rc < 0) {
        target_free(gl, t);
        return rc;
    }
    t->width = w;
    t->height = h;
    t->is_float = is_float;
    return 0;
}

/* Resizes frame f's buffers for w x h (float ones only when want_float). */
static int frame_ensure(rnd_frame *f, int w, int h, int want_float, sd_err *err)
{
    size_t npix = (size_t)w * (size_t)h;
    if (f->width != w || f->height != h || !f->rgba8) {
        free(f->rgba8);
        free(f->rgba16f);
        free(f->depth);
        f->rgba8 = NULL, f->rgba16f = NULL, f->depth = NULL;
        f->width = w;
        f->height = h;
    }
    if (!f->rgba8) f->rgba8 = malloc(npix * 4);
    if (want_float) {
        if (!f->rgba16f) f->rgba16f = malloc(npix * 4 * sizeof *f->rgba16f);
        if (!f->depth) f->depth = malloc(npix * sizeof *f->depth);
    } else {
        free(f->rgba16f);
        free(f->depth);
        f->rgba16f = NULL, f->depth = NULL;
    }
    if (!f->rgba8 || (want_float && (!f->rgba16f || !f->depth))) {
        rnd_frame_free(f);
        return sd_errf(err, SD_ENOMEM, "out of memory for a %dx%d frame", w, h);
    }
    return 0;
}

int rnd_render(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cam, const sp_params *params,
               int want_float, rnd_frame *frame, sd_err *err)
{
    if (!cam || !params || !frame) return sd_errf(err, SD_EINVAL, "rnd_render: NULL argument");
    cloud_slot *slot = lookup(r, cloud_id);
    if (!slot) return sd_errf(err, SD_EINVAL, "cloud id %u is not (or no longer) loaded", cloud_id);
    if (cam->width < 1 || cam->height < 1 || cam->width > r->max_width ||
        cam->height > r->max_height)
        return sd_errf(err, SD_ELIMIT, "frame size %dx%d is outside 1x1 to %dx%d", cam->width,
                       cam->height, r->max_width, r->max_height);
    int pi = params->pipeline;
    if (pi < 0 || pi >= NPIPES)
        return sd_errf(err, SD_EINVAL, "pipeline %d is not one of the %d pipelines", pi, NPIPES);
    const rnd_gpu_cloud *c = &slot->c;
    rnd_view v;
    int rc = rnd__view_setup(cam, c->offset, c->bmin, c->bmax, &v, err);
    if (rc < 0) return rc;
    uint64_t budget = params->point_budget > 0 ? (uint64_t)params->point_budget : 0;
    v.nranges = rnd__cull(&v, c->batches, c->nbatches, budget, r->range_first, r->range_count,
                          &v.points_visible);
    v.range_first = r->range_first;
    v.range_count = r->range_count;

    const gl_api *gl = &r->gl;
    if ((rc = r->ops->make_current(r->be, err)) < 0) return rc;
    if (!r->pcreated[pi]) {
        rc = pipelines[pi]->create(gl, r->sh, &r->pstate[pi], err);
        if (rc < 0) return rc;
        r->pcreated[pi] = 1;
    }
    /* Float frames render into TARGET_F and are copied into TARGET_8 for their RGBA8. */
    if ((rc = target_ensure(r, TARGET_8, cam->width, cam->height, err)) < 0) return rc;
    if (want_float && (rc = target_ensure(r, TARGET_F, cam->width, cam->height, err)) < 0)
        return rc;
    if ((rc = frame_ensure(frame, cam->width, cam->height, want_float, err)) < 0) return rc;

    uint64_t t0 = now_us();
    const rnd_target *t8 = &r->target[TARGET_8];
    const rnd_target *t = want_float ? &r->target[TARGET_F] : t8;
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    gl->Viewport(0, 0, cam->width, cam->height);
    /* 8-bit frames are opaque: alpha is cleared to 1 and masked off while the pipeline draws
     * (pipe.h); the float target keeps coverage in alpha. */
    const float bg[4] = {params->background[0], params->background[1], params->background[2],
                         t->is_float ? 0.0f : 1.0f};
    const float inf[4] = {INFINITY, 0, 0, 0};
    /* The depth renderbuffer is left to the pipelines that test depth (pipe.h). */
    gl->ClearBufferfv(GL_COLOR, 0, bg);
    if (t->is_float) gl->ClearBufferfv(GL_COLOR, 1, inf);
    else gl->ColorMaski(0, GL_TRUE, GL_TRUE, GL_TRUE, GL_FALSE);
    rc = pipelines[pi]->render(gl, r->pstate[pi], c, &v, params, t, err);
    /* The pipeline may have bound other framebuffers and state. */
    gl->ColorMaski(0, GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->Disable(GL_DEPTH_TEST);
    gl->Disable(GL_BLEND);
    gl->Disable(GL_SCISSOR_TEST);
    if (rc < 0) return rc;
    if (t->is_float) {
        gl->BindFramebuffer(GL_READ_FRAMEBUFFER, t->fbo);
        gl->ReadBuffer(GL_COLOR_ATTACHMENT0); /* the last read-back left it on the depth */
        gl->BindFramebuffer(GL_DRAW_FRAMEBUFFER, t8->fbo);
        gl->BlitFramebuffer(0, 0, cam->width, cam->height, 0, 0, cam->width, cam->height,
                            GL_COLOR_BUFFER_BIT, GL_NEAREST);
        const float opaque[4] = {0, 0, 0, 1};
        gl->BindFramebuffer(GL_FRAMEBUFFER, t8->fbo);
        gl->ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_TRUE);
        gl->ClearBufferfv(GL_COLOR, 0, opaque);
        gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    }
    gl->Finish();
    uint64_t t1 = now_us();

    gl->PixelStorei(GL_PACK_ALIGNMENT, 1);
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    gl->BindFramebuffer(GL_READ_FRAMEBUFFER, t8->fbo);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl->ReadPixels(0, 0, cam->width, cam->height, GL_RGBA, GL_UNSIGNED_BYTE, frame->rgba8);
    if (want_float) {
        gl->BindFramebuffer(GL_READ_FRAMEBUFFER, t->fbo);
        gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
        gl->ReadPixels(0, 0, cam->width, cam->height, GL_RGBA, GL_HALF_FLOAT, frame->rgba16f);
        gl->ReadBuffer(GL_COLOR_ATTACHMENT1);
        gl->ReadPixels(0, 0, cam->width, cam->height, GL_RED, GL_FLOAT, frame->depth);
    }
    gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
    uint64_t t2 = now_us();
    frame->render_us = t1 - t0;
    frame->readback_us = t2 - t1;
    frame->points_drawn = v.points_visible;
    return gl_check(gl, "rendering a frame", err);
}

void rnd_frame_free(rnd_frame *f)
{
    if (!f) return;
    free(f->rgba8);
    free(f->rgba16f);
    free(f->depth);
    memset(f, 0, sizeof *f);
}
