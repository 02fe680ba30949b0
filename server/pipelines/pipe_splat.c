/* pipe_splat.c — the `splat` pipeline: EWA surface splatting (Zwicker et al. 2001; the
 * three-pass GPU form of Botsch et al. that the Soft Transparency paper uses, section 2), done
 * with compute shaders instead of point sprites.
 *
 *   pass 1, visibility   splat_raster.comp PASS 1: per splat, its footprint's pixels keep the
 *                        nearest ray-disc depth (atomicMax of ~float bits in a storage buffer);
 *   pass 2, attributes   splat_raster.comp PASS 2: fragments within eps * radius of that depth
 *                        add w*colour, w*normal and w (float atomicAdd with
 *                        GL_NV_shader_atomic_float, fixed-point uint atomicAdd without it);
 *   pass 3, resolve      splat_resolve.vert/.frag, two triangles over the rectangle of pixels
 *                        pass 1 touched (its atomicMin/Max box, read by the vertex shader):
 *                        (ewa=split) the rest of the low-pass as a depth-aware 3x3 Gaussian
 *                        over the sums, division by the weight, deferred shading; writes the
 *                        target's colour and depth_eye.
 *
 * Botsch et al. push pass 1's depths back by eps and test z <= zbuf in pass 2; here pass 1 keeps
 * the exact nearest depth (so depth_eye is the visible surface's depth) and pass 2 accepts
 * z <= zbuf + eps * r, the same test with a per-splat eps (r = the splat's radius).
 *
 * Two filters, chosen per frame by the parameter `ewa` (both through the same programs: the
 * modes differ only in the uniforms u_pre, u_subpx and u_post, see set_uniforms):
 *   exact   the textbook resampling filter: every splat's footprint is J V_r J^T + lowpass I,
 *           cut off at 2 standard deviations, every splat sampled over its full footprint; no
 *           resolve blur. The default on a hardware GPU (ewa=auto).
 *   split   the form below, for software rasterisers (ewa=auto where the GL back end reports
 *           one: rnd_kit.software, gl_backend.h).
 *
 * Why compute, and why the low-pass is split. On llvmpipe (2 cores, 1M points, 1280x720) a
 * three-pass point-sprite splatter takes 850-2000 ms, and even as compute passes every fragment
 * costs a storage-buffer read plus 7 atomics, each run lane by lane: with the full one-pixel
 * low-pass in every footprint a minified splat covers ~13 pixels and a frame took ~8x `points`.
 * Convolution is linear, so widening every footprint by the low-pass equals filtering the
 * accumulated sums once: each splat gets V_k + lowpass/4 I, splats whose own kernel V_k is under
 * 2 px (2 sigma) deposit their weight in the one pixel holding their centre (area sampling: a box
 * of one pixel, so they never vanish), and the resolve applies a 3x3 Gaussian of variance
 * 0.75 lowpass (truncated) across neighbours within a depth tolerance, as the extended z-buffer
 * would. A minified splat then costs one fragment, and the frame ~2-2.5x `points` (`make
 * bench`). lowpass = 0 turns all of it off: pure sampled discs, which alias and may vanish when
 * minified.
 *
 * The cloud is read through buffer textures (texelFetch gathers all SIMD lanes at once on
 * llvmpipe; storage-buffer reads at varying addresses go lane by lane), positions and normals
 * as R32F, three fetches a point (lib_fetch.glsl: RGB32F texels take a slow generic path, 15 %
 * of the frame), the sums likewise in the resolve. Each pass runs as three dispatches: one
 * invocation per visible point does the deposited splats and (pass 1) lists the others, since
 * llvmpipe executes a divergent branch's loops under a mask for every point (25 % of the frame
 * when they were inline); an indirect dispatch then loops each listed splat over its pixel
 * box, and one more gives every splat whose box has more than SPLAT_BIG_PIXELS pixels an 8x8
 * work group that walks it in tiles, so a close-up costs its pixels, not one lane's serial
 * loop. Pass 2 replays pass 1's lists. The
 * visibility keys live in their own compact buffer (4 bytes a pixel) beside the 32-byte sums.
 *
 * A cloud in several buffer sets (pipe.h) is drawn set by set into the same per-pixel buffers:
 * pass 1 over every set, then pass 2 over every set, each set's pass 2 preceded by its pass 1
 * again (the splat lists of passes 2's second and third dispatches are rebuilt per set; the
 * keys and the rectangle take the same values twice, so that changes nothing), then one
 * resolve. One set, the usual case, runs exactly the passes above.
 *
 * Frames larger than the accumulation buffer allowed by GL_MAX_SHADER_STORAGE_BLOCK_SIZE
 * (128 MiB on llvmpipe: 32 bytes a pixel, so a 3840x2160 frame) are rendered in horizontal
 * stripes, each with a halo row above and below for the 3x3 gather.
 *
 * Measured (`make bench`: 1M points, 1280x720, llvmpipe on 2 shared cores): split 63 ms,
 * 2.0x `points`; exact 462 ms, 15x (every minified splat ~13 fragments of 7 atomics). A split
 * frame's passes, timed with glFinish between them: clearing the sums ~3.5 ms, visibility
 * ~19 ms, attributes ~27 ms, the listed raster and big splats ~3 ms, the resolve ~8 ms.
 *
 * Quality is not a clear win for exact either: at a grazing angle (test_ewa_antialiasing) the
 * low-pass fringes of nearer minified splats, whose depths are clamped to their centre's +- r,
 * win the visibility pass, so a pixel blends only about one row of splats (pixel variance 499
 * exact vs 11 split, 1436 without low-pass); split's depth-aware resolve gather does not have
 * that problem. Widening the clamp to the plane's depths over the footprint fixed that case
 * (variance 0) but let near-edge-on splats at creases occlude the surface (dark lines on
 * Guanyin), so it was not kept. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pipe.h"
#include "shaders.h"
#include "splat_math.h"
#include "splat_passes.h"

enum {
    SPLAT_PX_BYTES = 32,       /* struct Px in the shaders */
    SPLAT_BIG_PIXELS = 256,    /* bounding boxes above this go to the big list */
    SPLAT_GROUP = 64,          /* local size of the per-splat passes */
    SPLAT_MAX_GROUPS = 65535,  /* the GL minimum of GL_MAX_COMPUTE_WORK_GROUP_COUNT */
    SPLAT_SW_GROUPS = 1024,    /* on a software rasteriser: see groups_cap */
    SPLAT_BIG_HEADER = 4,      /* uints before the big list: groups[3], count */
};

