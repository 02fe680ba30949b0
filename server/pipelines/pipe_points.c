/* pipe_points.c — the `points` pipeline: z-buffered points, one colour per point, the baseline
 * every other pipeline's cost is measured against.
 *
 * Forms (DESIGN.md "Rasterisation strategy"):
 *   packed   points_raster.comp once: atomicMin of a 32-bit key (log depth quantised to the
 *            high bits, point index in the low ones) into a per-pixel storage buffer, then
 *            points_resolve.vert/.frag (a full-frame pass writing colour and exact eye depth
 *            of each pixel's winner). Needs >= 12 depth bits: clouds below 2^20 points.
 *   exact    the same with two passes over the points (float depth, then index), for any
 *            size and exact depth order.
 *   gl       GL_POINTS with the depth test (points.vert + points.frag), one glMultiDrawArrays
 *            over the visible ranges. 3-6x slower than packed on llvmpipe (2 cores, 1M points).
 * rnd_desc.pipe.points_raster (RND_RASTER_*: auto, packed, exact, gl; tests and benchmarks set
 * it) picks one; auto takes packed, else exact, else gl when a per-pixel buffer of the frame
 * passes the largest storage block the driver allows. All give the same image up to
 * pixel-edge rounding: a point covers the pixels whose centres lie in the square of side
 * point_size around its projection, the nearest point wins (packed: up to its depth quantum),
 * ties go to the lower index.
 *
 * A cloud in several buffer sets (pipe.h) is drawn set by set: the raster passes key points by
 * their cloud-wide index (the set's base + its index in the set), so depth and ties resolve
 * across sets exactly as for one set, and the resolve runs once per set, each pass colouring
 * the pixels its own points won. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "pipe.h"
#include "shaders.h"

enum { PACKED_MIN_DEPTH_BITS = 12 };
enum { GROUP = 64, MAX_GROUPS_X = 65535 }; /* local_size_x of points_raster.comp */

typedef struct points_state {
    uint32_t per_invocation;          /* points per compute invocation */
    GLuint prog_gl, prog_raster, prog_resolve;
    GLuint vao;
    GLuint depth_buf, index_buf;      /* per pixel: RND_B_POINTS_DEPTH, RND_B_POINTS_INDEX */
    GLuint depth_tex, index_tex;      /* the same on RND_T_POINTS_DEPTH, RND_T_POINTS_INDEX */
    uint64_t depth_bytes, index_bytes;
    GLint *gl_first;                  /* GL_POINTS form: one set's chunks for glMultiDrawArrays */
    GLsizei *gl_count;
    uint32_t gl_cap;
    /* uniform locations */
    GLint g_viewproj, g_point_size, g_color, g_znear, g_zfar;
    GLint r_viewproj, r_size, r_point_size, r_znear, r_zfar, r_total, r_nranges, r_first;
    GLint r_stride, r_threads, r_per, r_pass, r_index_bits, r_log_near, r_log_scale, r_base;
    GLint s_width, s_color, s_znear, s_zfar, s_index_bits, s_viewproj, s_base, s_count;
} points_state;

static void points_destroy(rnd_kit *k, void *state)
{
    points_state *s = state;
    if (!s) return;
    const gl_api *gl = k->gl;
    if (s->prog_gl) gl->DeleteProgram(s->prog_gl);
    if (s->prog_raster) gl->DeleteProgram(s->prog_raster);
    if (s->prog_resolve) gl->DeleteProgram(s->prog_resolve);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    GLuint tex[2] = {s->depth_tex, s->index_tex};
    if (tex[0] || tex[1]) gl->DeleteTextures(2, tex);
    GLuint bufs[2] = {s->depth_buf, s->index_buf};
    gl->DeleteBuffers(2, bufs);
    free(s->gl_first);
    free(s->gl_count);
    memset(s, 0, sizeof *s);
    free(s);
}

