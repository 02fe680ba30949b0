/* render.c — the renderer (render.h): the GL back end, the function table, the shaders, the
 * clouds (ids = index + generation) and their residency on the GPU under a byte budget, the
 * output target, and one frame's sequence: view, culling, clear, pipeline, glFinish,
 * read-back. */
#include "render.h"

#include <math.h>
#include <stdio.h>
#include <unistd.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "camera.h"
#include "edl.h"
#include "gl_api.h"
#include "gl_backend.h"
#include "gl_names.h"
#include "lod_render.h"
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
    rnd_gpu_cloud c;          /* bounds and chunks always; sets while resident */
    rnd_lod *lod;             /* a LOD cloud: its node pool; NULL for a flat cloud */
    pc_prepared *src;         /* adopted data, to upload again after an eviction; NULL for a
                                 cloud that stays (rnd_upload) */
    uint64_t bytes;           /* its buffers' size on the GPU */
    uint64_t *set_base;       /* cloud-wide index of each buffer set's first point */
    uint32_t nsets;
    uint64_t last_used;       /* r->clock at its last frame (least recently used goes first) */
    void *pdata[NPIPES];      /* each pipeline's attach data while resident */
    uint8_t attached[NPIPES];
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
    rnd_kit kit;
    int coverage;              /* rnd_set_coverage: 8-bit frames keep coverage in alpha */
    void *pstate[NPIPES];
    int pcreated[NPIPES];
    cloud_slot *slots;
    uint32_t nslots;
    uint32_t max_set_points;
    int lod_uploads;
    uint64_t lod_prefetched;
    uint32_t lod_pool_points;
    uint64_t lod_budget;
    uint64_t budget, resident_bytes, clock, uploads, evictions;
    /* The two targets (pipe.h), each made on first use and remade when the size changes:
     * [TARGET_8] RGBA8 for 8-bit frames, read back as it is; [TARGET_F] RGBA16F + R32F depth
     * for float frames, blitted into [TARGET_8] for their RGBA8 copy (glReadPixels of RGBA16F
     * as unsigned bytes takes Mesa's per-pixel conversion path, ~15 ms at 1280x720).
     * Rendering 8-bit frames straight into RGBA8 saves the float clear and that blit: ~10 ms
     * of a 1280x720 frame on llvmpipe. */
    rnd_target target[2];
    rnd_chunk *visible;       /* one frame's chunks after culling */
    uint64_t visible_cap;
    rnd_edl edl;              /* shading=edl's pass; edl.prog 0 when it did not build */
    sd_err edl_err;           /* why not */
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

/* device_budget: the default cloud budget: 3/4 of the dedicated memory the driver reports
 * (GL_NVX_gpu_memory_info, GL_ATI_meminfo); on a software renderer, whose "GPU memory" is
 * system memory, a quarter of that; else 1 GiB. */
static uint64_t device_budget(rnd_ctx *r)
{
    const gl_api *gl = &r->gl;
    GLint kb[4] = {0, 0, 0, 0};
    if (rnd_kit_has_extension(gl, "GL_NVX_gpu_memory_info")) {
        gl->GetIntegerv(0x9047 /* GPU_MEMORY_INFO_DEDICATED_VIDMEM_NVX */, kb);
        gl->GetError();
        if (kb[0] > 0) return (uint64_t)kb[0] * 1024 / 4 * 3;
    }
    if (rnd_kit_has_extension(gl, "GL_ATI_meminfo")) {
        gl->GetIntegerv(0x87FB /* VBO_FREE_MEMORY_ATI */, kb);
        gl->GetError();
        if (kb[0] > 0) return (uint64_t)kb[0] * 1024 / 4 * 3;
    }
    if (r->kit.software) {
        long pages = sysconf(_SC_PHYS_PAGES), size = sysconf(_SC_PAGESIZE);
        if (pages > 0 && size > 0) return (uint64_t)pages * (uint64_t)size / 4;
    }
    return (uint64_t)1 << 30;
}

