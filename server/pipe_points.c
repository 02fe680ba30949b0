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
 * SPLATD_POINTS_RASTER=auto|packed|exact|gl picks one when the pipeline is created; auto
 * (the default) takes packed, else exact, else gl when a per-pixel buffer of the frame passes
 * the largest storage block the driver allows, or the cloud passes
 * GL_MAX_TEXTURE_BUFFER_SIZE / 3 points (both compute passes read the cloud through buffer
 * textures, positions as R32F, lib_fetch.glsl: gathers on llvmpipe). All give the
 * same image up to pixel-edge rounding: a point covers the pixels whose centres lie in the
 * square of side point_size around its projection, the nearest point wins (packed: up to its
 * depth quantum), ties go to the lower index. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "pipe.h"
#include "shaders.h"

enum { RASTER_AUTO = 0, RASTER_PACKED, RASTER_EXACT, RASTER_GL };
enum { PACKED_MIN_DEPTH_BITS = 12 };
enum { GROUP = 64, MAX_GROUPS_X = 65535 }; /* local_size_x of points_raster.comp */
/* The buffer textures both compute-form passes read (texture unit = index): positions (R32F,
 * lib_fetch.glsl), the per-pixel keys or depths (R32UI), the visible ranges (RG32UI), the
 * per-pixel winners of the exact form (R32UI), the colour source (R32UI) and normals (R32F). */
enum { T_POS, T_DEPTH, T_RANGES, T_INDEX, T_SRC, T_NRM, T_COUNT };

typedef struct points_state {
    int mode;
    GLint64 max_ssbo;                 /* GL_MAX_SHADER_STORAGE_BLOCK_SIZE */
    GLint64 max_texels;               /* GL_MAX_TEXTURE_BUFFER_SIZE */
    uint32_t per_invocation;          /* points per compute invocation */
    GLuint prog_gl, prog_raster, prog_resolve;
    GLuint vao;
    GLuint depth_buf, index_buf, range_buf;
    GLuint tex[T_COUNT];              /* buffer textures, on texture unit = their index */
    uint64_t pix_cap, range_cap;      /* elements the buffers hold */
    uint32_t *range_tmp;              /* CPU staging for the range table (uvec2 per range) */
    /* uniform locations */
    GLint g_viewproj, g_point_size, g_color, g_znear, g_zfar;
    GLint r_viewproj, r_size, r_point_size, r_znear, r_zfar, r_total, r_nranges, r_first;
    GLint r_stride, r_threads, r_per, r_pass, r_index_bits, r_log_near, r_log_scale;
    GLint s_width, s_color, s_znear, s_zfar, s_index_bits, s_viewproj;
} points_state;

static void points_destroy(const gl_api *gl, void *state)
{
    points_state *s = state;
    if (!s) return;
    if (s->prog_gl) gl->DeleteProgram(s->prog_gl);
    if (s->prog_raster) gl->DeleteProgram(s->prog_raster);
    if (s->prog_resolve) gl->DeleteProgram(s->prog_resolve);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    if (s->tex[0]) gl->DeleteTextures(T_COUNT, s->tex);
    GLuint bufs[3] = {s->depth_buf, s->index_buf, s->range_buf};
    gl->DeleteBuffers(3, bufs);
    free(s->range_tmp);
    memset(s, 0, sizeof *s);
    free(s);
}

