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
 *   split   the form below, for software rasterisers (ewa=auto on llvmpipe/softpipe/swrast,
 *           decided from GL_RENDERER at create time).
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
    X(SIZE, "u_size") X(STRIPE, "u_stripe") X(SCALE, "u_scale")               \
    X(PRE, "u_pre") X(SUBPX, "u_subpx") X(POST, "u_post") X(EPSG, "u_epsg") X(ACC, "u_acc")  \
    X(EPS, "u_eps") X(ZNEAR, "u_znear") X(TOTAL, "u_total") X(NRANGES, "u_nranges")          \
    X(BIGPX, "u_big") X(COLOR, "u_color") X(LIGHT, "u_light") X(ZFAR, "u_zfar")              \
    X(TPOS, "u_pos") X(TNRM, "u_nrm") X(TRAD, "u_rad") X(TSRC, "u_src") X(KEYS, "u_keys")  \
    X(TRANGES, "u_ranges")

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
    int software;              /* GL_RENDERER names a software rasteriser: ewa=auto is split */
    GLuint groups_cap;         /* most work groups per splat dispatch; invocations loop over
                                  the points (grid stride). llvmpipe pays ~3 us a work group, so
                                  there 1024 groups of 64 (1M points: 15 each) measured 20-25 %
                                  faster than one group per 64 points; a GPU wants them all. */
    GLint64 max_ssbo;          /* GL_MAX_SHADER_STORAGE_BLOCK_SIZE */
    GLint64 max_texels;        /* GL_MAX_TEXTURE_BUFFER_SIZE */
    int max_rows;              /* SPLATD_SPLAT_STRIPE_ROWS (tests): rows per stripe, 0 = any */
    GLuint vao;                /* empty, for the resolve's two triangles       */
    GLuint frame_buf;          /* the accumulation buffer: Px per pixel of one stripe */
    GLuint frame_tex;          /* the same buffer as a buffer texture, for the resolve */
    GLuint key_buf, key_tex;   /* the visibility keys (uint a pixel), and as a texture */
    GLuint cloud_tex[4];       /* buffer textures over pos, normal, radius, colour source */
    int frame_w, frame_rows;
    GLuint big_buf;            /* dispatch header + big splat indices */
    GLuint ras_buf;            /* dispatch header + sampled (not deposited) splat indices */
    uint64_t list_cap;         /* indices each holds */
    GLuint range_buf;          /* uvec2 (first point, first visible index) per range */
    GLuint range_tex;          /* RG32UI buffer texture over range_buf (lib_ranges.glsl) */
    GLuint rect_buf;           /* ivec4: the pixels pass 1 touched in the stripe (the resolve's
                                  rectangle) */
    uint32_t range_cap;
    uint32_t *range_tmp;
} splat_state;

/* Whether the current context lists extension name. */
static int gl_has_extension(const gl_api *gl, const char *name)
{
    GLint n = 0;
    gl->GetIntegerv(GL_NUM_EXTENSIONS, &n);
    for (GLint i = 0; i < n; i++) {
        const char *e = (const char *)gl->GetStringi(GL_EXTENSIONS, (GLuint)i);
        if (e && !strcmp(e, name)) return 1;
    }
    return 0;
}

/* Compiles shader file `name` (stage from its name) with `defines` inserted after its #version
 * line. Returns the shader, or 0 with err filled. */
static GLuint build_shader(const gl_api *gl, const rnd_shaders *sh, const char *name,
                           const char *defines, sd_err *err)
{
    const char *text;
    char *owned = NULL, origin[512];
    GLenum stage;
    if (rnd_shaders_source(sh, name, &text, &owned, origin, sizeof origin, err) < 0) return 0;
    if (rnd_shader_stage(name, text, &stage, err) < 0) {
        free(owned);
        return 0;
    }
    const char *nl = strchr(text, '\n');
    size_t head = nl ? (size_t)(nl - text) + 1 : strlen(text);
    size_t dl = strlen(defines), tl = strlen(text);
    char *full = malloc(tl + dl + 2);
    if (!full) {
        free(owned);
        sd_errf(err, SD_ENOMEM, "out of memory building shader %s", name);
        return 0;
    }
    memcpy(full, text, head);
    if (!nl) full[head++] = '\n';
    memcpy(full + head, defines, dl);
    memcpy(full + head + dl, text + (nl ? head : tl), tl - (nl ? head : tl) + 1);
    free(owned);
    char where[600];
    snprintf(where, sizeof where, "%s [%s]", origin, defines);
    for (char *q = where; *q; q++)
        if (*q == '\n') *q = ' ';
    GLuint s = gl_shader_compile(gl, stage, full, where, err);
    free(full);
    return s;
}