/* Depth tolerance of pass 2 in units of the splat radius: a fragment counts as the same surface
 * when it lies at most one radius behind the nearest one. Neighbouring discs of one surface
 * meet a ray within a fraction of a radius of each other (they are tangent planes r apart);
 * a second surface closer than one radius behind would blend in. */
#define SPLAT_EPS 1.0f

/* Uniform slots, looked up by name in every program (missing ones are -1 and ignored). */
#define SPLAT_UNIFORMS(X)                                                                   \
    X(VIEW, "u_view") X(PROJ, "u_proj") X(RAYO, "u_rayo") X(RAYD, "u_rayd")                  \
    X(SIZE, "u_size") X(STRIPE, "u_stripe") X(SCALE, "u_scale")                               \
    X(PRE, "u_pre") X(SUBPX, "u_subpx") X(POST, "u_post") X(EPSG, "u_epsg")                   \
    X(EPS, "u_eps") X(ZNEAR, "u_znear") X(TOTAL, "u_total") X(NRANGES, "u_nranges")          \
    X(BIGPX, "u_big") X(COLOR, "u_color") X(LIGHT, "u_light") X(ZFAR, "u_zfar")

enum {
#define SPLAT_U_ENUM_(id, name) U_##id,
    SPLAT_UNIFORMS(SPLAT_U_ENUM_)
#undef SPLAT_U_ENUM_
    U_COUNT
};

enum { P_VIS = 0, P_VIS_RAS, P_VIS_BIG, P_ACC, P_ACC_RAS, P_ACC_BIG, P_RESOLVE, P_COUNT };