static int points_create(const gl_api *gl, const rnd_shaders *sh, void **state, sd_err *err)
{
    *state = NULL;
    points_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory for the points pipeline");
    const char *m = getenv("SPLATD_POINTS_RASTER");
    if (!m || !*m || !strcmp(m, "auto")) s->mode = RASTER_AUTO;
    else if (!strcmp(m, "packed")) s->mode = RASTER_PACKED;
    else if (!strcmp(m, "exact")) s->mode = RASTER_EXACT;
    else if (!strcmp(m, "gl")) s->mode = RASTER_GL;
    else {
        free(s);
        return sd_errf(err, SD_EINVAL,
                       "SPLATD_POINTS_RASTER='%s' is not auto, packed, exact or gl", m);
    }
    GLint v = 0;
    gl->GetIntegerv(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &v);
    s->max_ssbo = v > 0 ? v : (GLint64)1 << 27;
    v = 0;
    gl->GetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &v);
    s->max_texels = v > 0 ? v : 65536;
    /* llvmpipe spends ~50 ns on each compute invocation however little it does (measured:
     * one point per invocation costs twice as much as 32), so there each invocation takes a
     * run of points; a GPU wants one each. */
    const char *ren = (const char *)gl->GetString(GL_RENDERER);
    int cpu = ren && (strstr(ren, "llvmpipe") || strstr(ren, "softpipe"));
    s->per_invocation = cpu ? 32 : 1;

    s->prog_gl = gl_program_from(gl, sh, err, "points.vert", "points.frag", NULL);
    if (!s->prog_gl) goto fail;
    s->prog_raster = gl_program_from(gl, sh, err, "points_raster.comp", NULL);
    if (!s->prog_raster) goto fail;
    s->prog_resolve = gl_program_from(gl, sh, err, "points_resolve.vert", "points_resolve.frag",
                                      NULL);
    if (!s->prog_resolve) goto fail;
    gl->GenVertexArrays(1, &s->vao);
    gl->GenBuffers(1, &s->depth_buf);
    gl->GenBuffers(1, &s->index_buf);
    gl->GenBuffers(1, &s->range_buf);
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

    s->s_index_bits = gl_uniform(gl, s->prog_resolve, "u_index_bits");
    s->s_viewproj = gl_uniform(gl, s->prog_resolve, "u_viewproj");
    s->s_width = gl_uniform(gl, s->prog_resolve, "u_width");
    s->s_color = gl_uniform(gl, s->prog_resolve, "u_color");
    s->s_znear = gl_uniform(gl, s->prog_resolve, "u_znear");
    s->s_zfar = gl_uniform(gl, s->prog_resolve, "u_zfar");
    /* Each program's samplers, on their units once and for all (a program keeps them). */
    static const char *const tname[T_COUNT] = {"u_pos", "u_depth", "u_ranges", "u_index",
                                               "u_src", "u_nrm"};
    const GLuint progs[2] = {s->prog_raster, s->prog_resolve};
    for (int i = 0; i < 2; i++) {
        gl->UseProgram(progs[i]);
        for (int k = 0; k < T_COUNT; k++) {
            GLint loc = gl_uniform(gl, progs[i], tname[k]);
            if (loc >= 0) gl->Uniform1i(loc, k);
        }
    }
    gl->UseProgram(0);
    gl->GenTextures(T_COUNT, s->tex);
    if (gl_check(gl, "creating the points pipeline", err) < 0) goto fail;
    *state = s;
    return 0;
fail:
    points_destroy(gl, s);
    return err && err->code ? err->code : SD_EGL;
}

/* Binds the cloud's attribute buffers to vertex attributes 0-4 of the bound VAO. */
static void bind_attributes(const gl_api *gl, const rnd_gpu_cloud *c)
{
    const struct {
        GLuint buf;
        GLint n;
        GLenum type;
        GLboolean norm;
    } attr[5] = {
        {c->pos, 3, GL_FLOAT, GL_FALSE},     {c->rgba, 4, GL_UNSIGNED_BYTE, GL_TRUE},
        {c->normal, 3, GL_FLOAT, GL_FALSE},  {c->field, 1, GL_FLOAT, GL_FALSE},
        {c->intensity, 1, GL_FLOAT, GL_FALSE},
    };
    for (GLuint i = 0; i < 5; i++) {
        gl->BindBuffer(GL_ARRAY_BUFFER, attr[i].buf);
        gl->VertexAttribPointer(i, attr[i].n, attr[i].type, attr[i].norm, 0, NULL);
        gl->EnableVertexAttribArray(i);
    }
    gl->BindBuffer(GL_ARRAY_BUFFER, 0);
}