static int points_create(rnd_kit *k, void **state, sd_err *err)
{
    *state = NULL;
    const gl_api *gl = k->gl;
    if (k->opts.points_raster < RND_RASTER_AUTO || k->opts.points_raster > RND_RASTER_GL)
        return sd_errf(err, SD_EINVAL, "points raster form %d is not auto, packed, exact or gl",
                       k->opts.points_raster);
    points_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory for the points pipeline");
    /* llvmpipe spends ~50 ns on each compute invocation however little it does (measured:
     * one point per invocation costs twice as much as 32), so there each invocation takes a
     * run of points; a GPU wants one each. */
    s->per_invocation = k->software ? 32 : 1;

    const char *const gl_files[2] = {"points.vert", "points.frag"};
    const char *const raster_files[1] = {"points_raster.comp"};
    const char *const resolve_files[2] = {"points_resolve.vert", "points_resolve.frag"};
    if (!(s->prog_gl = rnd_kit_program(k, gl_files, 2, NULL, err))) goto fail;
    if (!(s->prog_raster = rnd_kit_program(k, raster_files, 1, NULL, err))) goto fail;
    if (!(s->prog_resolve = rnd_kit_program(k, resolve_files, 2, NULL, err))) goto fail;
    gl->GenVertexArrays(1, &s->vao);
    gl->GenTextures(1, &s->depth_tex);
    gl->GenTextures(1, &s->index_tex);
    s->g_viewproj = gl_uniform(gl, s->prog_gl, "u_viewproj");
    s->g_point_size = gl_uniform(gl, s->prog_gl, "u_point_size");
    s->g_color = gl_uniform(gl, s->prog_gl, "u_color");
    s->g_znear = gl_uniform(gl, s->prog_gl, "u_znear");
    s->g_zfar = gl_uniform(gl, s->prog_gl, "u_zfar");
    s->r_viewproj = gl_uniform(gl, s->prog_raster, "u_viewproj");
    s->r_size = gl_uniform(gl, s->prog_raster, "u_size");
    s->r_point_size = gl_uniform(gl, s->prog_raster, "u_point_size");
    s->r_znear = gl_uniform(gl, s->prog_raster, "u_znear");
    s->r_zfar = gl_uniform(gl, s->prog_raster, "u_zfar");
    s->r_total = gl_uniform(gl, s->prog_raster, "u_total");
    s->r_nranges = gl_uniform(gl, s->prog_raster, "u_nranges");
    s->r_first = gl_uniform(gl, s->prog_raster, "u_first");
    s->r_stride = gl_uniform(gl, s->prog_raster, "u_stride");
    s->r_threads = gl_uniform(gl, s->prog_raster, "u_threads");
    s->r_per = gl_uniform(gl, s->prog_raster, "u_per");
    s->r_pass = gl_uniform(gl, s->prog_raster, "u_pass");
    s->r_index_bits = gl_uniform(gl, s->prog_raster, "u_index_bits");
    s->r_log_near = gl_uniform(gl, s->prog_raster, "u_log_near");
    s->r_log_scale = gl_uniform(gl, s->prog_raster, "u_log_scale");
    s->r_base = gl_uniform(gl, s->prog_raster, "u_base");
    s->s_index_bits = gl_uniform(gl, s->prog_resolve, "u_index_bits");
    s->s_viewproj = gl_uniform(gl, s->prog_resolve, "u_viewproj");
    s->s_width = gl_uniform(gl, s->prog_resolve, "u_width");
    s->s_color = gl_uniform(gl, s->prog_resolve, "u_color");
    s->s_znear = gl_uniform(gl, s->prog_resolve, "u_znear");
    s->s_zfar = gl_uniform(gl, s->prog_resolve, "u_zfar");
    s->s_base = gl_uniform(gl, s->prog_resolve, "u_base");
    s->s_count = gl_uniform(gl, s->prog_resolve, "u_count");
    if (gl_check(gl, "creating the points pipeline", err) < 0) goto fail;
    *state = s;
    return 0;
fail:
    points_destroy(k, s);
    return err && err->code ? err->code : SD_EGL;
}

/* Binds buffer set b's attribute buffers to vertex attributes 0-5 of the bound VAO. */
static void bind_attributes(const gl_api *gl, const rnd_bufset *b)
{
    const struct {
        GLuint buf;
        GLint n;
        GLenum type;
        GLboolean norm;
    } attr[6] = {
        {b->buf[RND_ATTR_POS], 3, GL_FLOAT, GL_FALSE},
        {b->buf[RND_ATTR_RGBA], 4, GL_UNSIGNED_BYTE, GL_TRUE},
        {b->buf[RND_ATTR_NORMAL], 3, GL_FLOAT, GL_FALSE},
        {b->buf[RND_ATTR_FIELD], 1, GL_FLOAT, GL_FALSE},
        {b->buf[RND_ATTR_INTENSITY], 1, GL_FLOAT, GL_FALSE},
        {b->buf[RND_ATTR_SCAN], 1, GL_FLOAT, GL_FALSE},
    };
    for (GLuint i = 0; i < 6; i++) {
        gl->BindBuffer(GL_ARRAY_BUFFER, attr[i].buf);
        gl->VertexAttribPointer(i, attr[i].n, attr[i].type, attr[i].norm, 0, NULL);
        gl->EnableVertexAttribArray(i);
    }
    gl->BindBuffer(GL_ARRAY_BUFFER, 0);
}

