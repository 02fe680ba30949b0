/* pipe_kawata.c — the `kawata` pipeline: Direct Point Rendering (Kawata & Kanai, ISVC 2005),
 * five passes over clouds that need nothing but positions (colours are used when present;
 * file normals, radii and F are never read). Passes 1-2 rasterise points into the small image
 * buffer with compute shaders where the paper used point sprites and the depth test (DESIGN.md
 * "Rasterisation strategy"); passes 3-4 are compute passes over the list of covered buffer
 * pixels, pass 5 a fragment pass (llvmpipe shades pixel quads at once); all read through
 * buffer textures (gathers on llvmpipe; a 2-D texelFetch cost several times as much).
 *
 * Image buffer (eq. 1-3). The paper's eq. 2-3 are garbled in the text; DESIGN.md reads them as:
 * rho = the frame-buffer pixels that the point spacing sigma covers at the distance of the
 * cloud's centroid, sigma * (h_s / 2) / (tan(fov_y / 2) |v - p~|), times kawata_rho_scale, at
 * least 1; the buffer is ceil(w_s / rho) x ceil(h_s / rho). sigma is the median
 * nearest-neighbour distance from prep (the paper's minimum is 0 for duplicate points); a
 * cloud without one (sigma 0) uses the spacing of its points spread over its bounding box's
 * largest face. kawata_rho_scale defaults to 3.5: sigma is the *median* nearest-neighbour
 * distance, and for irregular samples (a scan's sampling is not a grid) a buffer pixel of one
 * sigma holds on average a fraction of a point (about 0.22 for uniformly random points), which
 * leaves buffer pixels empty and the fit without support. Measured: at 1.5 Guanyin.ply's
 * default view showed holes of several buffer pixels; at 2.5 it had none but a sparse plane of
 * uniformly random points (test_sparse_holes) still had 28 empty frame pixels (3 with a 5x5
 * gather of cut-off 2); at 3.5 (2.7 random points a buffer pixel, 12 of a grid) none. The price
 * is the paper's own: a blurrier image than `splat` on clean scans.
 *
 *   pass 1  kawata_raster.comp, PASS 1: per point, atomicMin of its eye depth (float bits)
 *           into its buffer pixel: Omega_1's depth.
 *   pass 2  kawata_raster.comp, PASS 2: points with exactly that depth store their index
 *           (atomicMin: ties go to the lowest index), points behind it by at most gamma store
 *           atomicMax of (depth step quantised to the high bits | index): the farthest point
 *           within gamma, Omega_2. gamma = kawata_gamma x the bounding box's diagonal (paper:
 *           0.5-1 %; default 0.75 %). llvmpipe has no 64-bit atomics; quantising the step
 *           relative to gamma leaves 32 - index bits levels for it (4096 for 1M points).
 *   list    kawata_fit.comp STAGE 0: the buffer pixels of the rectangle with a nearest point,
 *           in row order (so that neighbours are read together), for passes 3-4: llvmpipe
 *           runs every instruction for every SIMD lane, masked, so fragment passes over the
 *           whole rectangle paid as much for its empty pixels as for covered ones (the 1M
 *           scan's default view: 74k of 213k covered).
 *   pass 3  kawata_fit.comp STAGE 1: per listed buffer pixel, both points to eye space with
 *           their colours; STAGE 2 averages them (Omega_a, the splat's position),
 *   pass 4  and (STAGE 2) fits z = Ax + By + C by least squares to the up to 18 points of the
 *           3x3 neighbourhood in both buffers (eq. 4-5, Cramer's rule on coordinates centred
 *           on Omega_a), normal (A, B, -1) turned towards the eye, Lambert shading (Omega_c).
 *           Outliers: the paper drops points that pass 2 rejects, but a buffer pixel whose
 *           nearest point is an outlier has nothing within gamma behind it, so here a buffer
 *           pixel is kept only when at least KAWATA_MIN_SUPPORT of the other 17 points lie
 *           within the depth tolerance of its nearest one (gamma plus KAWATA_SLOPE_PIXELS
 *           buffer pixels of depth, so surfaces up to ~75 degrees from the view keep their
 *           support); the same points, and only they, enter the fit. A second round refits
 *           without the points beyond 2.5 RMS of the first plane and drops the pixel when its
 *           own nearest point is one of them: gamma is a fraction of the whole cloud, so in a
 *           large scene (the 1M scan: 0.75 m) stray points well off a surface pass the depth
 *           test and tilted the fit enough to darken their pixels.
 *   pass 5  kawata_splat.vert/.frag: Gaussian splats from the buffer magnified to the frame,
 *           normalised blending, as a gather: each frame pixel sums the splats of the 5x5 buffer
 *           pixels around it whose centres lie within KAWATA_CUTOFF (2) buffer pixels, kernel
 *           standard deviation KAWATA_SIGMA (0.75), keeping only those within the depth
 *           tolerance of the nearest one (the extended z-buffer's rule), and divides by the
 *           summed weight. A cut-off of 1.5 (a 4x4 gather) left 94 one-pixel holes in the
 *           README figure's view of the 1M scan, where buffer pixels of the far ground are
 *           empty; 2 leaves 14. On llvmpipe a fragment pass shades whole pixel quads at once,
 *           where scattering splats with float atomics runs lane by lane. It is drawn as two
 *           triangles per 8x8 tile of buffer pixels that the fit marked as within reach of a
 *           splat, and none elsewhere (kawata_splat.vert), so empty parts of the rectangle
 *           are not rasterised: the same pixels are written, with the same values.
 *
 * A cloud in several buffer sets (pipe.h) is drawn set by set: passes 1 and 2 key points by
 * their cloud-wide index, and STAGE 1 runs once per set, each resolving the points of its own.
 *
 * With the renderer's host paths (pipe.h rnd_host: a software renderer) passes 1 and 2, the
 * list and STAGE 1 run on the host instead (kawata_cpu.h), over every core, writing the same
 * arrays: the same decisions (buffer pixel, nearest point, farthest within gamma) as the
 * shader's wherever the precision the GLSL specification allows a GPU leaves no doubt about
 * them (test_render_kawata's test_host_vs_gl states where it may and checks the rest). The
 * positions and colours are read where the GL keeps them, each buffer set's buffers mapped for
 * reading (on llvmpipe its own memory: no copy; a LOD pool's two sets share their buffers,
 * mapped once), and the arrays are written into the mapped storage buffers, which are unmapped
 * before the fit. The fit (STAGE 2) and the gather stay in the GL on every back end.
 * color=field keeps STAGE 0-1 in the GL (its colour map is a shader polynomial). Every cloud
 * form the GL path draws (one set, several, LOD pools, ranges after culling and budgets) goes
 * through the host path; there is no fallback to the GL for any of them.
 *
 * Costs of each pass on llvmpipe, and of the host path against the GL's: docs/performance.md
 * ("kawata", "Host paths"). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "host.h"
#include "pipe.h"
#include "progress.h"
#include "shaders.h"
#include "soft_cpu.h"

enum { GROUP = 64, MAX_GROUPS_X = 65535 };
enum { KAWATA_MIN_SUPPORT = 3 };     /* a plane needs three points; see the file comment */
#define KAWATA_SLOPE_PIXELS 4.0f     /* depth tolerance: buffer pixels of depth per pixel */
#define KAWATA_CUTOFF 2.0f           /* splat cut-off radius, buffer pixels (5x5 gather) */
#define KAWATA_SIGMA 0.75f           /* the splats' standard deviation, buffer pixels */
enum { LIST_PER = 32 };              /* passes 3-4: list entries an invocation, at most */