/* The GL_POINTS form. */
static int render_gl(const gl_api *gl, points_state *s, const rnd_gpu_cloud *c,
                     const rnd_view *v, const sp_params *p, sd_err *err)
{
    gl->UseProgram(s->prog_gl);
    gl->UniformMatrix4fv(s->g_viewproj, 1, GL_FALSE, v->viewproj);
    gl->Uniform1f(s->g_point_size, p->point_size);
    gl->Uniform1i(s->g_color, p->color);
    gl->Uniform1f(s->g_znear, v->znear);
    gl->Uniform1f(s->g_zfar, v->zfar);
    gl->BindVertexArray(s->vao);
    bind_attributes(gl, c);
    const float one = 1.0f;
    gl->DepthMask(GL_TRUE);
    gl->ClearBufferfv(GL_DEPTH, 0, &one); /* the renderer leaves it to us (pipe.h) */
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthFunc(GL_LESS);
    gl->Enable(GL_PROGRAM_POINT_SIZE);
    /* GLint/GLsizei and uint32_t ranges: render.c keeps every count below 2^31. */
    gl->MultiDrawArrays(GL_POINTS, (const GLint *)v->range_first, (const GLsizei *)v->range_count,
                        (GLsizei)v->nranges);
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

/* Grows SSBO buf (holding *cap elements of elem bytes) to at least n elements. */
static void ensure_buffer(const gl_api *gl, GLuint buf, uint64_t *cap, uint64_t n, size_t elem)
{
    if (*cap >= n) return;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, buf);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(n * elem), NULL, GL_DYNAMIC_DRAW);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    *cap = n;
}

/* Bits for a point index of a cloud of n points, leaving the all-ones key free for "empty":
 * the smallest b with n <= 2^b - 1. */
static uint32_t index_bits(uint64_t n)
{
    uint32_t b = 1;
    while (b < 32 && ((uint64_t)1 << b) - 1 < n) b++;
    return b;
}

/* The compute forms: packed (index_bits > 0: one pass) or exact (two passes), then the
 * resolve into the target. */
static int render_compute(const gl_api *gl, points_state *s, const rnd_gpu_cloud *c,
                          const rnd_view *v, const sp_params *p, uint32_t ibits, sd_err *err)
{
    uint64_t npix = (uint64_t)v->width * (uint64_t)v->height;
    if (npix * 4 > (uint64_t)s->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "a %dx%d frame needs a %llu-byte storage buffer, over the "
                       "driver's %lld; use SPLATD_POINTS_RASTER=gl", v->width, v->height,
                       (unsigned long long)(npix * 4), (long long)s->max_ssbo);
    if (c->n * 3 > (uint64_t)s->max_texels)
        return sd_errf(err, SD_ELIMIT, "%llu points are more than the compute rasteriser reads "
                       "(buffer textures of %lld texels, 3 a point); use "
                       "SPLATD_POINTS_RASTER=gl", (unsigned long long)c->n,
                       (long long)s->max_texels);
    if (npix > s->pix_cap) {
        uint64_t cap = s->pix_cap;
        ensure_buffer(gl, s->depth_buf, &cap, npix, 4);
        ensure_buffer(gl, s->index_buf, &s->pix_cap, npix, 4);
    }
    /* The range table: (first point, position in the sequence of visible points). */
    uint32_t nr = v->nranges;
    if (nr > s->range_cap) {
        uint32_t *tmp = realloc(s->range_tmp, (size_t)nr * 2 * sizeof *tmp);
        if (!tmp) return sd_errf(err, SD_ENOMEM, "out of memory for %u point ranges", nr);
        s->range_tmp = tmp;
        ensure_buffer(gl, s->range_buf, &s->range_cap, nr, 8);
    }
    uint32_t acc = 0;
    for (uint32_t i = 0; i < nr; i++) {
        s->range_tmp[2 * i] = v->range_first[i];
        s->range_tmp[2 * i + 1] = acc;
        acc += v->range_count[i];
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->range_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)nr * 8, s->range_tmp);
    /* Only the rows of the cloud's screen rectangle are cleared and resolved: points cannot
     * land outside it, and what they might write outside by rounding is never read. */
    int rect[4];
    rnd__screen_rect(v, c->bmin, c->bmax, (int)ceilf(p->point_size * 0.5f) + 1, rect);
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) return 0;
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
    /* The per-pixel buffers; everything else is read through buffer textures. */
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, s->depth_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, s->index_buf);

    uint32_t total = (uint32_t)v->points_visible;
    uint32_t gx, gy;
    dispatch_size((total + s->per_invocation - 1) / s->per_invocation, &gx, &gy);
    uint32_t threads = gx * gy * GROUP;
    /* Every buffer texture of both passes (lib_fetch.glsl: positions and normals as R32F). */
    GLuint src = p->color == SP_COLOR_FIELD ? c->field
               : p->color == SP_COLOR_INTENSITY ? c->intensity : c->rgba;
    const struct { GLenum fmt; GLuint buf; } tb[T_COUNT] = {
        [T_POS] = {GL_R32F, c->pos},          [T_DEPTH] = {GL_R32UI, s->depth_buf},
        [T_RANGES] = {GL_RG32UI, s->range_buf}, [T_INDEX] = {GL_R32UI, s->index_buf},
        [T_SRC] = {GL_R32UI, src},            [T_NRM] = {GL_R32F, c->normal}};
    for (int k = 0; k < T_COUNT; k++) {
        gl->ActiveTexture(GL_TEXTURE0 + (GLenum)k);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->tex[k]);
        gl->TexBuffer(GL_TEXTURE_BUFFER, tb[k].fmt, tb[k].buf);
    }
    gl->ActiveTexture(GL_TEXTURE0);
    gl->UseProgram(s->prog_raster);
    gl->UniformMatrix4fv(s->r_viewproj, 1, GL_FALSE, v->viewproj);
    gl->Uniform2i(s->r_size, v->width, v->height);
    gl->Uniform1f(s->r_point_size, p->point_size);
    gl->Uniform1f(s->r_znear, v->znear);
    gl->Uniform1f(s->r_zfar, v->zfar);
    gl->Uniform1ui(s->r_total, total);
    gl->Uniform1ui(s->r_nranges, nr);
    gl->Uniform1ui(s->r_first, v->range_first[0]);
    gl->Uniform1ui(s->r_stride, gx * GROUP);
    gl->Uniform1ui(s->r_threads, threads);
    gl->Uniform1ui(s->r_per, (total + threads - 1) / threads);
    if (ibits) {
        double levels = (double)((1u << (32 - ibits)) - 1);
        gl->Uniform1ui(s->r_index_bits, ibits);
        gl->Uniform1f(s->r_log_near, log2f(v->znear));
        gl->Uniform1f(s->r_log_scale, (float)(levels / log2((double)v->zfar / v->znear)));
        gl->Uniform1i(s->r_pass, 2);
        gl->DispatchCompute(gx, gy, 1);
        gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    } else {
        for (int pass = 0; pass < 2; pass++) {
            gl->Uniform1i(s->r_pass, pass);
            gl->DispatchCompute(gx, gy, 1);
            gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
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
    gl->DrawArrays(GL_TRIANGLES, 0, 3);
    gl->BindVertexArray(0);
    gl->Disable(GL_SCISSOR_TEST);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, 0);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, 0);
    for (int k = T_COUNT - 1; k >= 0; k--) {
        gl->ActiveTexture(GL_TEXTURE0 + (GLenum)k);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
    }
    gl->UseProgram(0);
    return GL_CHECK_PASS(gl, "the points passes (compute)", err);
}