rnd_ctx *rnd_create(const rnd_desc *desc, sd_err *err)
{
    rnd_desc d = desc ? *desc : (rnd_desc){0};
    if (!d.max_width) d.max_width = 8192;
    if (!d.max_height) d.max_height = 8192;
    if (d.max_width < 1 || d.max_height < 1 || d.backend < RND_BACKEND_AUTO ||
        d.backend > RND_BACKEND_OSMESA || d.software < RND_CAP_AUTO || d.software > RND_CAP_OFF ||
        d.host_paths < RND_CAP_AUTO || d.host_paths > RND_CAP_OFF) {
        sd_errf(err, SD_EINVAL, "bad renderer description (backend %d, max size %dx%d, "
                "software %d, host paths %d)", (int)d.backend, d.max_width, d.max_height,
                d.software, d.host_paths);
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
    /* the back end's capability, unless the description forces it (pipe.h: the host paths) */
    int software = d.software == RND_CAP_AUTO ? r->ops->software(r->be)
                                              : d.software == RND_CAP_ON;
    int host = d.host_paths == RND_CAP_AUTO ? software : d.host_paths == RND_CAP_ON;
    if ((rc = rnd_kit_init(&r->kit, &r->gl, r->sh, &d.pipe, software, host, err)) < 0) goto fail;
    /* EDL is optional: a driver that cannot build it refuses only frames that ask for it. */
    rnd__edl_init(&r->edl, &r->kit, &r->edl_err);
    r->budget = d.gpu_memory ? d.gpu_memory : device_budget(r);
    uint64_t limit = (uint64_t)r->kit.max_texels / 3; /* positions: 3 R32F texels a point */
    if (limit > INT32_MAX) limit = INT32_MAX;           /* GLint firsts and counts */
    r->max_set_points = d.max_set_points && d.max_set_points < limit ? d.max_set_points
                                                                       : (uint32_t)limit;
    r->lod_uploads = d.lod_uploads > 0 ? d.lod_uploads : 4;
    r->lod_budget = d.lod_budget ? d.lod_budget
                                 : r->kit.software ? RND_LOD_BUDGET_SOFTWARE : RND_LOD_BUDGET_GPU;
    uint64_t pool = d.lod_pool_points ? d.lod_pool_points : 6000000u;
    if (pool > limit) pool = limit;
    if (!d.lod_pool_points && rnd__lod_pool_bytes((uint32_t)pool) > r->budget / 2)
        pool = r->budget / 2 / rnd__lod_pool_bytes(1);
    r->lod_pool_points = pool ? (uint32_t)pool : 1;
    /* Every pipeline is built now, so the first frame does not pay for shader compilation.
     * The baseline must build (broken shaders or a driver without compute shaders show at
     * start-up); another that fails is retried, and its error reported, when a frame asks
     * for it. */
    rc = pipelines[SP_PIPE_POINTS]->create(&r->kit, &r->pstate[SP_PIPE_POINTS], err);
    if (rc < 0) goto fail;
    r->pcreated[SP_PIPE_POINTS] = 1;
    for (int i = 0; i < NPIPES; i++) {
        if (r->pcreated[i]) continue;
        sd_err ignored = {0};
        r->pcreated[i] = pipelines[i]->create(&r->kit, &r->pstate[i], &ignored) == 0;
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

/* detach_all: frees every pipeline's data for the slot's cloud (made again at its next frame). */
static void detach_all(rnd_ctx *r, cloud_slot *slot)
{
    for (int i = 0; i < NPIPES; i++) {
        if (slot->attached[i] && pipelines[i]->detach)
            pipelines[i]->detach(&r->kit, r->pstate[i], slot->pdata[i]);
        slot->pdata[i] = NULL;
        slot->attached[i] = 0;
    }
}

/* evict: takes slot's cloud off the GPU (its pipelines' data first); its bounds, chunks and
 * adopted data stay, so it can come back. */
static void evict(rnd_ctx *r, cloud_slot *slot)
{
    rnd_gpu_cloud *c = &slot->c;
    if (!c->sets) return;
    detach_all(r, slot);
    if (slot->lod) {
        rnd__lod_drop_pool(slot->lod, &r->gl, c);
        r->resident_bytes -= slot->bytes;
        return;
    }
    for (uint32_t s = 0; s < c->nsets; s++) r->gl.DeleteBuffers(RND_ATTR_COUNT, c->sets[s].buf);
    free(c->sets);
    c->sets = NULL;
    c->nsets = 0;
    r->resident_bytes -= slot->bytes;
}

/* slot_clear: evicts and forgets everything of the slot's cloud. */
static void slot_clear(rnd_ctx *r, cloud_slot *slot)
{
    evict(r, slot);
    if (slot->lod) rnd__lod_free(slot->lod, &r->gl, &slot->c);
    free(slot->c.chunks);
    free(slot->set_base);
    if (slot->src) {
        pc_prepared_free(slot->src);
        free(slot->src);
    }
    uint16_t gen = slot->gen;
    memset(slot, 0, sizeof *slot);
    slot->gen = gen;
}

void rnd_destroy(rnd_ctx *r)
{
    if (!r) return;
    if (r->be) {
        r->ops->make_current(r->be, NULL);
        for (uint32_t i = 0; i < r->nslots; i++)
            if (r->slots[i].used) slot_clear(r, &r->slots[i]);
        for (int i = 0; i < NPIPES; i++)
            if (r->pcreated[i]) pipelines[i]->destroy(&r->kit, r->pstate[i]);
        rnd__edl_free(&r->edl, &r->gl);
        rnd_kit_free(&r->kit);
        target_free(&r->gl, &r->target[TARGET_8]);
        target_free(&r->gl, &r->target[TARGET_F]);
        r->ops->destroy(r->be);
    }
    rnd_shaders_destroy(r->sh);
    free(r->slots);
    free(r->visible);
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

int rnd_host_paths(const rnd_ctx *r)
{
    return r && r->kit.host != NULL;
}

const char *rnd_backend_name(const rnd_ctx *r)
{
    return r->ops->name;
}

/* The ranges that normalise a cloud's intensities and scalar property to [0, 1], and the
 * factor of its scan indices (1 / the largest; 0 when it is 0: every point 0). */
typedef struct attr_norm {
    float lo[2], scale[2];     /* [0] intensity, [1] scalar; scale 0: constant, all 1 */
    float scan_scale;
} attr_norm;

/* norm_range: lo and 1 / (hi - lo) of the finite values of v[0..n). */
static void norm_range(const float *v, uint64_t n, float *lo_out, float *scale_out)
{
    float lo = INFINITY, hi = -INFINITY;
    for (uint64_t i = 0; i < n; i++) {
        if (!isfinite(v[i])) continue;
        lo = fminf(lo, v[i]);
        hi = fmaxf(hi, v[i]);
    }
    *lo_out = lo;
    *scale_out = hi > lo ? 1.0f / (hi - lo) : 0.0f;
}

/* upload_converted: fills the bound buffer with attribute a (intensity, scalar: normalised
 * float bits; class: the byte as a word; scan: the index times nm->scan_scale as float bits)
 * of points [base, base + n), in chunks. */
static int upload_converted(const gl_api *gl, int a, const pc_prepared *pc, uint64_t base,
                            uint32_t n, const attr_norm *nm, sd_err *err)
{
    enum { CHUNK = 1 << 16 };
    uint32_t *tmp = malloc(CHUNK * sizeof *tmp);
    if (!tmp) return sd_errf(err, SD_ENOMEM, "out of memory uploading a cloud's %s",
                             rnd_attrs[a].name);
    int w = a == RND_ATTR_SCALAR;
    const float *in = a == RND_ATTR_SCALAR      ? pc->scalar + base
                      : a == RND_ATTR_INTENSITY ? pc->intensity + base
                                                : NULL; /* class, scan: below */
    for (uint64_t i = 0; i < n; i += CHUNK) {
        uint64_t m = n - i < CHUNK ? n - i : CHUNK;
        for (uint64_t j = 0; j < m; j++) {
            if (a == RND_ATTR_SCAN) {
                float f = (float)pc->scan[base + i + j] * nm->scan_scale;
                memcpy(&tmp[j], &f, 4);
                continue;
            }
            if (!in) {
                tmp[j] = pc->cls[base + i + j];
                continue;
            }
            float x = in[i + j];
            float f = isfinite(x) ? (nm->scale[w] > 0 ? (x - nm->lo[w]) * nm->scale[w] : 1.0f)
                                  : 0.0f;
            memcpy(&tmp[j], &f, 4);
        }
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(i * 4), (GLsizeiptr)(m * 4), tmp);
    }
    free(tmp);
    return 0;
}

/* upload_attr: buffer *b for attribute a of points [base, base + n) of pc. Missing colours are
 * white, missing intensities 0; intensities and the scalar are normalised by the cloud's range
 * (nm); a cloud without classes or a scalar gets a one-word buffer for them. */
static int upload_attr(const gl_api *gl, GLuint *b, int a, const pc_prepared *pc, uint64_t base,
                       uint32_t n, const attr_norm *nm, sd_err *err)
{
    uint64_t len = (uint64_t)n * 4 * (uint64_t)rnd_attrs[a].components;
    const void *src = NULL;
    int convert = 0;
    switch (a) {
    case RND_ATTR_POS: src = pc->pos + 3 * base; break;
    case RND_ATTR_NORMAL: src = pc->normal ? pc->normal + 3 * base : NULL; break;
    case RND_ATTR_RADIUS: src = pc->radius ? pc->radius + base : NULL; break;
    case RND_ATTR_FIELD: src = pc->F ? pc->F + base : NULL; break;
    case RND_ATTR_RGBA:
        src = (pc->attrs & PC_ATTR_RGB) && pc->rgba ? pc->rgba + 4 * base : NULL;
        break;
    case RND_ATTR_INTENSITY: convert = (pc->attrs & PC_ATTR_INTENSITY) && pc->intensity; break;
    case RND_ATTR_CLASS:
        convert = (pc->attrs & PC_ATTR_CLASS) && pc->cls;
        if (!convert) len = 4;
        break;
    case RND_ATTR_SCALAR:
        convert = (pc->attrs & PC_ATTR_SCALAR) && pc->scalar;
        if (!convert) len = 4;
        break;
    case RND_ATTR_SCAN:
        convert = (pc->attrs & PC_ATTR_SCAN) && pc->scan;
        if (!convert) len = 4;
        break;
    default: break;
    }
    gl->GenBuffers(1, b);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, *b);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)len, src, GL_STATIC_DRAW);
    if (convert) return upload_converted(gl, a, pc, base, n, nm, err);
    if (!src) {
        const GLuint fill = a == RND_ATTR_RGBA ? 0xFFFFFFFFu : 0;
        gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                            &fill);
    }
    return 0;
}