typedef struct splat_state {
    GLuint prog[P_COUNT];
    GLint loc[P_COUNT][U_COUNT];
    int float_atomics;         /* GL_NV_shader_atomic_float in use */
    int software;              /* rnd_kit.software (the back end's): ewa=auto is split */
    GLuint groups_cap;         /* most work groups per splat dispatch; invocations loop over
                                  the points (grid stride). llvmpipe pays ~3 us a work group, so
                                  there 1024 groups of 64 (1M points: 15 each) measured 20-25 %
                                  faster than one group per 64 points; a GPU wants them all. */
    int max_rows;              /* rnd_pipe_opts.splat_stripe_rows (tests): rows per stripe */
    void (*set_hook)(void *user, uint32_t set); /* splat__set_set_hook */
    void *set_hook_user;
    GLuint vao;                /* empty, for the resolve's two triangles       */
    GLuint frame_buf;          /* the accumulation buffer: Px per pixel of one stripe */
    GLuint frame_tex;          /* the same buffer as a buffer texture, for the resolve */
    GLuint key_buf, key_tex;   /* the visibility keys (uint a pixel), and as a texture */
    uint64_t frame_bytes, key_bytes;
    int frame_w, frame_rows;
    GLuint big_buf;            /* dispatch header + big splat indices */
    GLuint ras_buf;            /* dispatch header + sampled (not deposited) splat indices */
    uint64_t big_bytes, ras_bytes;
    GLuint rect_buf;           /* ivec4: the pixels pass 1 touched in the stripe (the resolve's
                                  rectangle) */
    uint64_t rect_bytes;
    GLint floc[P_COUNT][2];    /* splat__create_filtered: u_smode, u_st */
} splat_state;

static void splat_destroy(rnd_kit *k, void *state)
{
    splat_state *s = state;
    if (!s) return;
    const gl_api *gl = k->gl;
    for (int i = 0; i < P_COUNT; i++)
        if (s->prog[i]) gl->DeleteProgram(s->prog[i]);
    if (s->frame_tex) gl->DeleteTextures(1, &s->frame_tex);
    if (s->key_tex) gl->DeleteTextures(1, &s->key_tex);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    GLuint bufs[5] = {s->frame_buf, s->key_buf, s->big_buf, s->ras_buf, s->rect_buf};
    for (int i = 0; i < 5; i++)
        if (bufs[i]) gl->DeleteBuffers(1, &bufs[i]);
    memset(s, 0, sizeof *s);
    free(s);
}

/* create: compiles the programs (float or fixed-point atomics, chosen by the extension string;
 * rnd_pipe_opts.splat_fixed forces fixed point, for tests). */
static int splat_create_with(rnd_kit *k, void **state, int filtered, sd_err *err)
{
    *state = NULL;
    const gl_api *gl = k->gl;
    splat_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory creating the splat pipeline");
    s->software = k->software;
    s->groups_cap = s->software ? SPLAT_SW_GROUPS : SPLAT_MAX_GROUPS;
    s->float_atomics = k->float_atomics && !k->opts.splat_fixed;
    const char *fa = s->float_atomics
                         ? "#extension GL_NV_shader_atomic_float : require\n#define FLOAT_ATOMICS 1\n"
                         : "#define FLOAT_ATOMICS 0\n";
    static const struct {
        const char *files[2];
        int n;
        const char *defs;
    } progs[P_COUNT] = {
        [P_VIS] = {{"splat_raster.comp"}, 1, "#define PASS 1\n#define MODE 0\n"},
        [P_VIS_RAS] = {{"splat_raster.comp"}, 1, "#define PASS 1\n#define MODE 1\n"},
        [P_VIS_BIG] = {{"splat_raster.comp"}, 1, "#define PASS 1\n#define MODE 2\n"},
        [P_ACC] = {{"splat_raster.comp"}, 1, "#define PASS 2\n#define MODE 0\n"},
        [P_ACC_RAS] = {{"splat_raster.comp"}, 1, "#define PASS 2\n#define MODE 1\n"},
        [P_ACC_BIG] = {{"splat_raster.comp"}, 1, "#define PASS 2\n#define MODE 2\n"},
        [P_RESOLVE] = {{"splat_resolve.vert", "splat_resolve.frag"}, 2, ""},
    };
    static const char *const unames[U_COUNT] = {
#define SPLAT_U_NAME_(id, name) name,
        SPLAT_UNIFORMS(SPLAT_U_NAME_)
#undef SPLAT_U_NAME_
    };
    for (int p = 0; p < P_COUNT; p++) {
        char defs[256];
        snprintf(defs, sizeof defs, "%s%s%s", fa, progs[p].defs,
                 filtered && p != P_RESOLVE ? "#define SOFT_FILTER 1\n" : "");
        s->prog[p] = rnd_kit_program(k, progs[p].files, progs[p].n, defs, err);
        if (!s->prog[p]) {
            splat_destroy(k, s);
            return err ? err->code : SD_EGL;
        }
        for (int u = 0; u < U_COUNT; u++) s->loc[p][u] = gl_uniform(gl, s->prog[p], unames[u]);
    }
    for (int p = 0; p < P_COUNT; p++) {
        s->floc[p][0] = filtered && p != P_RESOLVE ? gl_uniform(gl, s->prog[p], "u_smode") : -1;
        s->floc[p][1] = filtered && p != P_RESOLVE ? gl_uniform(gl, s->prog[p], "u_st") : -1;
    }
    gl->GenVertexArrays(1, &s->vao);
    s->max_rows = k->opts.splat_stripe_rows;
    int rc = gl_check(gl, "creating the splat pipeline", err);
    if (rc < 0) {
        splat_destroy(k, s);
        return rc;
    }
    *state = s;
    return 0;
}