static int points_render(const gl_api *gl, void *state, const rnd_gpu_cloud *c,
                         const rnd_view *v, const sp_params *p, const rnd_target *t, sd_err *err)
{
    (void)t; /* already bound by the renderer, with its draw buffers (pipe.h) */
    points_state *s = state;
    if (!v->nranges || !v->points_visible) return 0;
    int mode = s->mode;
    uint64_t npix = (uint64_t)v->width * (uint64_t)v->height;
    uint32_t ibits = index_bits(c->n);
    int packs = 32 - ibits >= PACKED_MIN_DEPTH_BITS;
    if (mode == RASTER_AUTO) {
        if (npix * 4 > (uint64_t)s->max_ssbo || c->n * 3 > (uint64_t)s->max_texels)
            mode = RASTER_GL;
        else
            mode = packs ? RASTER_PACKED : RASTER_EXACT;
    }
    if (mode == RASTER_PACKED && !packs)
        return sd_errf(err, SD_ELIMIT, "SPLATD_POINTS_RASTER=packed: %llu points leave fewer "
                       "than %d depth bits; use exact", (unsigned long long)c->n,
                       PACKED_MIN_DEPTH_BITS);
    if (mode == RASTER_GL) return render_gl(gl, s, c, v, p, err);
    return render_compute(gl, s, c, v, p, mode == RASTER_PACKED ? ibits : 0, err);
}

const rnd_pipeline pipe_points = {
    .name = "points",
    .create = points_create,
    .destroy = points_destroy,
    .render = points_render,
};