/* cloud_bytes: the GPU bytes of cloud pc (every attribute, 4 bytes a component; class,
 * scalar and scan only when the cloud has them, upload_attr gives the others one word). */
static uint64_t cloud_bytes(const pc_prepared *pc)
{
    uint64_t per = 0;
    for (int a = 0; a < RND_ATTR_COUNT; a++) {
        if ((a == RND_ATTR_CLASS && !(pc->attrs & PC_ATTR_CLASS)) ||
            (a == RND_ATTR_SCALAR && !(pc->attrs & PC_ATTR_SCALAR)) ||
            (a == RND_ATTR_SCAN && !(pc->attrs & PC_ATTR_SCAN)))
            continue;
        per += 4 * (uint64_t)rnd_attrs[a].components;
    }
    return pc->n * per;
}

/* make_chunks: the slot's chunks from pc's batches (one batch covering everything when it has
 * none), batches over max points cut into pieces, grouped into buffer sets of at most max
 * points (slot->nsets and set_base; the sets themselves are made by make_resident). Returns 0
 * or SD_ENOMEM. */
static int make_chunks(cloud_slot *slot, const pc_prepared *pc, uint32_t max, sd_err *err)
{
    rnd_gpu_cloud *c = &slot->c;
    pc_batch whole = {.first = 0, .count = 0};
    const pc_batch *b = pc->batches;
    uint64_t nb = pc->nbatches;
    if (!nb) {
        memcpy(whole.bmin, c->bmin, sizeof whole.bmin);
        memcpy(whole.bmax, c->bmax, sizeof whole.bmax);
        b = &whole;
        nb = 1;
    }
    uint64_t nc = 0;
    for (uint64_t i = 0; i < nb; i++) {
        uint64_t cnt = nb == 1 && !pc->nbatches ? pc->n : b[i].count;
        nc += cnt ? (cnt + max - 1) / max : 0;
    }
    c->chunks = malloc((nc ? nc : 1) * sizeof *c->chunks);
    slot->set_base = malloc((nc ? nc : 1) * sizeof *slot->set_base); /* nsets <= nc */
    if (!c->chunks || !slot->set_base)
        return sd_errf(err, SD_ENOMEM, "out of memory for %llu chunks", (unsigned long long)nc);
    uint64_t k = 0, set_base = 0;
    uint32_t set = 0;
    for (uint64_t i = 0; i < nb; i++) {
        uint64_t first = b[i].first, cnt = nb == 1 && !pc->nbatches ? pc->n : b[i].count;
        while (cnt) {
            uint32_t piece = cnt < max ? (uint32_t)cnt : max;
            if (k == 0) {
                set_base = first;
                slot->set_base[0] = first;
            } else if (first + piece - set_base > max) { /* the set is full: the next one */
                set++;
                set_base = first;
                slot->set_base[set] = first;
            }
            rnd_chunk *ch = &c->chunks[k++];
            ch->set = set;
            ch->first = (uint32_t)(first - set_base);
            ch->count = piece;
            ch->level = 0;
            memcpy(ch->bmin, b[i].bmin, sizeof ch->bmin);
            memcpy(ch->bmax, b[i].bmax, sizeof ch->bmax);
            first += piece;
            cnt -= piece;
        }
    }
    c->nchunks = k;
    slot->nsets = k ? set + 1 : 0;
    return 0;
}

