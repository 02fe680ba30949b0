/* soft_lists.c — see soft_lists.h. */
#include "soft_lists.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "shaders.h"
#include "splat_math.h"

enum { L_COUNT = 0, L_STORE, L_SCAN, L_RESOLVE, L_NPROG };
enum { FRAG_BYTES = 16 };

void soft_light(const sp_params *p, float light[3])
{
    float ll = sqrtf(p->light[0] * p->light[0] + p->light[1] * p->light[1] +
                     p->light[2] * p->light[2]);
    for (int i = 0; i < 3; i++) light[i] = ll > 0.0f ? p->light[i] / ll : (i == 2 ? 1.0f : 0.0f);
}

void soft_lists_kappa(float k[65])
{
    enum { RINGS = 1000 };
    k[0] = 0.0f;
    for (int n = 1; n <= 64; n++) {
        double mass = 0.0;
        for (int q = 0; q < RINGS; q++) {
            double d = (q + 0.5) / RINGS, tau = 0.0;
            for (int i = 0; i < n; i++) {
                double ri = 1.0 - (double)i / n, rn = 1.0 - (double)(i + 1) / n;
                if (d >= ri) break;
                double ch = 2.0 * sqrt(ri * ri - d * d);
                double chn = i + 1 < n && d < rn ? 2.0 * sqrt(rn * rn - d * d) : 0.0;
                tau += 1.0 / (n * ri) * (1.0 - d / ri) * (ch - chn);
            }
            mass += tau * d / RINGS;
        }
        k[n] = (float)((1.0 / 6.0) / mass);
    }
}

int soft_lists_create(rnd_kit *k, soft_lists *s, sd_err *err)
{
    memset(s, 0, sizeof *s);
    soft_lists_kappa(s->kappa);
    static const struct {
        const char *files[2];
        int n;
        const char *defs;
    } cp[L_NPROG] = {
        [L_COUNT] = {{"soft_frag.comp"}, 1, "#define PASS 1\n"},
        [L_STORE] = {{"soft_frag.comp"}, 1, "#define PASS 2\n"},
        [L_SCAN] = {{"soft_scan.comp"}, 1, ""},
        [L_RESOLVE] = {{"soft_resolve.vert", "soft_resolve.frag"}, 2, ""},
    };
    for (int i = 0; i < L_NPROG; i++)
        if (!(s->prog[i] = rnd_kit_program(k, cp[i].files, cp[i].n, cp[i].defs, err))) {
            soft_lists_destroy(k, s);
            return err ? err->code : SD_EGL;
        }
    static const char *const bf[1] = {"soft_fblend.comp"};
    for (int c = 0; c < 2; c++)
        if (!(s->blend[c] = rnd_kit_program(k, bf, 1, c ? "#define CONCENTRIC 1\n"
                                                         : "#define CONCENTRIC 0\n", err))) {
            soft_lists_destroy(k, s);
            return err ? err->code : SD_EGL;
        }
    k->gl->GenVertexArrays(1, &s->vao);
    k->gl->GenTextures(1, &s->layer_tex);
    return 0;
}

void soft_lists_destroy(rnd_kit *k, soft_lists *s)
{
    const gl_api *gl = k->gl;
    for (int i = 0; i < L_NPROG; i++)
        if (s->prog[i]) gl->DeleteProgram(s->prog[i]);
    for (int i = 0; i < 2; i++)
        if (s->blend[i]) gl->DeleteProgram(s->blend[i]);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    if (s->layer_tex) gl->DeleteTextures(1, &s->layer_tex);
    GLuint bufs[4] = {s->counts_buf, s->fill_buf, s->frags_buf, s->layer_buf};
    for (int i = 0; i < 4; i++)
        if (bufs[i]) gl->DeleteBuffers(1, &bufs[i]);
    free(s->offs);
    memset(s, 0, sizeof *s);
}

static void zero(const gl_api *gl, GLuint buf)
{
    const GLuint z = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, buf);
    gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &z);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
}

static GLint U(const gl_api *gl, GLuint prog, const char *name)
{
    return gl_uniform(gl, prog, name);
}