/* The GL_POINTS form: one glMultiDrawArrays per buffer set over its visible chunks. */
static int render_gl(const gl_api *gl, points_state *s, const rnd_gpu_cloud *c,
                     const rnd_view *v, const sp_params *p, sd_err *err)
{
    if (v->nchunks > s->gl_cap) {
        GLint *f = realloc(s->gl_first, v->nchunks * sizeof *f);
        if (f) s->gl_first = f;
        GLsizei *n = realloc(s->gl_count, v->nchunks * sizeof *n);
        if (n) s->gl_count = n;
        if (!f || !n) return sd_errf(err, SD_ENOMEM, "out of memory for %u chunks", v->nchunks);
        s->gl_cap = v->nchunks;
    }
    gl->UseProgram(s->prog_gl);
    gl->UniformMatrix4fv(s->g_viewproj, 1, GL_FALSE, v->viewproj);
    gl->Uniform1f(s->g_point_size, p->point_size);
    gl->Uniform1i(s->g_color, p->color);
    gl->Uniform1f(s->g_znear, v->znear);
    gl->Uniform1f(s->g_zfar, v->zfar);
    gl->BindVertexArray(s->vao);
    const float one = 1.0f;
    gl->DepthMask(GL_TRUE);
    gl->ClearBufferfv(GL_DEPTH, 0, &one); /* the renderer leaves it to us (pipe.h) */
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthFunc(GL_LESS);
    gl->Enable(GL_PROGRAM_POINT_SIZE);
    for (uint32_t a = 0; a < v->nchunks;) {
        uint32_t set = v->chunks[a].set, n = 0;
        for (; a < v->nchunks && v->chunks[a].set == set; a++, n++) {
            /* GLint/GLsizei: a buffer set holds fewer than 2^31 points (render.c) */
            s->gl_first[n] = (GLint)v->chunks[a].first;
            s->gl_count[n] = (GLsizei)v->chunks[a].count;
        }
        bind_attributes(gl, &c->sets[set]);
        gl->MultiDrawArrays(GL_POINTS, s->gl_first, s->gl_count, (GLsizei)n);
    }
    gl->Disable(GL_PROGRAM_POINT_SIZE);
    gl->Disable(GL_DEPTH_TEST);
    for (GLuint i = 0; i < 5; i++) gl->DisableVertexAttribArray(i);
    gl->BindVertexArray(0);
    gl->UseProgram(0);
    return GL_CHECK_PASS(gl, "the points pass (GL_POINTS)", err);
}

/* A dispatch of gx x gy groups of GROUP holding at least `threads` invocations (2-D beyond
 * 65535 groups). */
static void dispatch_size(uint32_t threads, uint32_t *gx, uint32_t *gy)
{
    uint32_t groups = (threads + GROUP - 1) / GROUP;
    if (!groups) groups = 1;
    *gx = groups < MAX_GROUPS_X ? groups : MAX_GROUPS_X;
    *gy = (groups + *gx - 1) / *gx;
}

/* Bits for a point index of a cloud of n points, leaving the all-ones key free for "empty":
 * the smallest b with n <= 2^b - 1. */
static uint32_t index_bits(uint64_t n)
{
    uint32_t b = 1;
    while (b < 32 && ((uint64_t)1 << b) - 1 < n) b++;
    return b;
}

/* bind_pixel_buffer: the per-pixel buffer buf (grown to npix uints) on storage block
 * `block` and, through tex, on texture unit `unit`. */
