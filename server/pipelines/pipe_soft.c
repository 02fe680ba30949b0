/* pipe_soft.c — the `soft` pipeline: Soft Transparency (Seemann et al.), the Express-Model.
 *
 * The solid/soft split. Each point has a scalar F in [0, 1] from the source `field`
 * (soft_field.h; the normalisation of each source is in params.h). Points with F <= t are
 * solid and are drawn by the `splat` pipeline's own passes (splat_passes.h), F > t are soft.
 * Three forms of the split, measured:
 *   list    (a cloud in one buffer set, the usual case, with soft and solid points) the solid
 *           points listed in point order (made with the soft arrays below, uploaded as an
 *           R32UI buffer texture), the view's chunks cut to the list's entries in them (a
 *           binary search per chunk), and splat__create_filtered's programs in mode
 *           SPLAT_SOLID_LIST read each point through the list: the passes cost what the solid
 *           points cost. On Guanyin at t = 0.5 (81k solid of 238k) the solid passes took
 *           24.6 ms of CPU a frame against 39.9 with the filter.
 *   filter  (one set, all solid or all soft) the same programs skip soft points at the start
 *           of both passes (one texel fetch a point); scattered soft points leave SIMD lanes
 *           idle among solid ones, so the cost stays near splat's.
 *   runs    (several buffer sets, whose field buffers the splat passes do not rebind) a view
 *           whose chunks are the runs of solid points within the frame's visible chunks,
 *           through the unchanged programs; the runs are made on the CPU when the cloud
 *           attaches and when `field` or `t` change. Scattered soft points make many runs and
 *           lib_ranges' binary search pays for them: 42 ms CPU a frame on the 1M cloud at
 *           t = 0.9 (15k soft points), which is why one set takes the filter.
 * Both give t = 1 the splat image exactly (test_t1_equals_splat, test_buffer_sets).
 *
 * The soft points (Express-Model, eq. 19). Each is a view-facing disc of the splat radius times
 * splat_scale, drawn as one GL point sprite (soft.vert/.frag) whose fragments get the opacity
 * Phi = lambda (cos(pi d / r) + 1) / 2 at distance d from the centre, its colour Lambert-shaded
 * from the point's normal as splat's resolve does (lib_shade.glsl; the paper shades all points),
 * composited with the premultiplied "over" (ONE, ONE_MINUS_SRC_ALPHA) after the splat resolve of
 * each stripe,
 * tested against the solid surface's depth (splat__keys_texture) and writing no depth.
 *
 * Order: the paper's pre-sorted index arrays. At attach, the points of every buffer set are
 * sorted along x, y and z (a stable radix sort of the coordinates' order-preserving bits) on the
 * CPU; when `field` or `t` changes, the soft points are listed in point order (number j) and,
 * per axis, their j in the order along that axis, and uploaded as one R32UI buffer texture of
 * four arrays. The projection (soft_bin.comp PASS 0) runs in point order, reading and writing
 * sequentially; the sprites and the binning follow the axis order through the index. Projecting
 * in the axis order instead (random reads, or random writes) cost ~65 ms more CPU on a Guanyin
 * frame (157k soft points). Per frame the axis closest to
 * the view direction picks the array, read forwards or backwards, so that the first disc is the
 * farthest. Three arrays read both ways are the paper's six (half its memory). The order is
 * exact for discs separated along the chosen axis and the paper's approximation otherwise; a
 * cloud in several buffer sets draws its sets by their centres along the axis, each sorted
 * within. Three ways to composite in that order (parameter `order`):
 *   axis  one GL point sprite per soft disc (soft.vert/.frag): GL blends in primitive order, so
 *         the "over" runs back to front with no per-frame sort or list.
 *   tile  a compute compositor (soft_bin.comp, soft_scan.comp, soft_blend.comp,
 *         soft_resolve.frag): the ordered soft points are cut into 64 consecutive blocks whose
 *         invocations walk them serially, count and then scatter each disc into the 8x8 pixel
 *         tiles it touches (per (tile, block) cells in tile-major order, so each tile's list
 *         stays in back-to-front order without a sort); one work group per tile blends its list
 *         per pixel in float, and one blend puts the result over the target. Same order, one
 *         rounding to 8 bits instead of one per disc (test_tile_matches_axis).
 *   auto  (the default) axis, or where the renderer has host paths (pipe.h rnd_host: a software
 *         renderer, whose GL is the CPU) the host compositor (soft_host.c, soft_cpu.h):
 *         soft_bin.comp PASS 0's projection read back, each stripe's visibility keys read back,
 *         the discs binned into 64x64 tiles in draw order and blended in float by every core
 *         over only the pixels they cover, the rows they reached uploaded as the layer
 *         soft_resolve puts over the target; clouds of more than 64 buffer sets take the
 *         sprites. The host paths project the discs too (soft_proj.h: no dispatch, no
 *         read-back), but for color=field. On an opaque 8-bit frame with nothing after the pipeline in the GL
 *         (rnd_draw.host_after: no Eye-Dome Lighting) there is no layer: the stripes' keys are
 *         kept and, after the read-back, soft__after blends each tile's discs into a float tile
 *         of its thread's and puts it over the frame's pixels (rnd_pipeline.after); the binning
 *         (soft_cpu_bin) then runs on a thread of its own while the GL makes the keys, where
 *         llvmpipe leaves a core partly idle.
 * What each costs on llvmpipe, and why the host compositor is the default there:
 * docs/performance.md ("soft", "Host paths").
 *
 * Transparency modulation (eq. 22). For t < F < l_m the opacity is interpolated between the
 * model's Phi and a near-solid disc, with W = (F - t) / (l_m - t): Phi_f = (1 - d/r)(1 - W) +
 * Phi W. The paper writes the first term lambda (1 - d); read literally its mean over a disc
 * (lambda / 3) is below the cosine's (0.30 lambda), so it would not make the points "rendered
 * with higher density when close to the threshold" as the paper's text and figure 5 say. We
 * leave lambda out: at the threshold a soft disc is as dense as a solid splat at its centre,
 * and the colour step between solid and soft regions shrinks (test_modulation measures it).
 * l_m <= t turns the modulation off.
 *
 * model=base and model=concentric replace the soft discs by spheres composited through per-pixel
 * fragment lists (soft_lists.h), per stripe after the splat resolve, clipped by the same
 * visibility keys; clouds in one buffer set only, and l_m does not apply to them. F comes from
 * soft_field.h for every `field` source.
 *
 * What is not here: soft discs larger than the GL's point size limit (llvmpipe: 255 pixels) are
 * drawn at that size by order=axis. Culling: soft points are drawn whether or not their chunk
 * was culled (the GL clips them); the point budget applies to solid points only. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "shaders.h"
#include "soft_pipe.h"
#include "splat_passes.h"

enum {
    SOFT_TILE = 8,             /* tile side in pixels: one 8x8 work group of soft_blend */
    SOFT_BLOCKS = 64,          /* binning blocks: invocations walking the order serially */
};