/* Links the shader files names[0..n-1] (1 or 2), each compiled with `defines`, into a program.
 * Returns the program, or 0 with err filled. */
static GLuint build_program(const gl_api *gl, const rnd_shaders *sh, const char *const *names,
                            int n, const char *defines, sd_err *err)
{
    GLuint shaders[2] = {0, 0};
    for (int i = 0; i < n; i++) {
        shaders[i] = build_shader(gl, sh, names[i], defines, err);
        if (!shaders[i]) {
            if (i) gl->DeleteShader(shaders[0]);
            return 0;
        }
    }
    GLuint prog = gl->CreateProgram();
    for (int i = 0; i < n; i++) gl->AttachShader(prog, shaders[i]);
    gl->LinkProgram(prog);
    for (int i = 0; i < n; i++) {
        gl->DetachShader(prog, shaders[i]);
        gl->DeleteShader(shaders[i]);
    }
    GLint ok = 0;
    gl->GetProgramiv(prog, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[400] = "";
        gl->GetProgramInfoLog(prog, sizeof log, NULL, log);
        sd_errf(err, SD_EGL, "program %s%s%s: link failed: %s", names[0], n > 1 ? " + " : "",
                n > 1 ? names[1] : "", log);
        gl->DeleteProgram(prog);
        return 0;
    }
    return prog;
}

static void splat_destroy(const gl_api *gl, void *state)
{
    splat_state *s = state;
    if (!s) return;
    for (int i = 0; i < P_COUNT; i++)
        if (s->prog[i]) gl->DeleteProgram(s->prog[i]);
    if (s->frame_tex) gl->DeleteTextures(1, &s->frame_tex);
    if (s->key_tex) gl->DeleteTextures(1, &s->key_tex);
    if (s->cloud_tex[0]) gl->DeleteTextures(4, s->cloud_tex);
    if (s->range_tex) gl->DeleteTextures(1, &s->range_tex);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    GLuint bufs[6] = {s->frame_buf, s->key_buf, s->big_buf, s->ras_buf, s->range_buf,
                      s->rect_buf};
    for (int i = 0; i < 6; i++)
        if (bufs[i]) gl->DeleteBuffers(1, &bufs[i]);
    free(s->range_tmp);
    memset(s, 0, sizeof *s);
    free(s);
}

/* create: compiles the five programs (float or fixed-point atomics, chosen by the extension
 * string; SPLATD_SPLAT_FIXED=1 in the environment forces fixed point, for tests). */
static int splat_create(const gl_api *gl, const rnd_shaders *sh, void **state, sd_err *err)
{
    *state = NULL;
    splat_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory creating the splat pipeline");
    const char *force = getenv("SPLATD_SPLAT_FIXED");
    const char *renderer = (const char *)gl->GetString(GL_RENDERER);
    s->software = renderer && (strstr(renderer, "llvmpipe") || strstr(renderer, "softpipe") ||
                               strstr(renderer, "swrast"));
    s->groups_cap = s->software ? SPLAT_SW_GROUPS : SPLAT_MAX_GROUPS;
    s->float_atomics = gl_has_extension(gl, "GL_NV_shader_atomic_float") && !(force && *force == '1');
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
        snprintf(defs, sizeof defs, "%s%s", fa, progs[p].defs);
        s->prog[p] = build_program(gl, sh, progs[p].files, progs[p].n, defs, err);
        if (!s->prog[p]) {
            splat_destroy(gl, s);
            return err ? err->code : SD_EGL;
        }
        for (int u = 0; u < U_COUNT; u++) s->loc[p][u] = gl_uniform(gl, s->prog[p], unames[u]);
    }
    GLint v = 0;
    gl->GetIntegerv(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &v);
    s->max_ssbo = v > 0 ? v : (1 << 27);
    v = 0;
    gl->GetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &v);
    s->max_texels = v > 0 ? v : 65536;
    gl->GenVertexArrays(1, &s->vao);
    const char *rows = getenv("SPLATD_SPLAT_STRIPE_ROWS");
    s->max_rows = rows ? atoi(rows) : 0;
    int rc = gl_check(gl, "creating the splat pipeline", err);
    if (rc < 0) {
        splat_destroy(gl, s);
        return rc;
    }
    *state = s;
    return 0;
}