static void zero_buffer(const gl_api *gl, GLuint buf)
{
    GLuint zero = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, buf);
    gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
}

/* Sets the uniforms every program of this frame shares (those a program lacks are skipped). */
static void set_uniforms(const gl_api *gl, const splat_state *s, int p, const rnd_view *v,
                         const sp_params *prm, const float rayo[4], const float rayd[4],
                         const float light[3])
{
    const GLint *l = s->loc[p];
    gl->UseProgram(s->prog[p]);
    if (l[U_VIEW] >= 0) gl->UniformMatrix4fv(l[U_VIEW], 1, GL_FALSE, v->view);
    if (l[U_PROJ] >= 0) gl->UniformMatrix4fv(l[U_PROJ], 1, GL_FALSE, v->proj);
    if (l[U_RAYO] >= 0) gl->Uniform4fv(l[U_RAYO], 1, rayo);
    if (l[U_RAYD] >= 0) gl->Uniform4fv(l[U_RAYD], 1, rayd);
    if (l[U_SIZE] >= 0) gl->Uniform2i(l[U_SIZE], v->width, v->height);
    if (l[U_SCALE] >= 0) gl->Uniform1f(l[U_SCALE], prm->splat_scale);
    /* ewa=split (see splat_raster.comp): a quarter of the low-pass in every footprint, the rest
     * in the resolve's 3x3 Gaussian of variance 0.75 lowpass; sub-pixel splats deposited when
     * lowpass > 0. ewa=exact: the whole low-pass in every footprint, nothing deposited, no
     * gather (the textbook resampling filter). The two modes differ only in these three
     * uniforms. The gather's depth tolerance: 4 pixel widths at the reference depth, as a
     * fraction of that depth (a perspective camera: rnd_camera has no orthographic mode). */
    int split = prm->ewa == SP_EWA_SPLIT || (prm->ewa == SP_EWA_AUTO && s->software);
    float lp = prm->lowpass;
    float h1 = split && lp > 0.0f ? expf(-1.0f / (2.0f * 0.75f * lp)) : 0.0f;
    const float post[3] = {1.0f, h1, h1 * h1};
    if (l[U_PRE] >= 0) gl->Uniform1f(l[U_PRE], split ? 0.25f * lp : lp);
    if (l[U_SUBPX] >= 0) gl->Uniform1f(l[U_SUBPX], split && lp > 0.0f ? 2.0f : 0.0f);
    if (l[U_POST] >= 0) gl->Uniform3fv(l[U_POST], 1, post);
    if (l[U_EPSG] >= 0) gl->Uniform1f(l[U_EPSG], 4.0f * 2.0f / ((float)v->height * v->proj[5]));
    if (l[U_EPS] >= 0) gl->Uniform1f(l[U_EPS], SPLAT_EPS);
    if (l[U_ZNEAR] >= 0) gl->Uniform1f(l[U_ZNEAR], v->znear);
    if (l[U_BIGPX] >= 0) gl->Uniform1ui(l[U_BIGPX], SPLAT_BIG_PIXELS);
    if (l[U_COLOR] >= 0) gl->Uniform1i(l[U_COLOR], prm->color);
    if (l[U_LIGHT] >= 0) gl->Uniform3fv(l[U_LIGHT], 1, light);
    if (l[U_ZFAR] >= 0) gl->Uniform1f(l[U_ZFAR], v->zfar);
}

/* set_points: makes buffer set `set` current for the splat passes: its range table and
 * buffers bound, u_total and u_nranges set in every raster program. Returns its visible
 * points (0: none) or a negative SD_E* code. */