static void soft_destroy(rnd_kit *k, void *state)
{
    soft_state *s = state;
    if (!s) return;
    soft__bin_join(s);
    const gl_api *gl = k->gl;
    if (s->splat) splat__destroy(k, s->splat);
    soft_lists_destroy(k, &s->lists);
    if (s->prog) gl->DeleteProgram(s->prog);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    if (s->f_tex) gl->DeleteTextures(1, &s->f_tex);
    if (s->idx_tex) gl->DeleteTextures(1, &s->idx_tex);
    if (s->solid_tex) gl->DeleteTextures(1, &s->solid_tex);
    for (int i = 0; i < C_COUNT; i++)
        if (s->cprog[i]) gl->DeleteProgram(s->cprog[i]);
    GLuint bufs[4] = {s->proj_buf, s->cells_buf, s->list_buf, s->layer_buf};
    GLuint texs[4] = {s->proj_tex, s->cells_tex, s->list_tex, s->layer_tex};
    for (int i = 0; i < 4; i++) {
        if (bufs[i]) gl->DeleteBuffers(1, &bufs[i]);
        if (texs[i]) gl->DeleteTextures(1, &texs[i]);
    }
    free(s->chunks);
    free(s->h_proj), free(s->h_layer), free(s->h_keys), free(s->h_fkeys);
    soft_cpu_mem_free(&s->mem);
    memset(s, 0, sizeof *s);
    free(s);
}

static int soft_create(rnd_kit *k, void **state, sd_err *err)
{
    *state = NULL;
    const gl_api *gl = k->gl;
    soft_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory creating the soft pipeline");
    long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    s->threads = ncpu < 1 ? 1 : ncpu > 16 ? 16 : (int)ncpu;
    s->host = k->host;
    int rc = splat__create_filtered(k, &s->splat, err);
    if (rc < 0) {
        soft_destroy(k, s);
        return rc;
    }
    static const char *const files[2] = {"soft.vert", "soft.frag"};
    s->prog = rnd_kit_program(k, files, 2, "", err);
    if (!s->prog) {
        soft_destroy(k, s);
        return err ? err->code : SD_EGL;
    }
    static const char *const unames[SU_COUNT] = {
#define SOFT_U_NAME_(id, name) name,
        SOFT_UNIFORMS(SOFT_U_NAME_)
#undef SOFT_U_NAME_
    };
    for (int u = 0; u < SU_COUNT; u++) s->loc[u] = gl_uniform(gl, s->prog, unames[u]);
    static const struct {
        const char *files[2];
        int n;
        const char *defs;
    } cp[C_COUNT] = {
        [C_PROJ] = {{"soft_bin.comp"}, 1, "#define PASS 0\n"},
        [C_BIN1] = {{"soft_bin.comp"}, 1, "#define PASS 1\n"},
        [C_BIN3] = {{"soft_bin.comp"}, 1, "#define PASS 3\n"},
        [C_SCAN] = {{"soft_scan.comp"}, 1, ""},
        [C_BLEND] = {{"soft_blend.comp"}, 1, ""},
        [C_RESOLVE] = {{"soft_resolve.vert", "soft_resolve.frag"}, 2, ""},
    };
    for (int i = 0; i < C_COUNT; i++) {
        s->cprog[i] = rnd_kit_program(k, cp[i].files, cp[i].n, cp[i].defs, err);
        if (!s->cprog[i]) {
            soft_destroy(k, s);
            return err ? err->code : SD_EGL;
        }
    }
    if ((rc = soft_lists_create(k, &s->lists, err)) < 0) {
        soft_destroy(k, s);
        return rc;
    }
    GLuint *texs[4] = {&s->proj_tex, &s->cells_tex, &s->list_tex, &s->layer_tex};
    for (int i = 0; i < 4; i++) gl->GenTextures(1, texs[i]);

    gl->GenVertexArrays(1, &s->vao);
    gl->GenTextures(1, &s->f_tex);
    gl->GenTextures(1, &s->idx_tex);
    gl->GenTextures(1, &s->solid_tex);
    GLfloat range[2] = {1.0f, 1.0f};
    gl->GetFloatv(GL_POINT_SIZE_RANGE, range);
    s->max_point = range[1] >= 1.0f ? range[1] : 1.0f;
    rc = gl_check(gl, "creating the soft pipeline", err);
    if (rc < 0) {
        soft_destroy(k, s);
        return rc;
    }
    *state = s;
    return 0;
}