/* Makes sure buffer *buf holds at least bytes (growing it, contents lost). Returns 1 when it
 * was (re)allocated. */
static int ensure_buffer(const gl_api *gl, GLuint *buf, uint64_t have, uint64_t bytes)
{
    if (*buf && have >= bytes) return 0;
    if (!*buf) gl->GenBuffers(1, buf);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, *buf);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)bytes, NULL, GL_DYNAMIC_DRAW);
    return 1;
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
                         uint32_t total, const float light[3])
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
    if (l[U_ACC] >= 0) gl->Uniform1i(l[U_ACC], 0);
    for (int k = 0; k < 4; k++)
        if (l[U_TPOS + k] >= 0) gl->Uniform1i(l[U_TPOS + k], 1 + k);
    if (l[U_KEYS] >= 0) gl->Uniform1i(l[U_KEYS], 5);
    if (l[U_TRANGES] >= 0) gl->Uniform1i(l[U_TRANGES], 6);
    if (l[U_EPS] >= 0) gl->Uniform1f(l[U_EPS], SPLAT_EPS);
    if (l[U_ZNEAR] >= 0) gl->Uniform1f(l[U_ZNEAR], v->znear);
    if (l[U_TOTAL] >= 0) gl->Uniform1ui(l[U_TOTAL], total);
    if (l[U_NRANGES] >= 0) gl->Uniform1ui(l[U_NRANGES], v->nranges);
    if (l[U_BIGPX] >= 0) gl->Uniform1ui(l[U_BIGPX], SPLAT_BIG_PIXELS);
    if (l[U_COLOR] >= 0) gl->Uniform1i(l[U_COLOR], prm->color);
    if (l[U_LIGHT] >= 0) gl->Uniform3fv(l[U_LIGHT], 1, light);
    if (l[U_ZFAR] >= 0) gl->Uniform1f(l[U_ZFAR], v->zfar);
}

/* Uploads the visible ranges as (first point, first visible index) pairs. Returns the visible
 * total, or -1 when out of memory. */
static int64_t upload_ranges(const gl_api *gl, splat_state *s, const rnd_view *v)
{
    if (v->nranges > s->range_cap) {
        uint32_t cap = v->nranges < 64 ? 64 : v->nranges;
        uint32_t *t = realloc(s->range_tmp, (size_t)cap * 2 * sizeof *t);
        if (!t) return -1;
        s->range_tmp = t;
        ensure_buffer(gl, &s->range_buf, 0, (uint64_t)cap * 8);
        s->range_cap = cap;
    }
    uint64_t total = 0;
    for (uint32_t i = 0; i < v->nranges; i++) {
        s->range_tmp[2 * i] = v->range_first[i];
        s->range_tmp[2 * i + 1] = (uint32_t)total;
        total += v->range_count[i];
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->range_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)v->nranges * 8, s->range_tmp);
    return (int64_t)total;
}