/* make_room: evicts the least recently rendered evictable clouds other than keep until need
 * more bytes fit the budget. Returns 0, or SD_ELIMIT naming the sizes when they cannot. */
static int make_room(rnd_ctx *r, const cloud_slot *keep, uint64_t need, sd_err *err)
{
    while (r->resident_bytes + need > r->budget) {
        cloud_slot *lru = NULL;
        for (uint32_t i = 0; i < r->nslots; i++) {
            cloud_slot *s = &r->slots[i];
            if (!s->used || s == keep || !s->c.sets || (!s->src && !s->lod)) continue;
            if (!lru || s->last_used < lru->last_used) lru = s;
        }
        if (!lru)
            return sd_errf(err, SD_ELIMIT, "a cloud of %llu MiB does not fit the GPU budget of "
                           "%llu MiB beside the %llu MiB that must stay (--gpu-memory)",
                           (unsigned long long)(need >> 20), (unsigned long long)(r->budget >> 20),
                           (unsigned long long)(r->resident_bytes >> 20));
        evict(r, lru);
        r->evictions++;
    }
    return 0;
}

/* make_resident: uploads slot's cloud from pc (its buffer sets, from its chunks), making room
 * first. Returns 0 or SD_E*. */
static int make_resident(rnd_ctx *r, cloud_slot *slot, const pc_prepared *pc, sd_err *err)
{
    rnd_gpu_cloud *c = &slot->c;
    if (c->sets) return 0;
    int rc = make_room(r, slot, slot->bytes, err);
    if (rc < 0) return rc;
    uint32_t nsets = slot->nsets;
    c->sets = calloc(nsets ? nsets : 1, sizeof *c->sets);
    if (!c->sets) return sd_errf(err, SD_ENOMEM, "out of memory for %u buffer sets", nsets);
    /* a set holds the points from its first chunk's to the end of its last chunk */
    for (uint32_t s = 0; s < nsets; s++) c->sets[s].base = slot->set_base[s];
    for (uint64_t k = 0; k < c->nchunks; k++) {
        rnd_bufset *bs = &c->sets[c->chunks[k].set];
        uint32_t end = c->chunks[k].first + c->chunks[k].count;
        if (end > bs->n) bs->n = end;
    }
    attr_norm nm = {{0, 0}, {0, 0}, 0};
    if ((pc->attrs & PC_ATTR_INTENSITY) && pc->intensity)
        norm_range(pc->intensity, pc->n, &nm.lo[0], &nm.scale[0]);
    if ((pc->attrs & PC_ATTR_SCALAR) && pc->scalar)
        norm_range(pc->scalar, pc->n, &nm.lo[1], &nm.scale[1]);
    if ((pc->attrs & PC_ATTR_SCAN) && pc->scan) {
        uint16_t top = 0;
        for (uint64_t i = 0; i < pc->n; i++) top = pc->scan[i] > top ? pc->scan[i] : top;
        nm.scan_scale = top ? 1.0f / (float)top : 0.0f;
    }
    const gl_api *gl = &r->gl;
    c->nsets = nsets;
    for (uint32_t s = 0; s < nsets && rc == 0; s++)
        for (int a = 0; a < RND_ATTR_COUNT && rc == 0; a++)
            rc = upload_attr(gl, &c->sets[s].buf[a], a, pc, c->sets[s].base, c->sets[s].n, &nm,
                             err);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    if (rc == 0) rc = gl_check(gl, "uploading a cloud", err);
    /* A cache file cut under the daemon read as zeros (the guarded mapping, prepared.h): what
     * was uploaded from it, and the bounds and chunks add_cloud read before, are no cloud. */
    if (rc == 0) rc = pc_prepared_check(pc, err);
    r->resident_bytes += slot->bytes;
    if (rc < 0) {
        evict(r, slot);
        return rc;
    }
    r->uploads++;
    return 0;
}