/* ---- per-cloud data ------------------------------------------------------------------------ */

static void soft_detach(rnd_kit *k, void *state, void *cloud_data)
{
    (void)state;
    soft_cloud *sc = cloud_data;
    if (!sc) return;
    for (uint32_t i = 0; i < sc->nsets; i++) {
        soft_set *ss = &sc->sets[i];
        free(ss->runs);
        for (int a = 0; a < 3; a++) free(ss->sorted[a]);
        free(ss->idx);
        free(ss->solid);
        if (ss->idx_buf) k->gl->DeleteBuffers(1, &ss->idx_buf);
        if (ss->solid_buf) k->gl->DeleteBuffers(1, &ss->solid_buf);
    }
    free(sc->sets);
    soft_fields_free(k->gl, &sc->fields);
    free(sc);
}

/* Order-preserving bits of a float: unsigned comparison of the results orders the floats. */
static uint32_t float_key(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    return (u & 0x80000000u) ? ~u : u | 0x80000000u;
}

/* sort_axis: out = 0..n-1 ordered by key (a stable LSD radix sort, 4 passes of 8 bits; ties keep
 * point order). tmp_k, tmp_i are scratch of n entries. */
static void sort_axis(const uint32_t *key, uint32_t n, uint32_t *out, uint32_t *kbuf,
                      uint32_t *tmp_k, uint32_t *tmp_i)
{
    for (uint32_t i = 0; i < n; i++) out[i] = i, kbuf[i] = key[i];
    for (int shift = 0; shift < 32; shift += 8) {
        uint32_t count[257] = {0};
        for (uint32_t i = 0; i < n; i++) count[((kbuf[i] >> shift) & 255u) + 1]++;
        for (int b = 0; b < 256; b++) count[b + 1] += count[b];
        for (uint32_t i = 0; i < n; i++) {
            uint32_t b = (kbuf[i] >> shift) & 255u, at = count[b]++;
            tmp_k[at] = kbuf[i], tmp_i[at] = out[i];
        }
        memcpy(kbuf, tmp_k, (size_t)n * 4);
        memcpy(out, tmp_i, (size_t)n * 4);
    }
}

/* attach: reads back each set's positions, F and intensity once, and sorts its points along the
 * three axes. The split itself waits for the first frame (it depends on field and t). */
static int soft_attach(rnd_kit *k, void *state, const rnd_gpu_cloud *c, void **cloud_data,
                       sd_err *err)
{
    (void)state;
    const gl_api *gl = k->gl;
    *cloud_data = NULL;
    soft_cloud *sc = calloc(1, sizeof *sc);
    if (!sc) return sd_errf(err, SD_ENOMEM, "out of memory attaching a cloud to soft");
    sc->sets = calloc(c->nsets ? c->nsets : 1, sizeof *sc->sets);
    if (!sc->sets) {
        free(sc);
        return sd_errf(err, SD_ENOMEM, "out of memory attaching a cloud to soft");
    }
    sc->nsets = c->nsets;
    int frc = soft_fields_attach(gl, c, &sc->fields, err);
    if (frc < 0) {
        free(sc->sets), free(sc);
        return frc;
    }
    for (uint32_t si = 0; si < c->nsets; si++) {
        const rnd_bufset *b = &c->sets[si];
        soft_set *ss = &sc->sets[si];
        uint32_t n = b->n;
        ss->n = n;
        const float *pos = sc->fields.sets[si].pos;
        uint32_t *keys = malloc((size_t)(n ? n : 1) * 4 * 4);
        for (int a = 0; a < 3; a++) ss->sorted[a] = malloc((size_t)(n ? n : 1) * 4);
        int ok = keys && ss->sorted[0] &&
                 ss->sorted[1] && ss->sorted[2];
        if (ok) {
            float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            for (int a = 0; a < 3; a++) {
                for (uint32_t i = 0; i < n; i++) {
                    float v = pos[3 * (size_t)i + a];
                    keys[i] = float_key(v);
                    lo[a] = fminf(lo[a], v), hi[a] = fmaxf(hi[a], v);
                }
                sort_axis(keys, n, ss->sorted[a], keys + n, keys + 2 * (size_t)n,
                          keys + 3 * (size_t)n);
                ss->centre[a] = n ? 0.5f * (lo[a] + hi[a]) : 0.0f;
            }
        }
        free(keys);
        if (!ok) {
            soft_detach(k, state, sc);
            return sd_errf(err, SD_ENOMEM, "out of memory sorting a cloud's points for soft");
        }
    }
    int rc = gl_check(gl, "attaching a cloud to soft", err);
    if (rc < 0) {
        soft_detach(k, state, sc);
        return rc;
    }
    *cloud_data = sc;
    return 0;
}

/* make_split: the solid runs and the uploaded soft index arrays of every set for the fields'
 * current F and t. Returns 0 or SD_ENOMEM. */