static int64_t set_points(rnd_kit *k, splat_state *s, const rnd_draw *d, uint32_t set,
                          sd_err *err)
{
    uint32_t nranges, first;
    int64_t total = rnd_kit_set_ranges(k, d->view, set, &nranges, &first, err);
    if (total <= 0) return total;
    rnd_kit_bind_set(k, &d->cloud->sets[set], d->params->color);
    if (s->set_hook) s->set_hook(s->set_hook_user, set);
    for (int p = 0; p < P_RESOLVE; p++) {
        k->gl->UseProgram(s->prog[p]);
        if (s->loc[p][U_TOTAL] >= 0) k->gl->Uniform1ui(s->loc[p][U_TOTAL], (GLuint)total);
        if (s->loc[p][U_NRANGES] >= 0) k->gl->Uniform1ui(s->loc[p][U_NRANGES], nranges);
    }
    return total;
}

/* reset_lists: empties the splat lists and their dispatch headers. */
static void reset_lists(const gl_api *gl, const splat_state *s)
{
    const GLuint header[SPLAT_BIG_HEADER] = {0, 1, 1, 0};
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->big_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof header, header);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->ras_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof header, header);
}

/* run_pass: one raster program: the per-point dispatch, or the indirect one over a list. */
static void run_pass(const gl_api *gl, const splat_state *s, int p, GLuint groups)
{
    gl->UseProgram(s->prog[p]);
    if (p == P_VIS || p == P_ACC) {
        gl->DispatchCompute(groups, 1, 1);
    } else {
        int big = p == P_VIS_BIG || p == P_ACC_BIG;
        gl->BindBuffer(GL_DISPATCH_INDIRECT_BUFFER, big ? s->big_buf : s->ras_buf);
        gl->DispatchComputeIndirect(0);
    }
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT |
                      GL_TEXTURE_FETCH_BARRIER_BIT);
}

static GLuint groups_for(const splat_state *s, int64_t total)
{
    uint64_t groups64 = ((uint64_t)total + SPLAT_GROUP - 1) / SPLAT_GROUP;
    return groups64 > s->groups_cap ? s->groups_cap : (GLuint)groups64;
}

/* frame_begin: splat__frame_begin; with even_empty, a frame with no visible point is set up
 * too (buffers, uniforms, one stripe or more) with f->total 0, for sort-last frames, where a
 * rank that draws nothing may still resolve the others' sums. */
static int frame_begin(rnd_kit *k, void *state, const rnd_draw *d, splat_frame *f,
                       int even_empty, sd_err *err);

int splat__frame_begin(rnd_kit *k, void *state, const rnd_draw *d, splat_frame *f, sd_err *err)
{
    return frame_begin(k, state, d, f, 0, err);
}