static void bind_pixel_buffer(const gl_api *gl, GLuint *buf, uint64_t *have, GLuint tex,
                              uint64_t npix, GLuint block, GLenum unit)
{
    rnd_kit_ensure_ssbo(gl, buf, have, npix * 4);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, block, *buf);
    gl->ActiveTexture(GL_TEXTURE0 + unit);
    gl->BindTexture(GL_TEXTURE_BUFFER, tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, *buf);
    gl->ActiveTexture(GL_TEXTURE0);
}

/* One raster pass over the visible points of buffer set `set` (ranges bound by the caller). */
static void raster_set(const gl_api *gl, const points_state *s, const rnd_gpu_cloud *c,
                       uint32_t set, uint32_t total, uint32_t nranges, uint32_t first, int pass)
{
    uint32_t gx, gy;
    dispatch_size((total + s->per_invocation - 1) / s->per_invocation, &gx, &gy);
    uint32_t threads = gx * gy * GROUP;
    gl->Uniform1ui(s->r_total, total);
    gl->Uniform1ui(s->r_nranges, nranges);
    gl->Uniform1ui(s->r_first, first);
    gl->Uniform1ui(s->r_stride, gx * GROUP);
    gl->Uniform1ui(s->r_threads, threads);
    gl->Uniform1ui(s->r_per, (total + threads - 1) / threads);
    gl->Uniform1ui(s->r_base, (GLuint)c->sets[set].base);
    gl->Uniform1i(s->r_pass, pass);
    gl->DispatchCompute(gx, gy, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* The compute forms: packed (ibits > 0: one pass) or exact (two passes), each over every
 * buffer set, then the resolve into the target, once per set. */
static int render_compute(rnd_kit *k, points_state *s, const rnd_gpu_cloud *c,
                          const rnd_view *v, const sp_params *p, uint32_t ibits, sd_err *err)
{
    const gl_api *gl = k->gl;
    uint64_t npix = (uint64_t)v->width * (uint64_t)v->height;
    /* Only the rows of the cloud's screen rectangle are cleared and resolved: points cannot
     * land outside it, and what they might write outside by rounding is never read. */
    int rect[4];
    rnd__screen_rect(v, c->bmin, c->bmax, (int)ceilf(p->point_size * 0.5f) + 1, rect);
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) return 0;
    bind_pixel_buffer(gl, &s->depth_buf, &s->depth_bytes, s->depth_tex, npix, RND_B_POINTS_DEPTH,
                      RND_T_POINTS_DEPTH);
    bind_pixel_buffer(gl, &s->index_buf, &s->index_bytes, s->index_tex, npix, RND_B_POINTS_INDEX,
                      RND_T_POINTS_INDEX);
    GLintptr row0 = (GLintptr)rect[1] * v->width * 4;
    GLsizeiptr rows = (GLsizeiptr)(rect[3] - rect[1]) * v->width * 4;
    const GLuint ones = 0xFFFFFFFFu;
    const GLuint pix[2] = {s->depth_buf, s->index_buf};
    for (int i = 0; i < (ibits ? 1 : 2); i++) {
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, pix[i]);
        gl->ClearBufferSubData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, row0, rows, GL_RED_INTEGER,
                               GL_UNSIGNED_INT, &ones);
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);

    gl->UseProgram(s->prog_raster);
    gl->UniformMatrix4fv(s->r_viewproj, 1, GL_FALSE, v->viewproj);
    gl->Uniform2i(s->r_size, v->width, v->height);
    gl->Uniform1f(s->r_point_size, p->point_size);
    gl->Uniform1f(s->r_znear, v->znear);
    gl->Uniform1f(s->r_zfar, v->zfar);
    gl->Uniform1ui(s->r_index_bits, ibits);
    if (ibits) {
        double levels = (double)((1u << (32 - ibits)) - 1);
        gl->Uniform1f(s->r_log_near, log2f(v->znear));
        gl->Uniform1f(s->r_log_scale, (float)(levels / log2((double)v->zfar / v->znear)));
    }
    /* packed: pass 2 once; exact: pass 0 (depth) over every set, then pass 1 (index). With one
     * buffer set its range table is uploaded once for both. */
    const int passes[2] = {ibits ? 2 : 0, 1};
    int npasses = ibits ? 1 : 2, sets_rebind = c->nsets > 1;
    uint32_t nranges = 0, first = 0;
    int64_t total = 0;
    for (int pi = 0; pi < npasses; pi++) {
        for (uint32_t set = 0; set < c->nsets; set++) {
            if (pi == 0 || sets_rebind) {
                total = rnd_kit_set_ranges(k, v, set, &nranges, &first, err);
                if (total < 0) return (int)total;
                rnd_kit_bind_set(k, &c->sets[set], p->color);
            }
            if (total > 0) raster_set(gl, s, c, set, (uint32_t)total, nranges, first, passes[pi]);
        }
    }
    gl->UseProgram(s->prog_resolve);
    gl->Uniform1i(s->s_width, v->width);
    gl->Uniform1ui(s->s_index_bits, ibits);
    gl->UniformMatrix4fv(s->s_viewproj, 1, GL_FALSE, v->viewproj);
    gl->Uniform1i(s->s_color, p->color);
    gl->Uniform1f(s->s_znear, v->znear);
    gl->Uniform1f(s->s_zfar, v->zfar);
    gl->Enable(GL_SCISSOR_TEST);
    gl->Scissor(rect[0], rect[1], rect[2] - rect[0], rect[3] - rect[1]);
    gl->BindVertexArray(s->vao);
    for (uint32_t set = 0; set < c->nsets; set++) {
        if (sets_rebind) rnd_kit_bind_set(k, &c->sets[set], p->color);
        gl->Uniform1ui(s->s_base, (GLuint)c->sets[set].base);
        gl->Uniform1ui(s->s_count, c->sets[set].n);
        gl->DrawArrays(GL_TRIANGLES, 0, 3);
    }
    gl->BindVertexArray(0);
    gl->Disable(GL_SCISSOR_TEST);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_POINTS_DEPTH, 0);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_POINTS_INDEX, 0);
    rnd_kit_unbind(k);
    gl->UseProgram(0);
    return GL_CHECK_PASS(gl, "the points passes (compute)", err);
}