#define KAWATA_UNIFORMS(X)                                                                   \
    X(VIEWPROJ, "u_viewproj") X(VIEW, "u_view") X(PROJ, "u_proj") X(BSIZE, "u_bsize")         \
    X(FSIZE, "u_fsize") X(ZNEAR, "u_znear") X(ZFAR, "u_zfar") X(TOTAL, "u_total")             \
    X(NRANGES, "u_nranges") X(FIRST, "u_first") X(STRIDE, "u_stride") X(THREADS, "u_threads")  \
    X(PER, "u_per") X(BASE, "u_base") X(SETN, "u_count")                                       \
    X(IBITS, "u_index_bits") X(GAMMA, "u_gamma") X(QSCALE, "u_qscale") X(QMAX, "u_qmax")       \
    X(SLOPE, "u_slope") X(COLOR, "u_color") X(LIGHT, "u_light") X(SUPPORT, "u_min_support")   \
    X(ALL, "u_all") X(CUTOFF, "u_cutoff") X(BLO, "u_blo") X(BHI, "u_bhi") X(KERNEL, "u_k")    \
    X(T0, "u_t0") X(TCOLS, "u_tcols")

enum {
#define KW_U_ENUM_(id, name) U_##id,
    KAWATA_UNIFORMS(KW_U_ENUM_)
#undef KW_U_ENUM_
    U_COUNT
};

enum { P_RASTER1 = 0, P_RASTER2, P_LIST, P_RESOLVE, P_FIT, P_SPLAT, P_COUNT };
enum { B_DEPTH = 0, B_NEAR, B_FAR, B_PTS, B_SPLATS, B_LIST, B_TILES, B_COUNTER, NBUF };
enum { PTS_BYTES = 64, SPLAT_BYTES = 32 }; /* per buffer pixel */

typedef struct kawata_state {
    GLuint prog[P_COUNT];
    GLint loc[P_COUNT][U_COUNT];
    uint32_t per_invocation;   /* points per raster invocation (as pipe_points.c) */
    GLuint vao;
    GLuint buf[NBUF];
    uint64_t bytes[NBUF];
    GLuint tex[NBUF];          /* buffer textures over buf[] (0 for the counter) */
    /* the host path (kawata_cpu.h): the view's runs of points, each set's mapped positions,
     * the host's working memory and its thread count */
    kawata_cpu_seg *segs;
    kawata_cpu_set *sets;
    uint8_t *own;              /* per set: OWN_POS, OWN_SRC where this set's mapping is held */
    size_t segs_cap, sets_cap, own_cap;
    kawata_cpu_mem mem;
    int threads;
} kawata_state;

static void kawata_destroy(rnd_kit *k, void *state)
{
    kawata_state *s = state;
    if (!s) return;
    const gl_api *gl = k->gl;
    for (int i = 0; i < P_COUNT; i++)
        if (s->prog[i]) gl->DeleteProgram(s->prog[i]);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    gl->DeleteTextures(NBUF, s->tex);
    gl->DeleteBuffers(NBUF, s->buf);
    free(s->segs), free(s->sets), free(s->own);
    kawata_cpu_mem_free(&s->mem);
    memset(s, 0, sizeof *s);
    free(s);
}