/* add_cloud: a new slot for pc (checked), with its chunks, resident. src: adopted data (the
 * slot keeps it) or NULL (the cloud stays). Returns the id or SD_E*. */
static int64_t add_cloud(rnd_ctx *r, const pc_prepared *pc, pc_prepared *src, sd_err *err)
{
    if (!pc || !pc->pos || pc->n == 0)
        return sd_errf(err, SD_EEMPTY, "cannot upload a cloud without points");
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
    c->n = pc->n;
    c->attrs = pc->attrs;
    snprintf(c->scalar_name, sizeof c->scalar_name, "%s",
             (pc->attrs & PC_ATTR_SCALAR) ? pc->scalar_name : "");
    for (int i = 0; i < 3; i++) {
        c->offset[i] = pc->offset[i];
        c->bmin[i] = (float)(pc->bmin[i] - pc->offset[i]);
        c->bmax[i] = (float)(pc->bmax[i] - pc->offset[i]);
    }
    c->sigma = pc->sigma;
    c->radius_median = pc->radius_median;
    double sum[3] = {0, 0, 0};
    for (uint64_t i = 0; i < pc->n; i++)
        for (int k = 0; k < 3; k++) sum[k] += pc->pos[3 * i + k];
    for (int k = 0; k < 3; k++) c->centroid[k] = (float)(sum[k] / (double)pc->n);
    slot->bytes = cloud_bytes(pc);
    slot->last_used = ++r->clock;
    int rc = make_chunks(slot, pc, r->max_set_points, err);
    if (rc >= 0) rc = make_resident(r, slot, pc, err);
    if (rc == 0 && c->nchunks > r->visible_cap) {
        rnd_chunk *v = realloc(r->visible, c->nchunks * sizeof *v);
        if (!v) rc = sd_errf(err, SD_ENOMEM, "out of memory for the chunk table");
        else r->visible = v, r->visible_cap = c->nchunks;
    }
    if (rc < 0) {
        slot->src = NULL; /* the caller frees what it passed */
        slot_clear(r, slot);
        return rc;
    }
    slot->src = src;
    if (++slot->gen == 0) slot->gen = 1;
    slot->used = 1;
    return (int64_t)(((uint32_t)slot->gen << ID_INDEX_BITS) | (idx + 1));
}