static int make_split(const gl_api *gl, soft_cloud *sc, float t, sd_err *err)
{
    for (uint32_t si = 0; si < sc->nsets; si++) {
        soft_set *ss = &sc->sets[si];
        uint32_t n = ss->n;
        uint8_t *soft = malloc(n ? n : 1);
        if (!soft) return sd_errf(err, SD_ENOMEM, "out of memory splitting a cloud");
        uint32_t nsoft = 0, nruns = 0;
        for (uint32_t i = 0; i < n; i++) {
            soft[i] = sc->fields.sets[si].f[i] > t;
            nsoft += soft[i];
            nruns += !soft[i] && (i == 0 || soft[i - 1]);
        }
        free(ss->runs);
        ss->runs = malloc((size_t)(nruns ? nruns : 1) * 8);
        uint32_t *idx = malloc((size_t)(nsoft ? nsoft : 1) * 4 * 4);
        uint32_t *at = malloc((size_t)(n ? n : 1) * 4);
        if (!ss->runs || !idx || !at) {
            free(soft), free(idx), free(at);
            ss->nruns = 0;
            return sd_errf(err, SD_ENOMEM, "out of memory splitting a cloud");
        }
        uint32_t r = 0;
        for (uint32_t i = 0; i < n; i++) {
            if (soft[i]) continue;
            if (i == 0 || soft[i - 1]) ss->runs[2 * r] = i, ss->runs[2 * r + 1] = 0, r++;
            ss->runs[2 * (r - 1) + 1]++;
        }
        ss->nruns = nruns;
        /* [0, nsoft): the soft points in point order (j -> point); then per axis a, at
         * (1 + a) nsoft + k, the j of the k-th soft point along a (see the file comment) */
        uint32_t m = 0;
        for (uint32_t i = 0; i < n; i++)
            if (soft[i]) at[i] = m, idx[m++] = i;
        for (int a = 0; a < 3; a++) {
            uint32_t *o = idx + (size_t)(1 + a) * nsoft;
            for (uint32_t j = 0; j < n; j++)
                if (soft[ss->sorted[a][j]]) *o++ = at[ss->sorted[a][j]];
        }
        ss->nsoft = nsoft;
        /* one set: the solid points listed for the splat passes (SPLAT_SOLID_LIST) */
        free(ss->solid);
        ss->solid = NULL;
        if (sc->nsets == 1 && nsoft > 0 && nsoft < n) {
            if (!(ss->solid = malloc((size_t)(n - nsoft) * 4))) {
                free(soft), free(idx), free(at);
                return sd_errf(err, SD_ENOMEM, "out of memory splitting a cloud");
            }
            for (uint32_t i = 0, q = 0; i < n; i++)
                if (!soft[i]) ss->solid[q++] = i;
            if (!ss->solid_buf) gl->GenBuffers(1, &ss->solid_buf);
            gl->BindBuffer(GL_TEXTURE_BUFFER, ss->solid_buf);
            gl->BufferData(GL_TEXTURE_BUFFER, (GLsizeiptr)(n - nsoft) * 4, ss->solid,
                           GL_STATIC_DRAW);
        }
        if (!ss->idx_buf) gl->GenBuffers(1, &ss->idx_buf);
        gl->BindBuffer(GL_TEXTURE_BUFFER, ss->idx_buf);
        gl->BufferData(GL_TEXTURE_BUFFER, (GLsizeiptr)((nsoft ? nsoft : 1) * 4ull * 4), idx,
                       GL_STATIC_DRAW);
        gl->BindBuffer(GL_TEXTURE_BUFFER, 0);
        free(ss->idx);
        ss->idx = idx;
        free(at);
        free(soft);
    }
    sc->have_split = 1, sc->t = t;
    return 0;
}

/* solid_view: *out = v with its chunks cut to the solid runs (set by set, point order kept).
 * Returns 0 or SD_ENOMEM. */
static int solid_view(soft_state *s, const rnd_view *v, const soft_cloud *sc, rnd_view *out,
                      sd_err *err)
{
    *out = *v;
    uint64_t n = 0, visible = 0;
    uint32_t ci = 0;
    while (ci < v->nchunks) {
        uint32_t set = v->chunks[ci].set;
        const soft_set *ss = &sc->sets[set];
        uint32_t r = 0;
        for (; ci < v->nchunks && v->chunks[ci].set == set; ci++) {
            const rnd_chunk *ch = &v->chunks[ci];
            uint64_t a = ch->first, b = (uint64_t)ch->first + ch->count;
            while (r < ss->nruns && (uint64_t)ss->runs[2 * r] + ss->runs[2 * r + 1] <= a) r++;
            for (uint32_t q = r; q < ss->nruns && ss->runs[2 * q] < b; q++) {
                uint64_t lo = ss->runs[2 * q] > a ? ss->runs[2 * q] : a;
                uint64_t hi = (uint64_t)ss->runs[2 * q] + ss->runs[2 * q + 1];
                if (hi > b) hi = b;
                if (hi <= lo) continue;
                if (n == s->chunks_cap) {
                    uint64_t cap = s->chunks_cap ? 2 * s->chunks_cap : 256;
                    rnd_chunk *nc = realloc(s->chunks, cap * sizeof *nc);
                    if (!nc) return sd_errf(err, SD_ENOMEM, "out of memory splitting a frame");
                    s->chunks = nc, s->chunks_cap = cap;
                }
                rnd_chunk *o = &s->chunks[n++];
                *o = *ch;
                o->first = (uint32_t)lo, o->count = (uint32_t)(hi - lo);
                visible += hi - lo;
            }
        }
    }
    out->chunks = s->chunks;
    out->nchunks = (uint32_t)n;
    out->points_visible = visible;
    return 0;
}