static int kawata_create(rnd_kit *k, void **state, sd_err *err)
{
    *state = NULL;
    const gl_api *gl = k->gl;
    kawata_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory for the kawata pipeline");
    /* llvmpipe pays ~50 ns per compute invocation (pipe_points.c): a run of points each. */
    s->per_invocation = k->software ? 32 : 1;
    s->threads = prep_default_threads();
    static const struct {
        const char *files[2];
        int n;
        const char *defs;
    } progs[P_COUNT] = {
        [P_RASTER1] = {{"kawata_raster.comp"}, 1, "#define PASS 1\n"},
        [P_RASTER2] = {{"kawata_raster.comp"}, 1, "#define PASS 2\n"},
        [P_LIST] = {{"kawata_fit.comp"}, 1, "#define STAGE 0\n"},
        [P_RESOLVE] = {{"kawata_fit.comp"}, 1, "#define STAGE 1\n"},
        [P_FIT] = {{"kawata_fit.comp"}, 1, "#define STAGE 2\n"},
        [P_SPLAT] = {{"kawata_splat.vert", "kawata_splat.frag"}, 2, NULL},
    };
    static const char *const unames[U_COUNT] = {
#define KW_U_NAME_(id, name) name,
        KAWATA_UNIFORMS(KW_U_NAME_)
#undef KW_U_NAME_
    };
    for (int p = 0; p < P_COUNT; p++) {
        s->prog[p] = rnd_kit_program(k, progs[p].files, progs[p].n, progs[p].defs, err);
        if (!s->prog[p]) {
            kawata_destroy(k, s);
            return err && err->code ? err->code : SD_EGL;
        }
        for (int u = 0; u < U_COUNT; u++) s->loc[p][u] = gl_uniform(gl, s->prog[p], unames[u]);
    }
    gl->GenVertexArrays(1, &s->vao);
    gl->GenBuffers(NBUF, s->buf);
    gl->GenTextures(NBUF, s->tex);
    int rc = gl_check(gl, "creating the kawata pipeline", err);
    if (rc < 0) {
        kawata_destroy(k, s);
        return rc;
    }
    *state = s;
    return 0;
}

/* Bits for a point index of a cloud of n points, leaving 0 free in pass 2's keys: the smallest
 * b with n <= 2^b - 1 (as pipe_points.c). */
static uint32_t index_bits(uint64_t n)
{
    uint32_t b = 1;
    while (b < 32 && ((uint64_t)1 << b) - 1 < n) b++;
    return b;
}

/* kawata_rho: the image buffer's pixel size in frame pixels (eq. 1-3 as the file comment reads
 * them), at least 1. */
static double kawata_rho(const rnd_gpu_cloud *c, const rnd_view *v, float scale)
{
    double sigma = c->sigma;
    if (!(sigma > 0)) {
        /* no spacing from prep: points spread evenly over the box's largest face */
        double e[3], face = 0;
        for (int i = 0; i < 3; i++) e[i] = (double)c->bmax[i] - c->bmin[i];
        for (int i = 0; i < 3; i++) face = fmax(face, e[i] * e[(i + 1) % 3]);
        sigma = face > 0 ? sqrt(face / (double)c->n) : 0;
    }
    double dist = 0;
    for (int i = 0; i < 3; i++)
        dist += ((double)v->eye[i] - c->centroid[i]) * ((double)v->eye[i] - c->centroid[i]);
    dist = sqrt(dist);
    if (!(dist > 0) || !(sigma > 0)) return 1.0;
    double rho = sigma * 0.5 * v->height / (tan(0.5 * v->fov_y) * dist) * scale;
    return rho > 1.0 ? rho : 1.0;
}

/* buffer: grows s->buf[b] to bytes and binds it on storage block `block` and, when format is
 * not 0, as a buffer texture of that format on unit `unit`. */
static void buffer(const gl_api *gl, kawata_state *s, int b, uint64_t bytes, GLuint block,
                   GLenum format, GLenum unit)
{
    rnd_kit_ensure_ssbo(gl, &s->buf[b], &s->bytes[b], bytes);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, block, s->buf[b]);
    if (!format) return;
    gl->ActiveTexture(GL_TEXTURE0 + unit);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->tex[b]);
    gl->TexBuffer(GL_TEXTURE_BUFFER, format, s->buf[b]);
    gl->ActiveTexture(GL_TEXTURE0);
}

static void fill(const gl_api *gl, GLuint buf, GLintptr at, GLsizeiptr bytes, GLuint value)
{
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, buf);
    gl->ClearBufferSubData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, at, bytes, GL_RED_INTEGER,
                           GL_UNSIGNED_INT, &value);
}