static int frame_begin(rnd_kit *k, void *state, const rnd_draw *d, splat_frame *f,
                       int even_empty, sd_err *err)
{
    splat_state *s = state;
    const gl_api *gl = k->gl;
    const rnd_gpu_cloud *c = d->cloud;
    const rnd_view *v = d->view;
    const sp_params *p = d->params;
    memset(f, 0, sizeof *f);
    f->d = d;
    if (!even_empty && (v->nchunks == 0 || v->points_visible == 0)) return 0;
    if (v->width <= 0 || v->height <= 0) return sd_errf(err, SD_EINVAL, "bad frame size");
    /* The largest set's visible points size the splat lists. */
    uint64_t most = 0;
    for (uint32_t a = 0; a < v->nchunks;) {
        uint64_t n = 0;
        uint32_t set = v->chunks[a].set;
        for (; a < v->nchunks && v->chunks[a].set == set; a++) n += v->chunks[a].count;
        if (n > most) most = n;
    }

    /* Accumulation buffer: as many rows as one storage block (and a buffer texture of 2 texels
     * a pixel) may hold, including one halo row above and below the stripe for the resolve's
     * 3x3 gather. */
    int64_t rows_fit = k->max_ssbo / ((int64_t)v->width * SPLAT_PX_BYTES);
    if (rows_fit > k->max_texels / (2 * (int64_t)v->width)) rows_fit = k->max_texels / (2 * (int64_t)v->width);
    rows_fit -= 2;
    if (s->max_rows > 0 && rows_fit > s->max_rows) rows_fit = s->max_rows;
    if (rows_fit < 1)
        return sd_errf(err, SD_ELIMIT, "a %d pixel wide frame needs a %lld byte storage block "
                       "for 3 rows; the GL allows %lld", v->width,
                       (long long)v->width * SPLAT_PX_BYTES * 3, (long long)k->max_ssbo);
    int rows = v->height < rows_fit ? v->height : (int)rows_fit;
    if (s->frame_w != v->width || s->frame_rows != rows || !s->frame_buf) {
        uint64_t bytes = (uint64_t)v->width * (uint64_t)(rows + 2) * SPLAT_PX_BYTES;
        rnd_kit_ensure_ssbo(gl, &s->frame_buf, &s->frame_bytes, bytes);
        if (!s->frame_tex) gl->GenTextures(1, &s->frame_tex);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->frame_tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, s->float_atomics ? GL_RGBA32F : GL_RGBA32UI, s->frame_buf);
        rnd_kit_ensure_ssbo(gl, &s->key_buf, &s->key_bytes, bytes / SPLAT_PX_BYTES * 4);
        if (!s->key_tex) gl->GenTextures(1, &s->key_tex);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->key_tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, s->key_buf);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
        s->frame_w = v->width, s->frame_rows = rows;
    }
    uint64_t list_bytes = (SPLAT_BIG_HEADER + most) * 4;
    rnd_kit_ensure_ssbo(gl, &s->big_buf, &s->big_bytes, list_bytes);
    rnd_kit_ensure_ssbo(gl, &s->ras_buf, &s->ras_bytes, list_bytes);
    rnd_kit_ensure_ssbo(gl, &s->rect_buf, &s->rect_bytes, 16);

    float rayo[4], rayd[4], light[3];
    splat_ray_coeffs(v->proj, v->width, v->height, rayo, rayd);
    float ll = sqrtf(p->light[0] * p->light[0] + p->light[1] * p->light[1] + p->light[2] * p->light[2]);
    for (int i = 0; i < 3; i++) light[i] = ll > 0.0f ? p->light[i] / ll : (i == 2 ? 1.0f : 0.0f);

    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SPLAT_KEYS, s->key_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SPLAT_SUMS, s->frame_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SPLAT_BIG, s->big_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SPLAT_RAS, s->ras_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SPLAT_RECT, s->rect_buf);
    for (int p_ = 0; p_ < P_COUNT; p_++) set_uniforms(gl, s, p_, v, p, rayo, rayd, light);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SPLAT_KEYS);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->key_tex);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SPLAT_SUMS);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->frame_tex);
    gl->ActiveTexture(GL_TEXTURE0);

    /* One buffer set (the usual case) is bound once for every stripe and pass. */
    f->one_set = c->nsets == 1;
    if (f->one_set) {
        int64_t total = set_points(k, s, d, 0, err);
        if (total < 0) return (int)total;
        f->total = total;
        if (total == 0 && !even_empty) return 0;
    }
    f->rows = rows;
    f->nstripes = (v->height + rows - 1) / rows;
    return f->nstripes;
}

void splat__stripe_begin(rnd_kit *k, void *state, splat_frame *f, int i)
{
    splat_state *s = state;
    const gl_api *gl = k->gl;
    int height = f->d->view->height;
    f->y0 = i * f->rows;
    f->n = height - f->y0 < f->rows ? height - f->y0 : f->rows;
    int yb = f->y0 > 0 ? f->y0 - 1 : 0; /* halo rows */
    int nb = (f->y0 + f->n < height ? f->y0 + f->n + 1 : f->y0 + f->n) - yb;
    zero_buffer(gl, s->frame_buf);
    zero_buffer(gl, s->key_buf);
    const GLint rect0[4] = {INT32_MAX, INT32_MAX, -1, -1};
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->rect_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof rect0, rect0);
    for (int p_ = 0; p_ < P_COUNT; p_++) {
        gl->UseProgram(s->prog[p_]);
        if (s->loc[p_][U_STRIPE] >= 0) gl->Uniform2i(s->loc[p_][U_STRIPE], yb, nb);
    }
}