/* lower_bound: the first j in [0, n) with a[j] >= x (n if none); a ascending. */
static uint32_t lower_bound(const uint32_t *a, uint32_t n, uint32_t x)
{
    uint32_t lo = 0, hi = n;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (a[mid] < x) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* solid_list_view: a cloud in one set with a solid list (ss->solid): *out = v with each chunk's
 * points replaced by the entries of the list that fall in it (SPLAT_SOLID_LIST), chunks with
 * none dropped. Returns 0 or SD_ENOMEM. */
static int solid_list_view(soft_state *s, const rnd_view *v, const soft_set *ss, rnd_view *out,
                           sd_err *err)
{
    *out = *v;
    if (v->nchunks > s->chunks_cap) {
        rnd_chunk *nc = realloc(s->chunks, (size_t)v->nchunks * sizeof *nc);
        if (!nc) return sd_errf(err, SD_ENOMEM, "out of memory splitting a frame");
        s->chunks = nc, s->chunks_cap = v->nchunks;
    }
    uint32_t nsolid = ss->n - ss->nsoft, n = 0;
    uint64_t visible = 0;
    for (uint32_t ci = 0; ci < v->nchunks; ci++) {
        const rnd_chunk *ch = &v->chunks[ci];
        uint32_t lo = lower_bound(ss->solid, nsolid, ch->first);
        uint32_t hi = lower_bound(ss->solid, nsolid, ch->first + ch->count);
        if (hi <= lo) continue;
        rnd_chunk *o = &s->chunks[n++];
        *o = *ch;
        o->first = lo, o->count = hi - lo;
        visible += hi - lo;
    }
    out->chunks = s->chunks;
    out->nchunks = n;
    out->points_visible = visible;
    return 0;
}

/* ---- the frame ------------------------------------------------------------------------------- */


/* order_sets: the axis closest to the view direction and the sets back to front along it. */
static void order_sets(const rnd_view *v, const soft_cloud *sc, soft_order *o)
{
    /* The camera's forward direction in local coordinates is minus the view matrix's third
     * row (column-major: elements 2, 6, 10). */
    float fwd[3] = {-v->view[2], -v->view[6], -v->view[10]};
    int axis = 0;
    for (int a = 1; a < 3; a++)
        if (fabsf(fwd[a]) > fabsf(fwd[axis])) axis = a;
    o->axis = axis;
    /* Looking along +axis, the far points have the largest coordinate: read the ascending
     * array backwards. */
    o->rev = fwd[axis] > 0.0f;
    uint32_t n = sc->nsets < 64 ? sc->nsets : 64;
    for (uint32_t i = 0; i < n; i++) o->set_order[i] = i;
    for (uint32_t i = 1; i < n; i++) /* insertion sort: a handful of sets */
        for (uint32_t j = i; j > 0; j--) {
            float a = sc->sets[o->set_order[j - 1]].centre[axis];
            float b = sc->sets[o->set_order[j]].centre[axis];
            int swap = o->rev ? a < b : a > b;
            if (!swap) break;
            uint32_t tmp = o->set_order[j];
            o->set_order[j] = o->set_order[j - 1], o->set_order[j - 1] = tmp;
        }
}


/* soft__buf_tex: makes *buf hold at least bytes and *tex a buffer texture of format fmt over it. */
void soft__buf_tex(const gl_api *gl, GLuint *buf, uint64_t *have, uint64_t bytes, GLuint tex,
                    GLenum fmt)
{
    if (rnd_kit_ensure_ssbo(gl, buf, have, bytes) || bytes == 0) {
        gl->BindTexture(GL_TEXTURE_BUFFER, tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, fmt, *buf);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
    }
}

/* set_view_uniforms: the uniforms soft.vert and soft_bin.comp share, in program prog. */
static void set_view_uniforms(const gl_api *gl, GLuint prog, const rnd_draw *d, const soft_order *o,
                              uint32_t nsoft)
{
    const rnd_view *v = d->view;
    const sp_params *p = d->params;
    gl->UseProgram(prog);
    GLint l;
    if ((l = gl_uniform(gl, prog, "u_view")) >= 0) gl->UniformMatrix4fv(l, 1, GL_FALSE, v->view);
    if ((l = gl_uniform(gl, prog, "u_proj")) >= 0) gl->UniformMatrix4fv(l, 1, GL_FALSE, v->proj);
    if ((l = gl_uniform(gl, prog, "u_size")) >= 0) gl->Uniform2i(l, v->width, v->height);
    if ((l = gl_uniform(gl, prog, "u_scale")) >= 0) gl->Uniform1f(l, p->splat_scale);
    if ((l = gl_uniform(gl, prog, "u_color")) >= 0) gl->Uniform1i(l, p->color);
    if ((l = gl_uniform(gl, prog, "u_znear")) >= 0) gl->Uniform1f(l, v->znear);
    if ((l = gl_uniform(gl, prog, "u_zfar")) >= 0) gl->Uniform1f(l, v->zfar);
    if ((l = gl_uniform(gl, prog, "u_t")) >= 0) gl->Uniform1f(l, p->t);
    if ((l = gl_uniform(gl, prog, "u_light")) >= 0) {
        float light[3];
        soft_light(p, light);
        gl->Uniform3fv(l, 1, light);
    }
    if ((l = gl_uniform(gl, prog, "u_lm")) >= 0) gl->Uniform1f(l, p->l_m);
    if ((l = gl_uniform(gl, prog, "u_rev")) >= 0) gl->Uniform1i(l, o->rev);
    if ((l = gl_uniform(gl, prog, "u_base")) >= 0)
        gl->Uniform1ui(l, (GLuint)((uint64_t)(1 + o->axis) * nsoft));
    if ((l = gl_uniform(gl, prog, "u_n")) >= 0) gl->Uniform1ui(l, nsoft);
    if ((l = gl_uniform(gl, prog, "u_nblocks")) >= 0) gl->Uniform1ui(l, SOFT_BLOCKS);
    if ((l = gl_uniform(gl, prog, "u_tile")) >= 0) gl->Uniform1i(l, SOFT_TILE);
    int ntx = (v->width + SOFT_TILE - 1) / SOFT_TILE, nty = (v->height + SOFT_TILE - 1) / SOFT_TILE;
    if ((l = gl_uniform(gl, prog, "u_ntx")) >= 0) gl->Uniform1i(l, ntx);
    if ((l = gl_uniform(gl, prog, "u_nty")) >= 0) gl->Uniform1i(l, nty);
}

/* bind_soft_set: set 0's buffers, its field source and its soft index arrays. */
static void bind_soft_set(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                          uint32_t si)
{
    const gl_api *gl = k->gl;
    const sp_params *p = d->params;
    rnd_kit_bind_set(k, &d->cloud->sets[si], p->color);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_F);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->f_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, sc->fields.sets[si].f_buf);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_IDX);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->idx_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, sc->sets[si].idx_buf);
    gl->ActiveTexture(GL_TEXTURE0);
}