/* Passes 1 and 2 over buffer set `set` (its range table and textures bound). */
static void raster_set(const gl_api *gl, const kawata_state *s, const rnd_gpu_cloud *c,
                       uint32_t set, uint32_t total, uint32_t nranges, uint32_t first, int pass)
{
    uint32_t per = s->per_invocation;
    uint32_t groups = ((total + per - 1) / per + GROUP - 1) / GROUP;
    if (!groups) groups = 1;
    uint32_t gx = groups < MAX_GROUPS_X ? groups : MAX_GROUPS_X, gy = (groups + gx - 1) / gx;
    uint32_t threads = gx * gy * GROUP;
    gl->UseProgram(s->prog[P_RASTER1 + pass - 1]);
    const GLint *l = s->loc[P_RASTER1 + pass - 1];
    gl->Uniform1ui(l[U_TOTAL], total);
    gl->Uniform1ui(l[U_NRANGES], nranges);
    gl->Uniform1ui(l[U_FIRST], first);
    gl->Uniform1ui(l[U_STRIDE], gx * GROUP);
    gl->Uniform1ui(l[U_THREADS], threads);
    gl->Uniform1ui(l[U_PER], (total + threads - 1) / threads);
    gl->Uniform1ui(l[U_BASE], (GLuint)c->sets[set].base);
    gl->DispatchCompute(gx, gy, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
}

/* map: glMapBufferRange of bytes at `at` of buffer buf (through target), or NULL with err
 * filled. */
static void *map(const gl_api *gl, GLenum target, GLuint buf, GLintptr at, GLsizeiptr bytes,
                 GLbitfield access, const char *what, sd_err *err)
{
    gl->BindBuffer(target, buf);
    void *p = gl->MapBufferRange(target, at, bytes, access);
    if (!p && gl_check(gl, what, err) == 0) sd_errf(err, SD_EGL, "kawata: %s failed", what);
    return p;
}

static void unmap(const gl_api *gl, GLenum target, GLuint buf)
{
    gl->BindBuffer(target, buf);
    gl->UnmapBuffer(target);
}

enum { OWN_POS = 1, OWN_SRC = 2 };

/* The mapping of buffer buf for reading (n words): that of an earlier set sharing it (a LOD
 * pool's two sets share all but one buffer; a buffer is mapped once), else a new one, owned by
 * set `set` (bit own). NULL with err filled when it cannot be mapped. */
static const void *map_shared(const gl_api *gl, kawata_state *s, const rnd_gpu_cloud *c,
                              uint32_t set, int attr, uint64_t words, int own, sd_err *err)
{
    GLuint buf = c->sets[set].buf[attr];
    for (uint32_t j = 0; j < c->nsets; j++) {
        const kawata_cpu_set *h = &s->sets[j];
        const void *p = own == OWN_POS ? (const void *)h->pos : (const void *)h->src;
        if (j != set && p && c->sets[j].buf[attr] == buf) return p;
    }
    const void *p = map(gl, GL_COPY_READ_BUFFER, buf, 0, (GLsizeiptr)(words * 4),
                        GL_MAP_READ_BIT, own == OWN_POS ? "mapping a buffer set's positions"
                                                        : "mapping a buffer set's colours", err);
    if (p) s->own[set] |= (uint8_t)own;
    return p;
}

/* Passes 1 and 2 through the host paths h (kawata_cpu.h) into rows [y0, y1) of the depth, near
 * and far buffers, and with rj (not NULL) the list and pass 3's first half too (*nlist: the
 * listed pixels, also written to the counter). The positions of every buffer set with a
 * visible chunk (and with rj its colour source) are mapped for reading, the buffers written
 * mapped for writing (on a software renderer both are the GL's own memory: no copy either
 * way), and all are unmapped for the GL passes that follow. job and rj hold the frame's
 * constants. Returns 0 or SD_E*. */
static int host_passes(const gl_api *gl, const rnd_host *h, kawata_state *s,
                       const rnd_gpu_cloud *c, const rnd_view *v, kawata_cpu_job *job,
                       kawata_cpu_resolve_job *rj, int color, uint32_t *nlist, sd_err *err)
{
    uint32_t ns = c->nsets ? c->nsets : 1;
    if (soft_cpu_grow((void **)&s->segs, &s->segs_cap, v->nchunks ? v->nchunks : 1,
                      sizeof *s->segs) ||
        soft_cpu_grow((void **)&s->sets, &s->sets_cap, ns, sizeof *s->sets) ||
        soft_cpu_grow((void **)&s->own, &s->own_cap, ns, 1))
        return sd_errf(err, SD_ENOMEM, "out of memory for kawata's host passes");
    memset(s->sets, 0, ns * sizeof *s->sets);
    memset(s->own, 0, ns);
    for (uint32_t i = 0; i < c->nsets; i++)
        s->sets[i].base = c->sets[i].base, s->sets[i].n = c->sets[i].n;
    int src = rnd_kit_color_source(color), rc = 0;
    uint32_t nsegs = 0;
    for (uint32_t i = 0; i < v->nchunks && rc == 0; i++) {
        const rnd_chunk *ch = &v->chunks[i];
        if (ch->set >= c->nsets || !ch->count) continue;
        const rnd_bufset *b = &c->sets[ch->set];
        kawata_cpu_set *hs = &s->sets[ch->set];
        if ((uint64_t)ch->first + ch->count > b->n) {
            rc = sd_errf(err, SD_EINVAL, "kawata: chunk %u (points %u + %u) is outside buffer "
                         "set %u of %u points", i, ch->first, ch->count, ch->set, b->n);
            break;
        }
        if (!hs->pos) {
            hs->pos = map_shared(gl, s, c, ch->set, RND_ATTR_POS, (uint64_t)b->n * 3, OWN_POS,
                                 err);
            if (!hs->pos) rc = err && err->code ? err->code : SD_EGL;
        }
        if (rc == 0 && rj && !hs->src) {
            hs->src = map_shared(gl, s, c, ch->set, src, b->n, OWN_SRC, err);
            if (!hs->src) rc = err && err->code ? err->code : SD_EGL;
        }
        s->segs[nsegs++] = (kawata_cpu_seg){hs->pos, b->base, ch->first, ch->count};
    }
    /* depth, near, far, with rj the list and pts */
    static const int bufs[5] = {B_DEPTH, B_NEAR, B_FAR, B_LIST, B_PTS};
    void *arr[5] = {NULL, NULL, NULL, NULL, NULL};
    size_t rows = (size_t)(job->y1 - job->y0), bw = (size_t)job->bw;
    const GLintptr at[5] = {(GLintptr)(job->y0 * bw * 4), (GLintptr)(job->y0 * bw * 4),
                            (GLintptr)(job->y0 * bw * 4), 0, (GLintptr)(job->y0 * bw * 64)};
    size_t area = rj ? (size_t)(rj->x1 - rj->x0) * rows : 0;
    const GLsizeiptr bytes[5] = {(GLsizeiptr)(rows * bw * 4), (GLsizeiptr)(rows * bw * 4),
                                 (GLsizeiptr)(rows * bw * 4), (GLsizeiptr)(area * 4),
                                 (GLsizeiptr)(rows * bw * 64)};
    int nmap = rj ? 5 : 3;
    for (int a = 0; a < nmap && rc == 0 && rows > 0; a++) {
        arr[a] = map(gl, GL_SHADER_STORAGE_BUFFER, s->buf[bufs[a]], at[a], bytes[a],
                     a < 3 ? GL_MAP_READ_BIT | GL_MAP_WRITE_BIT : GL_MAP_WRITE_BIT,
                     "mapping kawata's image buffer", err);
        if (!arr[a]) rc = err && err->code ? err->code : SD_EGL;
    }
    uint32_t listed = 0;
    if (rc == 0 && rows > 0) {
        job->segs = s->segs, job->nsegs = nsegs;
        job->depth = arr[0], job->near = arr[1], job->far = arr[2];
        job->threads = s->threads;
        job->mem = &s->mem;
        if (h->kawata_raster(job) != 0)
            rc = sd_errf(err, SD_ENOMEM, "out of memory for kawata's host passes");
        if (rc == 0 && rj) {
            rj->sets = s->sets, rj->nsets = c->nsets;
            rj->near = arr[1], rj->far = arr[2], rj->list = arr[3], rj->pts = arr[4];
            rj->threads = s->threads;
            listed = h->kawata_resolve(rj);
        }
    }
    for (int a = 0; a < 5; a++)
        if (arr[a]) unmap(gl, GL_SHADER_STORAGE_BUFFER, s->buf[bufs[a]]);
    for (uint32_t i = 0; i < c->nsets; i++) {
        if (s->own[i] & OWN_POS) unmap(gl, GL_COPY_READ_BUFFER, c->sets[i].buf[RND_ATTR_POS]);
        if (s->own[i] & OWN_SRC) unmap(gl, GL_COPY_READ_BUFFER, c->sets[i].buf[src]);
    }
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    if (rc == 0 && rj) { /* the counter: (splats, listed); the GL's fit counts the splats */
        const GLuint counter[2] = {0, listed};
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->buf[B_COUNTER]);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof counter, counter);
        *nlist = listed;
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    return rc;
}