/* frag_uniforms: what soft_frag.comp's two passes share. */
static void frag_uniforms(const gl_api *gl, GLuint prog, const rnd_draw *d, uint32_t nsoft,
                          int concentric, int keys, int y0, int yb, int nb, const float *kappa,
                          uint64_t npx)
{
    const rnd_view *v = d->view;
    float rayo[4], rayd[4];
    splat_ray_coeffs(v->proj, v->width, v->height, rayo, rayd);
    gl->UseProgram(prog);
    gl->UniformMatrix4fv(U(gl, prog, "u_view"), 1, GL_FALSE, v->view);
    gl->UniformMatrix4fv(U(gl, prog, "u_proj"), 1, GL_FALSE, v->proj);
    gl->Uniform4fv(U(gl, prog, "u_rayo"), 1, rayo);
    gl->Uniform4fv(U(gl, prog, "u_rayd"), 1, rayd);
    gl->Uniform2i(U(gl, prog, "u_size"), v->width, v->height);
    gl->Uniform2i(U(gl, prog, "u_stripe"), yb, nb);
    gl->Uniform1i(U(gl, prog, "u_keys_on"), keys);
    gl->Uniform1f(U(gl, prog, "u_scale"), d->params->splat_scale);
    gl->Uniform1f(U(gl, prog, "u_znear"), v->znear);
    gl->Uniform1ui(U(gl, prog, "u_n"), nsoft);
    gl->Uniform1i(U(gl, prog, "u_concentric"), concentric);
    gl->Uniform1i(U(gl, prog, "u_row0"), y0);
    GLint lk = U(gl, prog, "u_kappa");
    if (lk >= 0) gl->Uniform1fv(lk, 65, kappa);
    /* samples a pixel may count: the stripe's total stays under 2^31 */
    uint64_t pxcap = ((uint64_t)1 << 31) / (npx ? npx : 1);
    gl->Uniform1ui(U(gl, prog, "u_pxcap"), (GLuint)(pxcap > 0xFFFF0000u ? 0xFFFF0000u : pxcap));
    gl->Uniform1ui(U(gl, prog, "u_npx"), (GLuint)npx);
}

static GLuint point_groups(uint32_t nsoft)
{
    uint64_t g = ((uint64_t)nsoft + 63) / 64;
    return (GLuint)(g > 4096 ? 4096 : g ? g : 1);
}

/* band: store, sort/blend and composite rows [ya, ya + m) whose samples start at offset base
 * and number `count` (the cap already applied by the caller's choice of cap). */
static int band(rnd_kit *k, soft_lists *s, const rnd_draw *d, uint32_t nsoft, int concentric,
                int keys, int y0, int ya, int m, int yb, int nb, uint64_t base, uint64_t cap,
                uint64_t count, uint64_t npx, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    uint64_t fbytes = (count < cap ? count : cap) * FRAG_BYTES;
    rnd_kit_ensure_ssbo(gl, &s->frags_buf, &s->frags_bytes, fbytes ? fbytes : FRAG_BYTES);
    if (rnd_kit_ensure_ssbo(gl, &s->layer_buf, &s->layer_bytes, (uint64_t)v->width * m * 16)) {
        gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_LAYER);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->layer_tex);
        gl->TexBuffer(GL_TEXTURE_BUFFER, GL_RGBA32F, s->layer_buf);
        gl->ActiveTexture(GL_TEXTURE0);
    }
    /* the per-pixel cursors (the word after them, the lost-sphere count, is kept) */
    const GLuint z = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->fill_buf);
    gl->ClearBufferSubData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, 0, (GLsizeiptr)(npx * 4),
                           GL_RED_INTEGER, GL_UNSIGNED_INT, &z);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_FRAGS, s->frags_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_LAYER, s->layer_buf);
    GLuint ps = s->prog[L_STORE];
    frag_uniforms(gl, ps, d, nsoft, concentric, keys, y0, yb, nb, s->kappa, npx);
    gl->Uniform2i(U(gl, ps, "u_rows"), ya, m);
    gl->Uniform1ui(U(gl, ps, "u_base"), (GLuint)base);
    gl->Uniform1ui(U(gl, ps, "u_cap"), (GLuint)cap);
    gl->DispatchCompute(point_groups(nsoft), 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);

    GLuint pb = s->blend[concentric ? 1 : 0];
    gl->UseProgram(pb);
    const sp_params *p = d->params;
    float unit = d->cloud->radius_median > 0.0f ? d->cloud->radius_median : 1.0f;
    unit *= p->splat_scale;
    gl->Uniform2i(U(gl, pb, "u_size"), v->width, v->height);
    gl->Uniform2i(U(gl, pb, "u_rows"), ya, m);
    gl->Uniform1i(U(gl, pb, "u_row0"), y0);
    gl->Uniform1ui(U(gl, pb, "u_base"), (GLuint)base);
    gl->Uniform1ui(U(gl, pb, "u_cap"), (GLuint)cap);
    gl->Uniform1ui(U(gl, pb, "u_npx"), (GLuint)npx);
    gl->Uniform1f(U(gl, pb, "u_k"), p->lambda / (unit * unit));
    gl->Uniform1f(U(gl, pb, "u_scale"), p->splat_scale);
    gl->Uniform1i(U(gl, pb, "u_color"), p->color);
    float light[3];
    soft_light(p, light);
    gl->Uniform3fv(U(gl, pb, "u_light"), 1, light);
    gl->UniformMatrix4fv(U(gl, pb, "u_view"), 1, GL_FALSE, v->view);
    gl->UniformMatrix4fv(U(gl, pb, "u_proj"), 1, GL_FALSE, v->proj);
    gl->DispatchCompute((GLuint)((v->width + 7) / 8), (GLuint)((m + 7) / 8), 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);

    GLuint pr = s->prog[L_RESOLVE];
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_LAYER);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->layer_tex);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->UseProgram(pr);
    gl->Uniform2i(U(gl, pr, "u_size"), v->width, v->height);
    gl->Uniform2i(U(gl, pr, "u_rows"), ya, m);
    rnd_kit_over_rows(k, s->vao, d->target, v->width, v->height, ya, m);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
    (void)err;
    return 0;
}