/* soft__project_set: soft_bin.comp PASS 0 over set si's soft discs in back-to-front order into the
 * proj buffer (2 texels a disc). Returns 0 or SD_ELIMIT. */
int soft__project_set(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                       const soft_order *o, uint32_t si, sd_err *err)
{
    const gl_api *gl = k->gl;
    uint32_t nsoft = sc->sets[si].nsoft;
    if ((uint64_t)nsoft * 32 > (uint64_t)k->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "soft: %u soft points in one buffer set exceed a storage "
                       "block", nsoft);
    soft__buf_tex(gl, &s->proj_buf, &s->proj_bytes, (uint64_t)(nsoft ? nsoft : 1) * 32, s->proj_tex,
            GL_RGBA32F);
    bind_soft_set(k, s, d, sc, si);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_PROJ, s->proj_buf);
    set_view_uniforms(gl, s->cprog[C_PROJ], d, o, nsoft);
    uint64_t groups = ((uint64_t)nsoft + 31) / 32;
    gl->DispatchCompute((GLuint)(groups > 4096 ? 4096 : groups ? groups : 1), 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
    return 0;
}

/* draw_soft: order=axis, the soft discs of every set over rows [y0, y0 + n) as point sprites
 * in primitive order (keys: whether the splat passes left visibility keys for these rows, with
 * halo row start yb and nb rows). Returns 0 or SD_E*. */
static int draw_soft(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                     const soft_order *o, int keys, int y0, int n, int yb, int nb, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    uint32_t nsets = sc->nsets < 64 ? sc->nsets : 64;
    for (uint32_t oi = 0; oi < sc->nsets; oi++) {
        uint32_t si = oi < nsets ? o->set_order[oi] : oi;
        uint32_t nsoft = sc->sets[si].nsoft;
        if (nsoft == 0) continue;
        int rc = soft__project_set(k, s, d, sc, o, si, err);
        if (rc < 0) return rc;
        const GLint *l = s->loc;
        gl->UseProgram(s->prog);
        gl->Uniform2i(l[SU_SIZE], v->width, v->height);
        if (l[SU_MAXSIZE] >= 0) gl->Uniform1f(l[SU_MAXSIZE], s->max_point);
        if (l[SU_STRIPE] >= 0) gl->Uniform2i(l[SU_STRIPE], yb, nb);
        if (l[SU_KEYS_ON] >= 0) gl->Uniform1i(l[SU_KEYS_ON], keys);
        if (l[SU_LAMBDA] >= 0) gl->Uniform1f(l[SU_LAMBDA], d->params->lambda);
        gl->Uniform1ui(l[SU_BASE], (GLuint)((uint64_t)(1 + o->axis) * nsoft));
        gl->Uniform1ui(l[SU_N], nsoft);
        gl->Uniform1i(l[SU_REV], o->rev);
        gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_PROJ);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->proj_tex);
        gl->ActiveTexture(GL_TEXTURE0 + RND_T_SPLAT_KEYS);
        gl->BindTexture(GL_TEXTURE_BUFFER, splat__keys_texture(s->splat));
        gl->ActiveTexture(GL_TEXTURE0);
        gl->BindFramebuffer(GL_FRAMEBUFFER, d->target->fbo);
        gl->Viewport(0, 0, v->width, v->height);
        gl->Enable(GL_SCISSOR_TEST);
        gl->Scissor(0, y0, v->width, n);
        gl->Disable(GL_DEPTH_TEST);
        gl->Enable(GL_BLEND);
        gl->BlendFuncSeparate(GL_ONE, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
        gl->ColorMaski(1, GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE); /* no depth writes */
        gl->Enable(GL_PROGRAM_POINT_SIZE);
        gl->BindVertexArray(s->vao);
        gl->DrawArrays(GL_POINTS, 0, (GLsizei)nsoft);
        gl->BindVertexArray(0);
        gl->Disable(GL_PROGRAM_POINT_SIZE);
        gl->ColorMaski(1, GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
        gl->Disable(GL_BLEND);
        gl->Disable(GL_SCISSOR_TEST);
        gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
    }
    return 0;
}

/* tile_bin: the compositor's binning of a one-set cloud's soft points for this frame
 * (soft_bin.comp PASS 1, soft_scan.comp, the list's size read back, PASS 3). Returns 0 or
 * SD_E*. */
static int tile_bin(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                    const soft_order *o, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    uint32_t nsoft = sc->sets[0].nsoft;
    int ntx = (v->width + SOFT_TILE - 1) / SOFT_TILE, nty = (v->height + SOFT_TILE - 1) / SOFT_TILE;
    uint64_t ncells = (uint64_t)ntx * nty * SOFT_BLOCKS;
    if ((ncells + 1) * 4 > (uint64_t)k->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "soft: %u soft points in a %dx%d frame exceed the "
                       "compositor's storage blocks", nsoft, v->width, v->height);
    int rc = soft__project_set(k, s, d, sc, o, 0, err);
    if (rc < 0) return rc;
    soft__buf_tex(gl, &s->cells_buf, &s->cells_bytes, (ncells + 1) * 4, s->cells_tex, GL_R32UI);
    GLuint zero = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->cells_buf);
    gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
    soft__buf_tex(gl, &s->list_buf, &s->list_bytes, 4, s->list_tex, GL_R32UI);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_CELLS, s->cells_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_LIST, s->list_buf);
    const GLuint groups = SOFT_BLOCKS / 32;
    set_view_uniforms(gl, s->cprog[C_BIN1], d, o, nsoft);
    gl->DispatchCompute(groups, 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    gl->UseProgram(s->cprog[C_SCAN]);
    gl->Uniform1ui(gl_uniform(gl, s->cprog[C_SCAN], "u_ncells"), (GLuint)ncells);
    gl->DispatchCompute(1, 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    GLuint total = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->cells_buf);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(ncells * 4), 4, &total);
    if ((uint64_t)total * 4 > (uint64_t)k->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "soft: %u tile entries exceed the compositor's storage "
                       "block", total);
    soft__buf_tex(gl, &s->list_buf, &s->list_bytes, (uint64_t)(total ? total : 1) * 4, s->list_tex,
            GL_R32UI);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_LIST, s->list_buf);
    set_view_uniforms(gl, s->cprog[C_BIN3], d, o, nsoft);
    gl->DispatchCompute(groups, 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
    return 0;
}