static int points_render(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    points_state *s = state;
    const rnd_gpu_cloud *c = d->cloud;
    const rnd_view *v = d->view;
    if (!v->nchunks || !v->points_visible) return 0;
    int mode = k->opts.points_raster;
    uint64_t npix = (uint64_t)v->width * (uint64_t)v->height;
    uint32_t ibits = index_bits(c->n);
    int packs = 32 - ibits >= PACKED_MIN_DEPTH_BITS;
    if (c->n > UINT32_MAX - 1u && mode != RND_RASTER_GL) mode = RND_RASTER_GL; /* 32-bit keys */
    if (mode == RND_RASTER_AUTO) {
        if (npix * 4 > (uint64_t)k->max_ssbo) mode = RND_RASTER_GL;
        else mode = packs ? RND_RASTER_PACKED : RND_RASTER_EXACT;
    }
    if (mode != RND_RASTER_GL && npix * 4 > (uint64_t)k->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "a %dx%d frame needs a %llu-byte storage buffer, over the "
                       "driver's %lld; use the gl form", v->width, v->height,
                       (unsigned long long)(npix * 4), (long long)k->max_ssbo);
    if (mode == RND_RASTER_PACKED && !packs)
        return sd_errf(err, SD_ELIMIT, "the packed points form: %llu points leave fewer than %d "
                       "depth bits; use exact", (unsigned long long)c->n, PACKED_MIN_DEPTH_BITS);
    if (mode == RND_RASTER_GL) return render_gl(k->gl, s, c, v, d->params, err);
    return render_compute(k, s, c, v, d->params, mode == RND_RASTER_PACKED ? ibits : 0, err);
}

/* points_trim: the per-pixel buffers go (bind_pixel_buffer makes them again and rebinds their
 * buffer textures). */
static void points_trim(rnd_kit *k, void *state)
{
    points_state *s = state;
    GLuint b[2] = {s->depth_buf, s->index_buf};
    if (b[0] || b[1]) k->gl->DeleteBuffers(2, b);
    s->depth_buf = s->index_buf = 0;
    s->depth_bytes = s->index_bytes = 0;
}

const rnd_pipeline pipe_points = {
    .name = "points",
    .needs = 1u << RND_ATTR_POS | 1u << RND_ATTR_NORMAL | 1u << RND_ATTR_RGBA |
             1u << RND_ATTR_FIELD | 1u << RND_ATTR_INTENSITY | 1u << RND_ATTR_SCAN,
    .create = points_create,
    .destroy = points_destroy,
    .render = points_render,
    .trim = points_trim,
};