int64_t rnd_upload(rnd_ctx *r, const pc_prepared *pc, sd_err *err)
{
    if ((int64_t)r->ops->make_current(r->be, err) < 0) return err->code;
    return add_cloud(r, pc, NULL, err);
}

int64_t rnd_adopt(rnd_ctx *r, pc_prepared *pc, sd_err *err)
{
    int64_t id = r->ops->make_current(r->be, err);
    if (id >= 0) id = add_cloud(r, pc, pc, err);
    if (id < 0 && pc) {
        pc_prepared_free(pc);
        free(pc);
    }
    return id;
}

int64_t rnd_adopt_lod(rnd_ctx *r, lod_cloud *lc, sd_err *err)
{
    int64_t rc = r->ops->make_current(r->be, err);
    uint32_t idx = 0;
    cloud_slot *slot = NULL;
    if (rc >= 0 && (!lc || !lc->nnodes)) rc = sd_errf(err, SD_EEMPTY, "a LOD cloud without nodes");
    if (rc >= 0) {
        while (idx < r->nslots && r->slots[idx].used) idx++;
        if (idx == r->nslots) {
            cloud_slot *s = idx < MAX_SLOTS ? realloc(r->slots, (r->nslots + 1) * sizeof *s) : NULL;
            if (!s) rc = sd_errf(err, SD_ELIMIT, "no room for another cloud slot");
            else r->slots = s, memset(&s[idx], 0, sizeof *s), r->nslots++;
        }
    }
    if (rc >= 0) {
        slot = &r->slots[idx];
        slot->lod = rnd__lod_new(lc, r->lod_pool_points, r->lod_uploads, &slot->c, err);
        if (!slot->lod) rc = err->code ? err->code : SD_ENOMEM;
    }
    if (rc < 0) {
        if (slot && slot->lod) {
            rnd__lod_free(slot->lod, &r->gl, &slot->c); /* frees lc */
            slot->lod = NULL;
        } else if (lc) {
            lod_cloud_free(lc);
            free(lc);
        }
        return rc;
    }
    slot->bytes = rnd__lod_pool_bytes(r->lod_pool_points);
    slot->last_used = ++r->clock;
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

int rnd_lod_wait(rnd_ctx *r, uint32_t cloud_id, int timeout_ms)
{
    cloud_slot *s = lookup(r, cloud_id);
    return s && s->lod ? rnd__lod_wait(s->lod, timeout_ms) : 0;
}

/* lod_budget: the point budget of a LOD frame: params' point_budget, else the back end's. */
static uint64_t lod_budget(const rnd_ctx *r, const sp_params *params)
{
    return params->point_budget > 0 ? (uint64_t)params->point_budget : r->lod_budget;
}

/* lod_room: makes room for a LOD cloud's node pool on its first use (frame, settle); the pool
 * itself is made by lod_render.c. */
static int lod_room(rnd_ctx *r, cloud_slot *slot, sd_err *err)
{
    if (slot->c.sets) return 0;
    int rc = make_room(r, slot, slot->bytes, err);
    if (rc < 0) return rc;
    r->resident_bytes += slot->bytes;
    r->uploads++;
    return 0;
}

int rnd_lod_prefetch(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cams, int n,
                     const sp_params *params, sd_err *err)
{
    cloud_slot *s = lookup(r, cloud_id);
    if (!s) return sd_errf(err, SD_EINVAL, "cloud id %u is not (or no longer) loaded", cloud_id);
    if (!s->lod || n <= 0) return 0;
    enum { MAXV = 64 };
    rnd_view v[MAXV];
    if (n > MAXV) n = MAXV;
    for (int j = 0; j < n; j++) {
        const rnd_camera *cam = &cams[j];
        if (cam->width < 1 || cam->height < 1 || cam->width > r->max_width ||
            cam->height > r->max_height)
            return sd_errf(err, SD_ELIMIT, "prefetch camera %d: frame size %dx%d is outside 1x1 "
                           "to %dx%d", j, cam->width, cam->height, r->max_width, r->max_height);
        int rc = rnd__view_setup(cam, s->c.offset, s->c.bmin, s->c.bmax, &v[j], err);
        if (rc < 0) return rc;
    }
    return rnd__lod_prefetch(s->lod, v, n, lod_budget(r, params));
}

int rnd_lod_settle(rnd_ctx *r, uint32_t cloud_id, const rnd_camera *cam,
                   const sp_params *params, int timeout_ms, sd_err *err)
{
    cloud_slot *s = lookup(r, cloud_id);
    if (!s) return sd_errf(err, SD_EINVAL, "cloud id %u is not (or no longer) loaded", cloud_id);
    if (!s->lod) return 1;
    if (cam->width < 1 || cam->height < 1 || cam->width > r->max_width ||
        cam->height > r->max_height)
        return 0; /* rnd_render refuses it with the reason */
    rnd_view v;
    int rc = rnd__view_setup(cam, s->c.offset, s->c.bmin, s->c.bmax, &v, err);
    if (rc < 0) return rc;
    if ((rc = r->ops->make_current(r->be, err)) < 0) return rc;
    if ((rc = lod_room(r, s, err)) < 0) return rc;
    rnd_lod_frame lf;
    rc = rnd__lod_settle(s->lod, &r->gl, &s->c, &v, lod_budget(r, params), timeout_ms, &lf, err);
    if (lf.changed) detach_all(r, s);
    return rc < 0 ? rc : lf.complete;
}

int rnd_lod_idle(rnd_ctx *r, sd_err *err)
{
    int any = 0, current = 0;
    for (uint32_t i = 0; i < r->nslots; i++) {
        cloud_slot *s = &r->slots[i];
        if (!s->used || !s->lod || !s->c.sets) continue;
        if (!current) {
            int rc = r->ops->make_current(r->be, err);
            if (rc < 0) return rc;
            current = 1;
        }
        rnd_lod_frame lf;
        int pending = 0;
        rnd__lod_idle(s->lod, &r->gl, &lf, &pending);
        if (lf.changed) detach_all(r, s); /* per-cloud data follows the pool's contents */
        r->lod_prefetched += lf.uploaded;
        any |= pending;
    }
    if (current) {
        int rc = gl_check(&r->gl, "uploading prefetched LOD nodes", err);
        if (rc < 0) return rc;
    }
    return any;
}

void rnd_release(rnd_ctx *r, uint32_t cloud_id)
{
    cloud_slot *s = lookup(r, cloud_id);
    if (!s) return;
    r->ops->make_current(r->be, NULL);
    slot_clear(r, s);
}

void rnd_get_stats(const rnd_ctx *r, rnd_stats *st)
{
    memset(st, 0, sizeof *st);
    st->budget = r->budget;
    st->resident_bytes = r->resident_bytes;
    st->uploads = r->uploads;
    st->evictions = r->evictions;
    st->lod_prefetched = r->lod_prefetched;
    for (uint32_t i = 0; i < r->nslots; i++) {
        if (!r->slots[i].used) continue;
        st->clouds++;
        st->resident += r->slots[i].c.sets != NULL;
    }
}

int rnd_cloud_resident(const rnd_ctx *r, uint32_t cloud_id)
{
    const cloud_slot *s = lookup((rnd_ctx *)r, cloud_id);
    return s ? s->c.sets != NULL : -1;
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
    /* The 8-bit target has a depth_eye too, for shading=edl: it is a draw buffer only in the
     * frames that use it, so other frames neither clear nor write it. */
    t->depth_eye = make_texture(gl, GL_R32F, w, h);
    gl->GenRenderbuffers(1, &t->depth_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, t->depth_rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
    gl->BindRenderbuffer(GL_RENDERBUFFER, 0);
    gl->GenFramebuffers(1, &t->fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, t->color, 0);
    gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, t->depth_eye,
                             0);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t->depth_rb);
    /* Fragment output 1 (eye depth) goes nowhere in the 8-bit target (but in EDL frames). */
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
    int edl = params->shading == SP_SHADING_EDL;
    if (edl && !r->edl.prog)
        return sd_errf(err, SD_EGL, "shading=edl is not available: %s", r->edl_err.msg);
    const rnd_gpu_cloud *c = &slot->c;
    rnd_view v;
    int rc = rnd__view_setup(cam, c->offset, c->bmin, c->bmax, &v, err);
    if (rc < 0) return rc;
    uint64_t budget = params->point_budget > 0 ? (uint64_t)params->point_budget : 0;
    const gl_api *gl = &r->gl;
    if ((rc = r->ops->make_current(r->be, err)) < 0) return rc;
    if (!r->pcreated[pi]) {
        rc = pipelines[pi]->create(&r->kit, &r->pstate[pi], err);
        if (rc < 0) return rc;
        r->pcreated[pi] = 1;
    }
    slot->last_used = ++r->clock;
    rnd_lod_frame lf = {.complete = 1};
    if (slot->lod) {
        if ((rc = lod_room(r, slot, err)) < 0) return rc;
        rc = rnd__lod_frame(slot->lod, gl, &slot->c, &v, lod_budget(r, params), &lf, err);
        if (rc < 0) return rc;
        if (lf.changed) detach_all(r, slot); /* per-cloud data follows the pool's contents */
        v.nchunks = lf.nchunks;
        v.chunks = lf.chunks;
        v.points_visible = lf.points;
    } else {
        v.nchunks = rnd__cull(&v, c->chunks, c->nchunks, budget, r->visible, &v.points_visible);
        v.chunks = r->visible;
    }
    if (!c->sets && (rc = make_resident(r, slot, slot->src, err)) < 0) return rc;
    if (pipelines[pi]->attach && !slot->attached[pi]) {
        rc = pipelines[pi]->attach(&r->kit, r->pstate[pi], c, &slot->pdata[pi], err);
        if (rc < 0) return rc;
        slot->attached[pi] = 1;
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
     * (pipe.h); the float target, and the 8-bit one under rnd_set_coverage, keep coverage in
     * alpha. */
    int opaque8 = !t->is_float && !r->coverage;
    const float bg[4] = {params->background[0], params->background[1], params->background[2],
                         opaque8 ? 1.0f : 0.0f};
    const float inf[4] = {INFINITY, 0, 0, 0};
    /* The depth renderbuffer is left to the pipelines that test depth (pipe.h). */
    /* EDL reads the eye depth (the 8-bit target then writes it too) over the cloud's screen
     * rectangle only, grown by what pipelines draw around a point (points: point_size / 2;
     * kawata's and splat's minified splats: a few pixels, hence 16) and the radius: nothing
     * else has depth. A magnified splat reaching farther out than that keeps its colour
     * unshaded there (a close-up's box covers the frame anyway). The margin is the pass's
     * cost: on the 1M scan's default view, 64 pixels instead of 16 made it ~30 % slower. The
     * 8-bit target clears its depth in that rectangle only. */
    int edl_rect[4] = {0, 0, 0, 0};
    if (edl) {
        int margin = 16 + (int)ceilf(params->point_size * 0.5f) + (int)ceilf(params->edl_radius);
        rnd__screen_rect(&v, c->bmin, c->bmax, margin, edl_rect);
        if (!t->is_float) {
            const GLenum both[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
            gl->DrawBuffers(2, both);
        }
    }
    gl->ClearBufferfv(GL_COLOR, 0, bg);
    if (t->is_float) {
        gl->ClearBufferfv(GL_COLOR, 1, inf);
    } else if (edl) {
        gl->Enable(GL_SCISSOR_TEST);
        gl->Scissor(edl_rect[0], edl_rect[1], edl_rect[2] - edl_rect[0], edl_rect[3] - edl_rect[1]);
        gl->ClearBufferfv(GL_COLOR, 1, inf);
        gl->Disable(GL_SCISSOR_TEST);
    }
    if (opaque8) gl->ColorMaski(0, GL_TRUE, GL_TRUE, GL_TRUE, GL_FALSE);
    rnd_draw_out out = {0};
    const rnd_draw draw = {.cloud = c, .cloud_data = slot->pdata[pi], .view = &v,
                           .params = params, .target = t, .out = &out,
                           .host_after = opaque8 && !edl};
    rc = pipelines[pi]->render(&r->kit, r->pstate[pi], &draw, err);
    free(frame->kawata_arrays);
    frame->kawata_arrays = out.probe;
    if (rc == 0 && edl)
        rnd__edl_apply(&r->edl, gl, t, edl_rect, params->edl_strength, params->edl_radius);
    if (edl && !t->is_float) {
        const GLenum one[2] = {GL_COLOR_ATTACHMENT0, GL_NONE};
        gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
        gl->DrawBuffers(2, one);
    }
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
    uint64_t t2 = now_us();
    /* the pipeline's host part: rendering too */
    if (out.after && pipelines[pi]->after)
        rc = pipelines[pi]->after(&r->kit, r->pstate[pi], &draw, frame->rgba8, err);
    gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
    if (rc < 0) return rc;
    frame->render_us = t1 - t0 + (now_us() - t2);
    frame->readback_us = t2 - t1;
    frame->points_drawn = v.points_visible;
    frame->splats_drawn = out.splats;
    frame->buffer_w = out.buffer_w;
    frame->flags = out.flags;
    frame->buffer_h = out.buffer_h;
    frame->complete = lf.complete;
    frame->lod_wanted = lf.wanted;
    frame->lod_drawn = lf.drawn;
    frame->lod_uploaded = lf.uploaded;
    return gl_check(gl, "rendering a frame", err);
}

void rnd_set_exchange(rnd_ctx *r, const rnd_exchange *x)
{
    r->kit.exchange = x;
}

void rnd_set_coverage(rnd_ctx *r, int on)
{
    r->coverage = on != 0;
}

void rnd_set_kawata_probe(rnd_ctx *r, int on)
{
    r->kit.kawata_probe = on != 0;
}

void rnd_release_targets(rnd_ctx *r)
{
    target_free(&r->gl, &r->target[TARGET_8]);
    target_free(&r->gl, &r->target[TARGET_F]);
    for (int i = 0; i < SP_PIPE_COUNT; i++)
        if (r->pcreated[i] && pipelines[i]->trim) pipelines[i]->trim(&r->kit, r->pstate[i]);
    r->gl.Finish();
}

void rnd_frame_free(rnd_frame *f)
{
    if (!f) return;
    free(f->kawata_arrays);
    free(f->rgba8);
    free(f->rgba16f);
    free(f->depth);
    memset(f, 0, sizeof *f);
}