/* soft__resolve_layer: soft_resolve puts the layer (rows [y0, y0 + n) of the frame) over the
 * target. */
void soft__resolve_layer(rnd_kit *k, soft_state *s, const rnd_draw *d, int y0, int n)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_LAYER);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->layer_tex);
    gl->ActiveTexture(GL_TEXTURE0);
    GLuint pr = s->cprog[C_RESOLVE];
    gl->UseProgram(pr);
    gl->Uniform2i(gl_uniform(gl, pr, "u_size"), v->width, v->height);
    gl->Uniform2i(gl_uniform(gl, pr, "u_rows"), y0, n);
    rnd_kit_over_rows(k, s->vao, d->target, v->width, v->height, y0, n);
}

/* tile_blend: the compositor over rows [y0, y0 + n): soft_blend.comp into the layer, then
 * soft_resolve puts the layer over the target. keys, yb, nb as draw_soft. */
static void tile_blend(rnd_kit *k, soft_state *s, const rnd_draw *d, int keys, int y0, int n,
                       int yb, int nb)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    int ntx = (v->width + SOFT_TILE - 1) / SOFT_TILE;
    soft__buf_tex(gl, &s->layer_buf, &s->layer_bytes, (uint64_t)v->width * n * 16, s->layer_tex,
            GL_RGBA32F);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_LAYER, s->layer_buf);
    const GLuint units[4] = {RND_T_SOFT_PROJ, RND_T_SOFT_LIST, RND_T_SOFT_CELLS, RND_T_SPLAT_KEYS};
    const GLuint texs[4] = {s->proj_tex, s->list_tex, s->cells_tex, splat__keys_texture(s->splat)};
    for (int i = 0; i < 4; i++) {
        gl->ActiveTexture(GL_TEXTURE0 + units[i]);
        gl->BindTexture(GL_TEXTURE_BUFFER, texs[i]);
    }
    gl->ActiveTexture(GL_TEXTURE0);
    GLuint pb = s->cprog[C_BLEND];
    gl->UseProgram(pb);
    gl->Uniform2i(gl_uniform(gl, pb, "u_size"), v->width, v->height);
    gl->Uniform2i(gl_uniform(gl, pb, "u_stripe"), yb, nb);
    gl->Uniform2i(gl_uniform(gl, pb, "u_rows"), y0, n);
    gl->Uniform1i(gl_uniform(gl, pb, "u_keys_on"), keys);
    gl->Uniform1f(gl_uniform(gl, pb, "u_lambda"), d->params->lambda);
    gl->Uniform1ui(gl_uniform(gl, pb, "u_nblocks"), SOFT_BLOCKS);
    gl->Uniform1i(gl_uniform(gl, pb, "u_ntx"), ntx);
    int ty0 = y0 / SOFT_TILE, ty1 = (y0 + n - 1) / SOFT_TILE;
    gl->Uniform1i(gl_uniform(gl, pb, "u_ty0"), ty0);
    gl->DispatchCompute((GLuint)ntx, (GLuint)(ty1 - ty0 + 1), 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
    soft__resolve_layer(k, s, d, y0, n);
}

/* render: the split (remade when field or t changed), the splat passes over the solid runs,
 * and per stripe the soft discs back to front over the resolved solid surface. */