/* each_set: runs pass 1 (and, when acc, pass 2) of the stripe over every buffer set. */
static int each_set(rnd_kit *k, splat_state *s, splat_frame *f, int acc, sd_err *err)
{
    const gl_api *gl = k->gl;
    if (f->one_set) {
        GLuint groups = groups_for(s, f->total);
        if (!acc) reset_lists(gl, s); /* pass 2 replays the lists pass 1 made */
        for (int p_ = acc ? P_ACC : P_VIS; p_ <= (acc ? P_ACC_BIG : P_VIS_BIG); p_++)
            run_pass(gl, s, p_, groups);
        return 0;
    }
    for (uint32_t set = 0; set < f->d->cloud->nsets; set++) {
        int64_t tot = set_points(k, s, f->d, set, err);
        if (tot < 0) return (int)tot;
        if (tot == 0) continue;
        GLuint groups = groups_for(s, tot);
        reset_lists(gl, s);
        /* pass 2 of a set follows its pass 1 again, to rebuild that set's splat lists (the
         * keys and the rectangle take the same values again) */
        for (int p_ = P_VIS; p_ <= P_VIS_BIG; p_++) run_pass(gl, s, p_, groups);
        if (acc)
            for (int p_ = P_ACC; p_ <= P_ACC_BIG; p_++) run_pass(gl, s, p_, groups);
    }
    return 0;
}

int splat__visibility(rnd_kit *k, void *state, splat_frame *f, sd_err *err)
{
    return each_set(k, state, f, 0, err);
}

int splat__attributes(rnd_kit *k, void *state, splat_frame *f, sd_err *err)
{
    return each_set(k, state, f, 1, err);
}

void splat__resolve(rnd_kit *k, void *state, splat_frame *f)
{
    splat_state *s = state;
    const gl_api *gl = k->gl;
    const rnd_view *v = f->d->view;
    /* Two triangles over the rectangle pass 1 touched (grown by the gather's pixel; the vertex
     * shader reads it from rect_buf, no read-back) into the target (bound by the renderer, both
     * draw buffers), limited to this stripe's rows by the scissor. */
    gl->UseProgram(s->prog[P_RESOLVE]);
    gl->Disable(GL_DEPTH_TEST);
    gl->Disable(GL_BLEND);
    gl->Enable(GL_SCISSOR_TEST);
    gl->Scissor(0, f->y0, v->width, f->n);
    gl->BindFramebuffer(GL_FRAMEBUFFER, f->d->target->fbo);
    gl->Viewport(0, 0, v->width, v->height);
    gl->BindVertexArray(s->vao);
    gl->DrawArrays(GL_TRIANGLES, 0, 6);
    gl->BindVertexArray(0);
    gl->Disable(GL_SCISSOR_TEST);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT |
                      GL_TEXTURE_FETCH_BARRIER_BIT);
}

int splat__frame_end(rnd_kit *k, void *state, sd_err *err)
{
    (void)state;
    const gl_api *gl = k->gl;
    rnd_kit_unbind(k);
    gl->MemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_FRAMEBUFFER_BARRIER_BIT |
                      GL_TEXTURE_FETCH_BARRIER_BIT | GL_TEXTURE_UPDATE_BARRIER_BIT |
                      GL_PIXEL_BUFFER_BARRIER_BIT);
    gl->UseProgram(0);
    gl->BindBuffer(GL_DISPATCH_INDIRECT_BUFFER, 0);
    return GL_CHECK_PASS(gl, "the splat passes", err);
}

GLuint splat__keys_texture(const void *state)
{
    return ((const splat_state *)state)->key_tex;
}

/* render_sortlast: one rank's part of a sort-last frame (render.h, rnd_exchange): pass 1 over
 * this rank's points, the keys and rectangle replaced by every rank's (the nearest surface of
 * the whole cloud), pass 2 against those, so that each rank adds exactly the fragments a single
 * process would add of its points; the sums added up across the ranks, and the resolve on the
 * rank the exchange names. One stripe only (a frame up to the accumulation buffer's rows). */