/* render: the three passes, per stripe of rows; see the file comment. */
static int splat_render(const gl_api *gl, void *state, const rnd_gpu_cloud *c, const rnd_view *v,
                        const sp_params *p, const rnd_target *t, sd_err *err)
{
    splat_state *s = state;
    if (!c->pos || !c->normal || !c->radius)
        return sd_errf(err, SD_EINVAL, "the splat pipeline needs positions, normals and radii");
    if (v->nranges == 0 || v->points_visible == 0) return 0;
    if (v->width <= 0 || v->height <= 0) return sd_errf(err, SD_EINVAL, "bad frame size");
    int64_t total = upload_ranges(gl, s, v);
    if (total < 0) return sd_errf(err, SD_ENOMEM, "out of memory for the splat ranges");
    if (total == 0) return 0;
    if (total > (int64_t)UINT32_MAX - 64)
        return sd_errf(err, SD_ELIMIT, "%lld visible points are more than the splat pipeline "
                       "addresses (2^32)", (long long)total);

    uint64_t last = 0; /* the largest point index + 1 the ranges reach */
    for (uint32_t i = 0; i < v->nranges; i++)
        if ((uint64_t)v->range_first[i] + v->range_count[i] > last)
            last = (uint64_t)v->range_first[i] + v->range_count[i];
    if (3 * last > (uint64_t)s->max_texels)
        return sd_errf(err, SD_ELIMIT, "the splat pipeline reads points through buffer textures "
                       "of at most %lld texels, 3 a point: at most %lld points, and this cloud "
                       "has %llu", (long long)s->max_texels, (long long)s->max_texels / 3,
                       (unsigned long long)last);

    /* Accumulation buffer: as many rows as one storage block (and a buffer texture of 2 texels
     * a pixel) may hold, including one halo row above and below the stripe for the resolve's
     * 3x3 gather. */
    int64_t rows_fit = s->max_ssbo / ((int64_t)v->width * SPLAT_PX_BYTES);
    if (rows_fit > s->max_texels / (2 * (int64_t)v->width)) rows_fit = s->max_texels / (2 * (int64_t)v->width);
    rows_fit -= 2;
    if (s->max_rows > 0 && rows_fit > s->max_rows) rows_fit = s->max_rows;
    if (rows_fit < 1)
        return sd_errf(err, SD_ELIMIT, "a %d pixel wide frame needs a %lld byte storage block "
                       "for 3 rows; the GL allows %lld", v->width,
                       (long long)v->width * SPLAT_PX_BYTES * 3, (long long)s->max_ssbo);
    int rows = v->height < rows_fit ? v->height : (int)rows_fit;
    if (s->frame_w != v->width || s->frame_rows != rows || !s->frame_buf) {
        uint64_t bytes = (uint64_t)v->width * (uint64_t)(rows + 2) * SPLAT_PX_BYTES;
        ensure_buffer(gl, &s->frame_buf, 0, bytes);
        if (!s->frame_tex) gl->GenTextures(1, &s->frame_tex);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->frame_tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, s->float_atomics ? GL_RGBA32F : GL_RGBA32UI, s->frame_buf);
        ensure_buffer(gl, &s->key_buf, 0, bytes / SPLAT_PX_BYTES * 4);
        if (!s->key_tex) gl->GenTextures(1, &s->key_tex);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->key_tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, s->key_buf);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
        s->frame_w = v->width, s->frame_rows = rows;
    }
    uint64_t list_bytes = (SPLAT_BIG_HEADER + (uint64_t)total) * 4;
    uint64_t list_have = (SPLAT_BIG_HEADER + s->list_cap) * 4;
    int grown = ensure_buffer(gl, &s->big_buf, list_have, list_bytes);
    grown |= ensure_buffer(gl, &s->ras_buf, list_have, list_bytes);
    if (grown) s->list_cap = (uint64_t)total;
    ensure_buffer(gl, &s->rect_buf, 16, 16);

    float rayo[4], rayd[4], light[3];
    splat_ray_coeffs(v->proj, v->width, v->height, rayo, rayd);
    float ll = sqrtf(p->light[0] * p->light[0] + p->light[1] * p->light[1] + p->light[2] * p->light[2]);
    for (int i = 0; i < 3; i++) light[i] = ll > 0.0f ? p->light[i] / ll : (i == 2 ? 1.0f : 0.0f);

    GLuint src = p->color == SP_COLOR_FIELD ? c->field
               : p->color == SP_COLOR_INTENSITY ? c->intensity : c->rgba;
    if (!src) src = c->rgba ? c->rgba : c->radius; /* never read for normal/depth colours */
    /* The cloud's buffers as buffer textures on units 1-4 (see splat_raster.comp). */
    if (!s->cloud_tex[0]) gl->GenTextures(4, s->cloud_tex);
    const GLuint cbuf[4] = {c->pos, c->normal, c->radius, src};
    const GLenum cfmt[4] = {GL_R32F, GL_R32F, GL_R32F, GL_R32UI}; /* lib_fetch.glsl */
    for (int k = 0; k < 4; k++) {
        gl->ActiveTexture(GL_TEXTURE1 + k);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->cloud_tex[k]);
        gl->TexBuffer(GL_TEXTURE_BUFFER, cfmt[k], cbuf[k]);
    }
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, s->key_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, s->frame_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, s->big_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 7, s->ras_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 8, s->rect_buf);

    uint64_t groups64 = ((uint64_t)total + SPLAT_GROUP - 1) / SPLAT_GROUP;
    GLuint groups = groups64 > s->groups_cap ? s->groups_cap : (GLuint)groups64;
    for (int p_ = 0; p_ < P_COUNT; p_++)
        set_uniforms(gl, s, p_, v, p, rayo, rayd, (uint32_t)total, light);

    gl->ActiveTexture(GL_TEXTURE5);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->key_tex);
    if (!s->range_tex) gl->GenTextures(1, &s->range_tex);
    gl->ActiveTexture(GL_TEXTURE6);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->range_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_RG32UI, s->range_buf);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->frame_tex);
    for (int y0 = 0; y0 < v->height; y0 += rows) {
        int n = v->height - y0 < rows ? v->height - y0 : rows;
        int yb = y0 > 0 ? y0 - 1 : 0;                                   /* halo rows */
        int nb = (y0 + n < v->height ? y0 + n + 1 : y0 + n) - yb;
        zero_buffer(gl, s->frame_buf);
        zero_buffer(gl, s->key_buf);
        const GLuint header[SPLAT_BIG_HEADER] = {0, 1, 1, 0};
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->big_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof header, header);
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->ras_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof header, header);
        const GLint rect0[4] = {INT32_MAX, INT32_MAX, -1, -1};
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->rect_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof rect0, rect0);
        for (int p_ = 0; p_ < P_COUNT; p_++) {
            gl->UseProgram(s->prog[p_]);
            if (s->loc[p_][U_STRIPE] >= 0) gl->Uniform2i(s->loc[p_][U_STRIPE], yb, nb);
            if (p_ == P_VIS || p_ == P_ACC) {
                gl->DispatchCompute(groups, 1, 1);
            } else if (p_ != P_RESOLVE) {
                int big = p_ == P_VIS_BIG || p_ == P_ACC_BIG;
                gl->BindBuffer(GL_DISPATCH_INDIRECT_BUFFER, big ? s->big_buf : s->ras_buf);
                gl->DispatchComputeIndirect(0);
            } else {
                /* Two triangles over the rectangle pass 1 touched (grown by the gather's
                 * pixel; the vertex shader reads it from rect_buf, no read-back) into the
                 * target (bound by the renderer, both draw buffers), limited to this stripe's
                 * rows by the scissor. */
                gl->Disable(GL_DEPTH_TEST);
                gl->Disable(GL_BLEND);
                gl->Enable(GL_SCISSOR_TEST);
                gl->Scissor(0, y0, v->width, n);
                gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
                gl->Viewport(0, 0, v->width, v->height);
                gl->BindVertexArray(s->vao);
                gl->DrawArrays(GL_TRIANGLES, 0, 6);
                gl->BindVertexArray(0);
                gl->Disable(GL_SCISSOR_TEST);
            }
            gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT |
                              GL_TEXTURE_FETCH_BARRIER_BIT);
        }
    }
    for (int k = 6; k >= 0; k--) {
        gl->ActiveTexture(GL_TEXTURE0 + k);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
    }
    gl->MemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_FRAMEBUFFER_BARRIER_BIT |
                      GL_TEXTURE_FETCH_BARRIER_BIT | GL_TEXTURE_UPDATE_BARRIER_BIT |
                      GL_PIXEL_BUFFER_BARRIER_BIT);
    gl->UseProgram(0);
    gl->BindBuffer(GL_DISPATCH_INDIRECT_BUFFER, 0);
    int rc = GL_CHECK_PASS(gl, "the splat passes", err);
    if (rc < 0) return rc;
    return 0;
}

const rnd_pipeline pipe_splat = {"splat", splat_create, splat_destroy, splat_render};