static int soft_render(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    soft_state *s = state;
    soft_cloud *sc = d->cloud_data;
    const sp_params *p = d->params;
    soft__bin_join(s); /* a frame whose soft__after never came (the renderer failed after us) */
    if (!sc) return sd_errf(err, SD_EINVAL, "soft: the cloud was not attached");
    int lists = p->model != SP_MODEL_EXPRESS, concentric = p->model == SP_MODEL_CONCENTRIC;
    if (lists && sc->nsets != 1)
        return sd_errf(err, SD_ELIMIT, "soft: model=%s takes a cloud in one buffer set (this one "
                       "has %u)", concentric ? "concentric" : "base", sc->nsets);
    int rc = 0;
    int changed = soft_fields_update(k->gl, d->cloud, &sc->fields, p, err);
    if (changed < 0) return changed;
    if (changed || !sc->have_split || sc->t != p->t)
        if ((rc = make_split(k->gl, sc, p->t, err)) < 0) return rc;
    /* The split (see the file comment): one buffer set, the splat programs' filter; several,
     * the solid runs. */
    int one = sc->nsets == 1;
    int list = one && sc->sets[0].solid; /* some points soft and some solid */
    rnd_view sv = *d->view;
    if (!one && (rc = solid_view(s, d->view, sc, &sv, err)) < 0) return rc;
    if (list && (rc = solid_list_view(s, d->view, &sc->sets[0], &sv, err)) < 0) return rc;
    rnd_draw sd = *d;
    sd.view = &sv;
    soft_order o;
    order_sets(d->view, sc, &o);
    int draw = p->lambda > 0.0f || (!lists && p->l_m > p->t);
    /* order=tile: the compositor, for one buffer set (the usual case); several take the
     * sprites. */
    int want_tile = p->order == SP_ORDER_TILE;
    int tile = !lists && draw && want_tile && sc->nsets == 1 && sc->sets[0].nsoft > 0;
    if (tile && (rc = tile_bin(k, s, d, sc, &o, err)) < 0) return rc;
    /* order=auto with the host paths: the host compositor (soft_cpu.h), for clouds of up to 64
     * sets (more take the sprites) */
    int cpu = !lists && draw && !tile && sc->nsets <= 64 && p->order == SP_ORDER_AUTO && k->host;
    if (cpu && (rc = soft__cpu_project(k, s, d, sc, &o, err)) < 0) return rc;
    /* on an 8-bit frame with no GL pass after ours, the discs go over the read-back pixels
     * (soft__after) */
    int after = cpu && d->host_after && s->nsegs > 0;
    if (after) { /* binned while the GL makes the keys; soft__after blends */
        s->bin_job = (soft_cpu_job){.segs = s->segs, .nsegs = s->nsegs,
                                    .width = d->view->width, .y0 = 0, .rows = d->view->height,
                                    .mem = &s->mem, .threads = s->threads};
        soft__bin_start(s);
    }

    splat_frame f;
    int nstripes = splat__frame_begin(k, s->splat, &sd, &f, err);
    rc = nstripes < 0 ? nstripes : 0;
    if (nstripes > 0) {
        splat__set_filter(k, s->splat, list ? SPLAT_SOLID_LIST : SPLAT_SKIP_SOFT,
                          one ? p->t : 2.0f);
        if (list) {
            k->gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_SOLID);
            k->gl->BindTexture(GL_TEXTURE_BUFFER, s->solid_tex);
            k->gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, sc->sets[0].solid_buf);
            k->gl->ActiveTexture(GL_TEXTURE0);
        }
        if (one) {
            k->gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_F);
            k->gl->BindTexture(GL_TEXTURE_BUFFER, s->f_tex);
            k->gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, sc->fields.sets[0].f_buf);
            k->gl->ActiveTexture(GL_TEXTURE0);
        }
    }
    for (int i = 0; i < nstripes && rc == 0; i++) {
        splat__stripe_begin(k, s->splat, &f, i);
        if ((rc = splat__visibility(k, s->splat, &f, err)) == 0 &&
            (rc = splat__attributes(k, s->splat, &f, err)) == 0) {
            splat__resolve(k, s->splat, &f);
            int height = d->view->height;
            int yb = f.y0 > 0 ? f.y0 - 1 : 0; /* the keys' first row (splat's halo) */
            int nb = (f.y0 + f.n < height ? f.y0 + f.n + 1 : f.y0 + f.n) - yb;
            if (lists && draw) {
                bind_soft_set(k, s, d, sc, 0);
                rc = soft_lists_draw(k, &s->lists, d, sc->sets[0].nsoft, concentric, 1, f.y0, f.n,
                                     yb, nb, err);
            } else if (tile) {
                tile_blend(k, s, d, 1, f.y0, f.n, yb, nb);
            } else if (after) {
                rc = soft__keep_keys(k, s, d, f.y0, f.n, yb, err);
            } else if (cpu) {
                rc = soft__cpu_blend(k, s, d, 1, f.y0, f.n, yb, nb, err);
            } else if (draw) {
                rc = draw_soft(k, s, d, sc, &o, 1, f.y0, f.n, yb, nb, err);
            }
            /* draw_soft bound its sets' buffers; splat binds one set once per frame, so give
             * it back (several sets are rebound by the splat passes themselves). */
            if (f.one_set) rnd_kit_bind_set(k, &d->cloud->sets[0], p->color);
        }
    }
    int whole_fits = (uint64_t)d->view->width * d->view->height * 16 <= (uint64_t)k->max_ssbo;
    if (nstripes == 0 && lists && draw) {
        bind_soft_set(k, s, d, sc, 0);
        rc = soft_lists_draw(k, &s->lists, d, sc->sets[0].nsoft, concentric, 0, 0,
                             d->view->height, 0, d->view->height, err);
    } else if (nstripes == 0 && tile && whole_fits)
        tile_blend(k, s, d, 0, 0, d->view->height, 0, d->view->height);
    else if (nstripes == 0 && cpu && !after)
        rc = soft__cpu_blend(k, s, d, 0, 0, d->view->height, 0, d->view->height, err);
    else if (nstripes == 0 && draw)
        rc = draw_soft(k, s, d, sc, &o, 0, 0, d->view->height, 0, d->view->height, err);
    int end = splat__frame_end(k, s->splat, err);
    if (rc == 0 && end == 0 && after) {
        d->out->after = 1;
        s->after_keys = nstripes > 0;
    } else {
        soft__bin_join(s); /* no soft__after for this frame */
    }
    return rc < 0 ? rc : end;
}

const rnd_pipeline pipe_soft = {
    .name = "soft",
    .needs = 1u << RND_ATTR_POS | 1u << RND_ATTR_NORMAL | 1u << RND_ATTR_RADIUS |
             1u << RND_ATTR_RGBA | 1u << RND_ATTR_FIELD | 1u << RND_ATTR_INTENSITY |
             1u << RND_ATTR_SCAN | 1u << RND_ATTR_CLASS | 1u << RND_ATTR_SCALAR,
    .create = soft_create,
    .destroy = soft_destroy,
    .attach = soft_attach,
    .detach = soft_detach,
    .render = soft_render,
    .after = soft__after,
};