/* rnd_frame.kawata_arrays (rnd_set_kawata_probe) after pass 4: the rectangle brect of depth,
 * near and far read back, then pts (16 words a buffer pixel) for its pixels with a nearest
 * point (those listed), the splats (8 words a buffer pixel) of the rectangle, and the tile
 * marks of the tile rows trect[1] .. trect[3]; everything else 0. NULL when out of memory (the
 * frame then carries none). */
static uint32_t *probe_arrays(const gl_api *gl, const kawata_state *s, int bw, int bh,
                              const int brect[4], const int trect[4])
{
    size_t nb = (size_t)bw * (size_t)bh, y0 = (size_t)brect[1];
    size_t rows = (size_t)(brect[3] - brect[1]), tw = ((size_t)bw + 7) / 8;
    size_t nt = tw * (((size_t)bh + 7) / 8);
    uint32_t *p = calloc(nb ? 27 * nb + nt : 1, 4);
    if (!p) return NULL;
    gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->buf[B_TILES]);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)((size_t)trect[1] * tw * 4),
                         (GLsizeiptr)((size_t)(trect[3] - trect[1]) * tw * 4),
                         p + 27 * nb + (size_t)trect[1] * tw);
    static const int bufs[5] = {B_DEPTH, B_NEAR, B_FAR, B_PTS, B_SPLATS};
    static const size_t at[5] = {0, 1, 2, 3, 19};
    for (int a = 0; a < 5; a++) {
        size_t w = a < 3 ? 1 : a == 3 ? 16 : 8;
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->buf[bufs[a]]);
        gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(y0 * bw * w * 4),
                             (GLsizeiptr)(rows * bw * w * 4), p + at[a] * nb + y0 * bw * w);
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    for (size_t i = 0; i < nb; i++) {
        int x = (int)(i % (size_t)bw);
        int out = i < y0 * bw || i >= (y0 + rows) * bw || x < brect[0] || x >= brect[2];
        if (out) p[i] = p[nb + i] = p[2 * nb + i] = 0;
        if (out || p[nb + i] == 0xFFFFFFFFu) memset(p + 3 * nb + 16 * i, 0, 64);
        if (out) memset(p + 19 * nb + 8 * i, 0, 32);
    }
    return p;
}