/* lost_spheres: flags the frame when the Base-Model's blend left spheres out (the fill buffer's
 * word past the npx pixels). Returns 0. */
static int lost_spheres(const gl_api *gl, const soft_lists *s, const rnd_draw *d, uint64_t npx)
{
    GLuint lost = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->fill_buf);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(npx * 4), 4, &lost);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    if (lost) d->out->flags |= RND_FRAME_SOFT_TRUNCATED;
    return 0;
}

int soft_lists_draw(rnd_kit *k, soft_lists *s, const rnd_draw *d, uint32_t nsoft, int concentric,
                    int keys, int y0, int n, int yb, int nb, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    uint64_t npx = (uint64_t)v->width * (uint64_t)n;
    if (nsoft == 0 || n <= 0) return 0;
    if ((npx + 1) * 4 > (uint64_t)k->max_ssbo || (uint64_t)v->width * 16 > (uint64_t)k->max_ssbo)
        return sd_errf(err, SD_ELIMIT, "soft: a %dx%d stripe's fragment counts exceed a storage "
                       "block", v->width, n);
    /* the cap in samples: soft_frag_mib, at most one storage block */
    uint64_t cap_bytes = (uint64_t)d->params->soft_frag_mib << 20;
    if (cap_bytes > (uint64_t)k->max_ssbo) cap_bytes = (uint64_t)k->max_ssbo;
    uint64_t cap = cap_bytes / FRAG_BYTES;
    if (cap > 0xFFFFFFF0u) cap = 0xFFFFFFF0u;
    /* the layer: rows of a band, at most one storage block */
    uint64_t max_band = (uint64_t)k->max_ssbo / ((uint64_t)v->width * 16);

    rnd_kit_ensure_ssbo(gl, &s->counts_buf, &s->counts_bytes, (npx + 1) * 4);
    rnd_kit_ensure_ssbo(gl, &s->fill_buf, &s->fill_bytes, (npx + 1) * 4);
    zero(gl, s->counts_buf);
    zero(gl, s->fill_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_CELLS, s->counts_buf);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, RND_B_SOFT_FILL, s->fill_buf);

    /* 1: counts */
    GLuint pc = s->prog[L_COUNT];
    frag_uniforms(gl, pc, d, nsoft, concentric, keys, y0, yb, nb, s->kappa, npx);
    gl->Uniform2i(U(gl, pc, "u_rows"), y0, n);
    gl->DispatchCompute(point_groups(nsoft), 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    /* 2: prefix sum (the fill buffer's size is the counts' size: its last word, past the
     * pixels, counts the Base-Model's left-out spheres) */
    gl->UseProgram(s->prog[L_SCAN]);
    gl->Uniform1ui(U(gl, s->prog[L_SCAN], "u_ncells"), (GLuint)npx);
    gl->DispatchCompute(1, 1, 1);
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    GLuint total = 0;
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->counts_buf);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)(npx * 4), 4, &total);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    s->samples += total;
    int rc = 0;
    if (total <= cap && (uint64_t)n <= max_band) {
        rc = band(k, s, d, nsoft, concentric, keys, y0, y0, n, yb, nb, 0, cap, total, npx, err);
        return rc < 0 ? rc : lost_spheres(gl, s, d, npx);
    }
    /* 3: bands of rows that fit (see soft_lists.h) */
    if (s->offs_cap < npx + 1) {
        uint32_t *o = realloc(s->offs, (size_t)(npx + 1) * 4);
        if (!o) return sd_errf(err, SD_ENOMEM, "out of memory for the soft fragment offsets");
        s->offs = o, s->offs_cap = npx + 1;
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->counts_buf);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)((npx + 1) * 4), s->offs);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    int W = v->width;
    for (int ya = 0; ya < n && rc == 0;) {
        uint64_t base = s->offs[(uint64_t)ya * W];
        int m = 1;
        while (ya + m < n && (uint64_t)m < max_band &&
               s->offs[(uint64_t)(ya + m + 1) * W] - base <= cap)
            m++;
        uint64_t count = s->offs[(uint64_t)(ya + m) * W] - base;
        if (count > cap) d->out->flags |= RND_FRAME_SOFT_TRUNCATED;
        rc = band(k, s, d, nsoft, concentric, keys, y0, y0 + ya, m, yb, nb, base, cap, count, npx,
                  err);
        ya += m;
    }
    return rc < 0 ? rc : lost_spheres(gl, s, d, npx);
}