static int render_sortlast(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    splat_state *s = state;
    const gl_api *gl = k->gl;
    const rnd_exchange *x = k->exchange;
    const rnd_view *v = d->view;
    splat_frame f;
    int n = frame_begin(k, state, d, &f, 1, err);
    int rc = n < 0 ? n : 0;
    if (rc == 0 && n != 1)
        rc = sd_errf(err, SD_ELIMIT, "a %dx%d splat frame needs %d stripes of %d rows; sort-last "
                     "rendering takes one", v->width, v->height, n, f.rows);
    size_t npix = (size_t)v->width * (size_t)v->height;
    uint32_t *buf = rc == 0 ? calloc(npix, SPLAT_PX_BYTES) : NULL;
    if (rc == 0 && !buf) rc = sd_errf(err, SD_ENOMEM, "out of memory for a sort-last frame");
    int draw = rc == 0 && v->points_visible > 0 && (!f.one_set || f.total > 0);
    int32_t rect[4] = {INT32_MAX, INT32_MAX, -1, -1};
    if (rc == 0) {
        splat__stripe_begin(k, state, &f, 0);
        if (draw && (rc = splat__visibility(k, state, &f, err)) == 0) {
            gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT);
            gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->key_buf);
            gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)(npix * 4), buf);
            gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->rect_buf);
            gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof rect, rect);
        }
    }
    int xr = x->keys(x->user, rc, rc == 0 ? buf : NULL, npix, v->width, rect, err);
    if (xr == 0) {
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->key_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)(npix * 4), buf);
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->rect_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof rect, rect);
        gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
        memset(buf, 0, npix * SPLAT_PX_BYTES);
        if (draw && (rc = splat__attributes(k, state, &f, err)) == 0) {
            gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT);
            gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->frame_buf);
            gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0,
                                 (GLsizeiptr)(npix * SPLAT_PX_BYTES), buf);
        }
        xr = x->sums(x->user, rc, rc == 0 ? buf : NULL, npix, s->float_atomics, err);
        if (xr == 1) {
            gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->frame_buf);
            gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)(npix * SPLAT_PX_BYTES),
                              buf);
            gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
            splat__resolve(k, state, &f);
        }
    }
    free(buf);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    int end = splat__frame_end(k, state, err);
    return xr < 0 ? xr : rc < 0 ? rc : end;
}

GLuint splat__keys_buffer(const void *state, uint64_t *bytes)
{
    const splat_state *s = state;
    *bytes = s->key_bytes;
    return s->key_buf;
}

/* render: the three passes, per stripe of rows; see the file comment. */
static int splat_render(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    if (k->exchange) return render_sortlast(k, state, d, err);
    splat_frame f;
    int nstripes = splat__frame_begin(k, state, d, &f, err);
    int rc = nstripes < 0 ? nstripes : 0;
    for (int i = 0; i < nstripes && rc == 0; i++) {
        splat__stripe_begin(k, state, &f, i);
        if ((rc = splat__visibility(k, state, &f, err)) == 0 &&
            (rc = splat__attributes(k, state, &f, err)) == 0)
            splat__resolve(k, state, &f);
    }
    int end = splat__frame_end(k, state, err);
    return rc < 0 ? rc : end;
}

static int splat_create(rnd_kit *k, void **state, sd_err *err)
{
    return splat_create_with(k, state, 0, err);
}

int splat__create(rnd_kit *k, void **state, sd_err *err)
{
    return splat_create_with(k, state, 0, err);
}

int splat__create_filtered(rnd_kit *k, void **state, sd_err *err)
{
    return splat_create_with(k, state, 1, err);
}

void splat__set_filter(rnd_kit *k, void *state, int mode, float t)
{
    splat_state *s = state;
    for (int p = 0; p < P_RESOLVE; p++) {
        if (s->floc[p][1] < 0) continue;
        k->gl->UseProgram(s->prog[p]);
        if (s->floc[p][0] >= 0) k->gl->Uniform1i(s->floc[p][0], mode);
        k->gl->Uniform1f(s->floc[p][1], t);
    }
}

void splat__set_set_hook(void *state, void (*fn)(void *user, uint32_t set), void *user)
{
    splat_state *s = state;
    s->set_hook = fn;
    s->set_hook_user = user;
}

void splat__destroy(rnd_kit *k, void *state)
{
    splat_destroy(k, state);
}

/* splat_trim: the stripe's accumulation and key buffers go (the next render makes them again:
 * frame_buf 0 is a new size). */
static void splat_trim(rnd_kit *k, void *state)
{
    splat_state *s = state;
    GLuint b[2] = {s->frame_buf, s->key_buf};
    if (b[0] || b[1]) k->gl->DeleteBuffers(2, b);
    s->frame_buf = s->key_buf = 0;
    s->frame_bytes = s->key_bytes = 0;
    s->frame_w = s->frame_rows = 0;
}

const rnd_pipeline pipe_splat = {
    .name = "splat",
    .needs = 1u << RND_ATTR_POS | 1u << RND_ATTR_NORMAL | 1u << RND_ATTR_RADIUS |
             1u << RND_ATTR_RGBA | 1u << RND_ATTR_FIELD | 1u << RND_ATTR_INTENSITY |
             1u << RND_ATTR_SCAN,
    .create = splat_create,
    .destroy = splat_destroy,
    .render = splat_render,
    .trim = splat_trim,
};