static int kawata_render(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    kawata_state *s = state;
    const gl_api *gl = k->gl;
    const rnd_gpu_cloud *c = d->cloud;
    const rnd_view *v = d->view;
    const sp_params *p = d->params;
    if (!v->nchunks || !v->points_visible) return 0;
    uint32_t ibits = index_bits(c->n);
    if (ibits > 28)
        return sd_errf(err, SD_ELIMIT, "the kawata pipeline keys points in 32 bits with at "
                       "least 4 bits of depth: at most 2^28 - 1 points, not %llu",
                       (unsigned long long)c->n);

    /* The image buffer: ceil(w / rho) x ceil(h / rho) (never larger than the frame). */
    double rho = kawata_rho(c, v, p->kawata_rho_scale);
    int bw = (int)ceil(v->width / rho), bh = (int)ceil(v->height / rho);
    if (bw > v->width) bw = v->width;
    if (bh > v->height) bh = v->height;
    d->out->buffer_w = bw;
    d->out->buffer_h = bh;
    uint64_t nb = (uint64_t)bw * (uint64_t)bh;
    if (bw > 65535 || bh > 65535) /* the list keeps x | y << 16 (frames: 16384 a side) */
        return sd_errf(err, SD_ELIMIT, "a %dx%d kawata image buffer is over 65535 a side", bw,
                       bh);
    if (nb * PTS_BYTES > (uint64_t)k->max_ssbo || nb * 4 > (uint64_t)k->max_texels)
        return sd_errf(err, SD_ELIMIT, "a %dx%d kawata image buffer needs a %llu-byte storage "
                       "block, over the driver's %lld", bw, bh,
                       (unsigned long long)(nb * PTS_BYTES), (long long)k->max_ssbo);

    /* Only the buffer pixels of the cloud's screen rectangle (grown by one for the 3x3 fit) are
     * cleared, resolved and fitted: points cannot land outside it, and the shaders treat
     * pixels outside it as empty (they hold an earlier frame's data). */
    int rect[4], brect[4];
    rnd__screen_rect(v, c->bmin, c->bmax, 1, rect);
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) return 0;
    brect[0] = (int)floor((double)rect[0] * bw / v->width) - 1;
    brect[1] = (int)floor((double)rect[1] * bh / v->height) - 1;
    brect[2] = (int)ceil((double)rect[2] * bw / v->width) + 1;
    brect[3] = (int)ceil((double)rect[3] * bh / v->height) + 1;
    brect[0] = brect[0] < 0 ? 0 : brect[0], brect[1] = brect[1] < 0 ? 0 : brect[1];
    brect[2] = brect[2] > bw ? bw : brect[2], brect[3] = brect[3] > bh ? bh : brect[3];

    /* gamma in local units; pass 2 quantises the depth step d - d1 in (0, gamma] to levels
     * 1 .. qmax - 1 above the index bits (0 stays "none"). */
    double diag = 0;
    for (int i = 0; i < 3; i++) diag += ((double)c->bmax[i] - c->bmin[i]) * (c->bmax[i] - c->bmin[i]);
    float gamma = (float)(p->kawata_gamma * sqrt(diag));
    uint32_t qmax = (uint32_t)(((uint64_t)1 << (32 - ibits)) - 1);
    float qscale = gamma > 0 ? (float)(qmax - 1) / gamma : 0.0f;
    /* KAWATA_SLOPE_PIXELS buffer pixels of depth at unit depth. */
    float slope = KAWATA_SLOPE_PIXELS * 2.0f * tanf(0.5f * v->fov_y) / (float)bh;
    float pixel = fminf((float)v->width / bw, (float)v->height / bh); /* frame px a buffer px */
    float cutoff = KAWATA_CUTOFF * pixel, ksig = KAWATA_SIGMA * pixel;
    float light[3], ll = sqrtf(p->light[0] * p->light[0] + p->light[1] * p->light[1] +
                               p->light[2] * p->light[2]);
    for (int i = 0; i < 3; i++) light[i] = ll > 0 ? p->light[i] / ll : (i == 2 ? 1.0f : 0.0f);

    buffer(gl, s, B_DEPTH, nb * 4, RND_B_KAWATA_DEPTH, GL_R32UI, RND_T_KAWATA_DEPTH);
    buffer(gl, s, B_NEAR, nb * 4, RND_B_KAWATA_NEAR, GL_R32UI, RND_T_KAWATA_NEAR);
    buffer(gl, s, B_FAR, nb * 4, RND_B_KAWATA_FAR, GL_R32UI, RND_T_KAWATA_FAR);
    buffer(gl, s, B_PTS, nb * PTS_BYTES, RND_B_KAWATA_PTS, GL_RGBA32F, RND_T_KAWATA_PTS);
    buffer(gl, s, B_SPLATS, nb * SPLAT_BYTES, RND_B_KAWATA_SPLATS, GL_RGBA32F,
           RND_T_KAWATA_SPLATS);
    buffer(gl, s, B_LIST, nb * 4, RND_B_KAWATA_LIST, GL_R32UI, RND_T_KAWATA_LIST);
    int tw = (bw + 7) / 8, th = (bh + 7) / 8;
    buffer(gl, s, B_TILES, (uint64_t)tw * (uint64_t)th * 4, RND_B_KAWATA_TILES, GL_R32UI,
           RND_T_KAWATA_TILES);
    buffer(gl, s, B_COUNTER, 8, RND_B_KAWATA_COUNT, 0, 0);
    GLintptr row0 = (GLintptr)brect[1] * bw * 4;
    GLsizeiptr rows = (GLsizeiptr)(brect[3] - brect[1]) * bw * 4;
    /* passes 1-2 through the host paths (kawata_cpu.h) or in kawata_raster.comp; with the host
     * paths the list and pass 3's first half too, but for color=field and color=scan (their
     * colour map is the GL's) */
    const rnd_host *h = k->host;
    int host_resolve = h && p->color != SP_COLOR_FIELD && p->color != SP_COLOR_SCAN;
    if (!h) {
        fill(gl, s->buf[B_DEPTH], row0, rows, 0xFFFFFFFFu);
        fill(gl, s->buf[B_NEAR], row0, rows, 0xFFFFFFFFu);
        fill(gl, s->buf[B_FAR], row0, rows, 0);
    }
    fill(gl, s->buf[B_SPLATS], (GLintptr)brect[1] * bw * SPLAT_BYTES,
         (GLsizeiptr)(brect[3] - brect[1]) * bw * SPLAT_BYTES, 0);
    /* the tiles within reach of the rectangle's splats (3 buffer pixels around it) */
    int trect[4] = {(brect[0] - 3 > 0 ? brect[0] - 3 : 0) / 8,
                    (brect[1] - 3 > 0 ? brect[1] - 3 : 0) / 8,
                    (brect[2] + 3 < bw ? brect[2] + 3 : bw - 1) / 8 + 1,
                    (brect[3] + 3 < bh ? brect[3] + 3 : bh - 1) / 8 + 1};
    fill(gl, s->buf[B_TILES], (GLintptr)trect[1] * tw * 4,
         (GLsizeiptr)(trect[3] - trect[1]) * tw * 4, 0);
    fill(gl, s->buf[B_COUNTER], 0, 8, 0);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);

    /* Every program's per-frame uniforms (those a program lacks are -1 and skipped). */
    for (int pr = 0; pr < P_COUNT; pr++) {
        gl->UseProgram(s->prog[pr]);
        const GLint *l = s->loc[pr];
        if (l[U_VIEWPROJ] >= 0) gl->UniformMatrix4fv(l[U_VIEWPROJ], 1, GL_FALSE, v->viewproj);
        if (l[U_VIEW] >= 0) gl->UniformMatrix4fv(l[U_VIEW], 1, GL_FALSE, v->view);
        if (l[U_PROJ] >= 0) gl->UniformMatrix4fv(l[U_PROJ], 1, GL_FALSE, v->proj);
        if (l[U_BSIZE] >= 0) gl->Uniform2i(l[U_BSIZE], bw, bh);
        if (l[U_FSIZE] >= 0) gl->Uniform2i(l[U_FSIZE], v->width, v->height);
        if (l[U_ZNEAR] >= 0) gl->Uniform1f(l[U_ZNEAR], v->znear);
        if (l[U_ZFAR] >= 0) gl->Uniform1f(l[U_ZFAR], v->zfar);
        if (l[U_IBITS] >= 0) gl->Uniform1ui(l[U_IBITS], ibits);
        if (l[U_GAMMA] >= 0) gl->Uniform1f(l[U_GAMMA], gamma);
        if (l[U_QSCALE] >= 0) gl->Uniform1f(l[U_QSCALE], qscale);
        if (l[U_QMAX] >= 0) gl->Uniform1ui(l[U_QMAX], qmax);
        if (l[U_SLOPE] >= 0) gl->Uniform1f(l[U_SLOPE], slope);
        if (l[U_COLOR] >= 0) gl->Uniform1i(l[U_COLOR], p->color);
        if (l[U_LIGHT] >= 0) gl->Uniform3fv(l[U_LIGHT], 1, light);
        if (l[U_SUPPORT] >= 0) gl->Uniform1i(l[U_SUPPORT], KAWATA_MIN_SUPPORT);
        if (l[U_CUTOFF] >= 0) gl->Uniform1f(l[U_CUTOFF], cutoff);
        if (l[U_KERNEL] >= 0) gl->Uniform1f(l[U_KERNEL], 1.0f / (2.0f * ksig * ksig));
        if (l[U_BLO] >= 0) gl->Uniform2i(l[U_BLO], brect[0], brect[1]);
        if (l[U_BHI] >= 0) gl->Uniform2i(l[U_BHI], brect[2], brect[3]);
    }

    /* Passes 1 and 2, through the host paths, or each over every buffer set (one set: its range
     * table is made once, and the set stays bound for pass 3). */
    int rebind = c->nsets > 1;
    uint32_t nranges = 0, first = 0;
    int64_t total = 0;
    uint32_t nlist = 0;
    if (h) {
        kawata_cpu_job job = {.bw = bw, .bh = bh, .znear = v->znear, .zfar = v->zfar,
                              .gamma = gamma, .qscale = qscale, .ibits = ibits, .qmax = qmax,
                              .x0 = brect[0], .x1 = brect[2], .y0 = brect[1], .y1 = brect[3]};
        memcpy(job.viewproj, v->viewproj, sizeof job.viewproj);
        kawata_cpu_resolve_job rj = {.intensity = p->color == SP_COLOR_INTENSITY, .bw = bw,
                                     .x0 = brect[0], .x1 = brect[2], .y0 = brect[1],
                                     .y1 = brect[3], .ibits = ibits};
        memcpy(rj.view, v->view, sizeof rj.view);
        int rc = host_passes(gl, h, s, c, v, &job, host_resolve ? &rj : NULL, p->color, &nlist,
                             err);
        if (rc < 0) return rc;
        if (!rebind && c->nsets) rnd_kit_bind_set(k, &c->sets[0], p->color);
    } else {
        for (int pass = 1; pass <= 2; pass++)
            for (uint32_t set = 0; set < c->nsets; set++) {
                if (pass == 1 || rebind) {
                    total = rnd_kit_set_ranges(k, v, set, &nranges, &first, err);
                    if (total < 0) return (int)total;
                    rnd_kit_bind_set(k, &c->sets[set], p->color);
                }
                if (total > 0) raster_set(gl, s, c, set, (uint32_t)total, nranges, first, pass);
            }
    }

    /* Passes 3-4 run over the list of the covered buffer pixels (those with a nearest point),
     * in the rectangle's row order: each invocation of the list pass takes LIST_PER pixels
     * of it. The list's length stays on the GPU, so passes 3-4 start as many invocations, each
     * taking entries `threads` apart. */
    uint64_t area = (uint64_t)(brect[2] - brect[0]) * (uint64_t)(brect[3] - brect[1]);
    uint64_t lgroups = (area + (uint64_t)GROUP * LIST_PER - 1) / ((uint64_t)GROUP * LIST_PER);
    GLuint lg = lgroups < 1 ? 1 : lgroups > MAX_GROUPS_X ? MAX_GROUPS_X : (GLuint)lgroups;
    uint32_t lper = (uint32_t)((area + (uint64_t)lg * GROUP - 1) / ((uint64_t)lg * GROUP));
    if (!host_resolve) {
        gl->UseProgram(s->prog[P_LIST]);
        gl->Uniform1ui(s->loc[P_LIST][U_PER], lper);
        gl->DispatchCompute(lg, 1, 1);
        gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);

        /* Pass 3, first half: both points of every listed buffer pixel to eye space, in one pass
         * for a cloud in one buffer set; else the rows are cleared to "no point" and each set
         * writes the points it holds. */
        if (rebind)
            fill(gl, s->buf[B_PTS], (GLintptr)brect[1] * bw * PTS_BYTES,
                 (GLsizeiptr)(brect[3] - brect[1]) * bw * PTS_BYTES, 0);
        gl->UseProgram(s->prog[P_RESOLVE]);
        const GLint *lr = s->loc[P_RESOLVE];
        gl->Uniform1i(lr[U_ALL], !rebind);
        for (uint32_t set = 0; set < c->nsets; set++) {
            if (rebind) rnd_kit_bind_set(k, &c->sets[set], p->color);
            gl->Uniform1ui(lr[U_BASE], (GLuint)c->sets[set].base);
            gl->Uniform1ui(lr[U_SETN], c->sets[set].n);
            gl->Uniform1ui(lr[U_THREADS], lg * GROUP);
            gl->DispatchCompute(lg, 1, 1);
            gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
        }
    }
    /* Passes 3 (average) and 4 (plane fit, shading): the splats. */
    gl->UseProgram(s->prog[P_FIT]);
    gl->Uniform1ui(s->loc[P_FIT][U_THREADS], lg * GROUP);
    gl->DispatchCompute(lg, 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT |
                      GL_BUFFER_UPDATE_BARRIER_BIT);
    if (k->kawata_probe) d->out->probe = probe_arrays(gl, s, bw, bh, brect, trect);

    /* Pass 5 into the target over the cloud's screen rectangle, grown by the cut-off. */
    rnd__screen_rect(v, c->bmin, c->bmax, (int)ceilf(cutoff) + 1, rect);
    gl->Disable(GL_DEPTH_TEST);
    gl->Disable(GL_BLEND);
    gl->Enable(GL_SCISSOR_TEST);
    gl->UseProgram(s->prog[P_SPLAT]);
    gl->Uniform2i(s->loc[P_SPLAT][U_T0], trect[0], trect[1]);
    gl->Uniform1i(s->loc[P_SPLAT][U_TCOLS], trect[2] - trect[0]);
    gl->BindFramebuffer(GL_FRAMEBUFFER, d->target->fbo);
    gl->Viewport(0, 0, v->width, v->height);
    gl->Scissor(rect[0], rect[1], rect[2] - rect[0], rect[3] - rect[1]);
    gl->BindVertexArray(s->vao);
    gl->DrawArraysInstanced(GL_TRIANGLES, 0, 6, (trect[2] - trect[0]) * (trect[3] - trect[1]));
    gl->BindVertexArray(0);
    gl->Disable(GL_SCISSOR_TEST);
    /* The splat count; the frame waits for the GPU at its end anyway (render.c's glFinish). */
    GLuint count = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->buf[B_COUNTER]);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, 4, &count);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    d->out->splats = count;
    for (GLuint b = RND_B_KAWATA_DEPTH; b <= RND_B_KAWATA_COUNT; b++)
        gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
    rnd_kit_unbind(k);
    gl->UseProgram(0);
    return GL_CHECK_PASS(gl, "the kawata passes", err);
}

const rnd_pipeline pipe_kawata = {
    .name = "kawata",
    .needs = 1u << RND_ATTR_POS | 1u << RND_ATTR_RGBA | 1u << RND_ATTR_FIELD |
             1u << RND_ATTR_INTENSITY | 1u << RND_ATTR_SCAN,
    .create = kawata_create,
    .destroy = kawata_destroy,
    .render = kawata_render,
};
