/* pipe_olt.c — the `olt` pipeline: One-Layer Transparency, the comparison of the Soft
 * Transparency paper (Seemann et al., sec. 5.3 and Table 1): the first layer of soft points
 * (F > t, F from soft_field.h) drawn transparent with opacity lambda, everything behind it
 * opaque.
 *
 * Per stripe of rows, through splat's passes (splat_passes.h) with the filtered programs:
 *   1. the soft points alone (SPLAT_SKIP_SOLID): visibility, attributes and resolve into an
 *      RGBA8 layer texture of the frame's size; the stripe's visibility keys (the nearest soft
 *      depth per pixel) are copied aside (RND_T_OLT_KEYS);
 *   2. every point except the soft ones of that first layer (SPLAT_PEEL: a soft point whose
 *      centre depth lies within splat's pass-2 depth tolerance of the layer's key at its centre
 *      pixel belongs to the layer, the same rule by which splat blends splats into one
 *      surface), resolved opaque into the target;
 *   3. olt_compose.frag puts the layer over that with opacity lambda where the layer is in
 *      front of the target's nearest surface (a solid point in front of it hides it).
 * So a pixel shows lambda * layer + (1 - lambda) * (the opaque surface behind the layer).
 * The membership test is per point (its centre pixel), not per fragment: a big soft splat that
 * straddles a depth edge of the layer is either all layer or all behind. A cloud in several
 * buffer sets (a LOD cloud's node pool, a large cloud) gets each set's field buffer bound as
 * splat's passes make the set current (splat__set_set_hook). Costs about two splat
 * frames plus a full-frame blend; `make bench` measures it. */
#include <stdlib.h>
#include <string.h>

#include "pipe.h"
#include "shaders.h"
#include "soft_field.h"
#include "splat_passes.h"

typedef struct olt_state {
    void *splat;               /* splat__create_filtered */
    GLuint compose, vao;
    GLuint f_tex, lkeys_tex, lkeys_buf;
    uint64_t lkeys_bytes;
    rnd_target layer;          /* fbo + RGBA8 colour texture of the frame's size */
    const gl_api *gl;          /* for bind_field, during a frame */
    const soft_fields *fs;     /*   the frame's cloud's field buffers */
} olt_state;

/* bind_field: splat's passes made buffer set `set` current: its field buffer on RND_T_SOFT_F. */
static void bind_field(void *user, uint32_t set)
{
    olt_state *s = user;
    const gl_api *gl = s->gl;
    if (!s->fs || set >= s->fs->nsets) return;
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SOFT_F);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->f_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, s->fs->sets[set].f_buf);
    gl->ActiveTexture(GL_TEXTURE0);
}

static void olt_destroy(rnd_kit *k, void *state)
{
    olt_state *s = state;
    if (!s) return;
    const gl_api *gl = k->gl;
    if (s->splat) splat__destroy(k, s->splat);
    if (s->compose) gl->DeleteProgram(s->compose);
    if (s->vao) gl->DeleteVertexArrays(1, &s->vao);
    GLuint texs[3] = {s->f_tex, s->lkeys_tex, s->layer.color};
    for (int i = 0; i < 3; i++)
        if (texs[i]) gl->DeleteTextures(1, &texs[i]);
    if (s->lkeys_buf) gl->DeleteBuffers(1, &s->lkeys_buf);
    if (s->layer.fbo) gl->DeleteFramebuffers(1, &s->layer.fbo);
    free(s);
}

static int olt_create(rnd_kit *k, void **state, sd_err *err)
{
    *state = NULL;
    const gl_api *gl = k->gl;
    olt_state *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory creating the olt pipeline");
    int rc = splat__create_filtered(k, &s->splat, err);
    if (rc < 0) {
        olt_destroy(k, s);
        return rc;
    }
    static const char *const files[2] = {"soft_resolve.vert", "olt_compose.frag"};
    s->compose = rnd_kit_program(k, files, 2, "", err);
    if (!s->compose) {
        olt_destroy(k, s);
        return err ? err->code : SD_EGL;
    }
    gl->GenVertexArrays(1, &s->vao);
    gl->GenTextures(1, &s->f_tex);
    gl->GenTextures(1, &s->lkeys_tex);
    rc = gl_check(gl, "creating the olt pipeline", err);
    if (rc < 0) {
        olt_destroy(k, s);
        return rc;
    }
    *state = s;
    return 0;
}

static int olt_attach(rnd_kit *k, void *state, const rnd_gpu_cloud *c, void **cloud_data,
                      sd_err *err)
{
    (void)state;
    *cloud_data = NULL;
    soft_fields *fs = calloc(1, sizeof *fs);
    if (!fs) return sd_errf(err, SD_ENOMEM, "out of memory attaching a cloud to olt");
    int rc = soft_fields_attach(k->gl, c, fs, err);
    if (rc < 0) {
        free(fs);
        return rc;
    }
    *cloud_data = fs;
    return 0;
}

static void olt_detach(rnd_kit *k, void *state, void *cloud_data)
{
    (void)state;
    if (!cloud_data) return;
    soft_fields_free(k->gl, cloud_data);
    free(cloud_data);
}

/* layer_ensure: the layer target at w x h. Returns 0 or SD_EGL. */
static int layer_ensure(const gl_api *gl, olt_state *s, int w, int h, sd_err *err)
{
    if (s->layer.fbo && s->layer.width == w && s->layer.height == h) return 0;
    if (!s->layer.fbo) gl->GenFramebuffers(1, &s->layer.fbo);
    if (s->layer.color) gl->DeleteTextures(1, &s->layer.color);
    gl->GenTextures(1, &s->layer.color);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_OLT_COLOR);
    gl->BindTexture(GL_TEXTURE_2D, s->layer.color);
    gl->TexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA8, w, h);
    gl->BindTexture(GL_TEXTURE_2D, 0);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->BindFramebuffer(GL_FRAMEBUFFER, s->layer.fbo);
    gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, s->layer.color, 0);
    GLenum st = gl->CheckFramebufferStatus(GL_FRAMEBUFFER);
    if (st != GL_FRAMEBUFFER_COMPLETE)
        return sd_errf(err, SD_EGL, "olt: the %dx%d layer framebuffer is incomplete (0x%x)", w, h,
                       (unsigned)st);
    s->layer.width = w, s->layer.height = h;
    return 0;
}

/* compose: olt_compose over rows [y0, y0 + n) of the target (keys from row yb, nb rows). */
static void compose(rnd_kit *k, olt_state *s, const rnd_draw *d, int y0, int n, int yb, int nb)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_OLT_COLOR);
    gl->BindTexture(GL_TEXTURE_2D, s->layer.color);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_OLT_KEYS);
    gl->BindTexture(GL_TEXTURE_BUFFER, s->lkeys_tex);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_SPLAT_KEYS);
    gl->BindTexture(GL_TEXTURE_BUFFER, splat__keys_texture(s->splat));
    gl->ActiveTexture(GL_TEXTURE0);
    gl->UseProgram(s->compose);
    gl->Uniform2i(gl_uniform(gl, s->compose, "u_size"), v->width, v->height);
    gl->Uniform2i(gl_uniform(gl, s->compose, "u_stripe"), yb, nb);
    gl->Uniform1f(gl_uniform(gl, s->compose, "u_lambda"), d->params->lambda);
    rnd_kit_over_rows(k, s->vao, d->target, v->width, v->height, y0, n); /* depth: behind's */
    gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
}

static int olt_render(rnd_kit *k, void *state, const rnd_draw *d, sd_err *err)
{
    olt_state *s = state;
    soft_fields *fs = d->cloud_data;
    const gl_api *gl = k->gl;
    const sp_params *p = d->params;
    if (!fs) return sd_errf(err, SD_EINVAL, "olt: the cloud was not attached");
    int rc = soft_fields_update(gl, d->cloud, fs, p, err);
    if (rc < 0) return rc;
    if ((rc = layer_ensure(gl, s, d->view->width, d->view->height, err)) < 0) return rc;
    /* each buffer set's field buffer is bound when splat's passes make the set current */
    s->gl = gl;
    s->fs = fs;
    splat__set_set_hook(s->splat, bind_field, s);
    splat_frame f;
    int nstripes = splat__frame_begin(k, s->splat, d, &f, err);
    rc = nstripes < 0 ? nstripes : 0;
    rnd_draw ld = *d;
    ld.target = &s->layer;
    for (int i = 0; i < nstripes && rc == 0; i++) {
        /* 1: the soft points alone, into the layer */
        splat__set_filter(k, s->splat, SPLAT_SKIP_SOLID, p->t);
        splat__stripe_begin(k, s->splat, &f, i);
        if ((rc = splat__visibility(k, s->splat, &f, err)) < 0 ||
            (rc = splat__attributes(k, s->splat, &f, err)) < 0)
            break;
        f.d = &ld;
        splat__resolve(k, s->splat, &f);
        f.d = d;
        uint64_t kb = 0;
        GLuint kbuf = splat__keys_buffer(s->splat, &kb);
        /* (the texture is (re)made on its own unit: unit 0 holds the positions) */
        gl->ActiveTexture(GL_TEXTURE0 + RND_T_OLT_KEYS);
        if (rnd_kit_ensure_ssbo(gl, &s->lkeys_buf, &s->lkeys_bytes, kb)) {
            gl->BindTexture(GL_TEXTURE_BUFFER, s->lkeys_tex);
            gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, s->lkeys_buf);
        }
        gl->ActiveTexture(GL_TEXTURE0);
        gl->BindBuffer(GL_COPY_READ_BUFFER, kbuf);
        gl->BindBuffer(GL_COPY_WRITE_BUFFER, s->lkeys_buf);
        gl->CopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0, (GLsizeiptr)kb);
        gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
        gl->BindBuffer(GL_COPY_WRITE_BUFFER, 0);
        gl->MemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
        /* 2: everything but the first soft layer, opaque, into the target */
        gl->ActiveTexture(GL_TEXTURE0 + RND_T_OLT_KEYS);
        gl->BindTexture(GL_TEXTURE_BUFFER, s->lkeys_tex);
        gl->ActiveTexture(GL_TEXTURE0);
        splat__set_filter(k, s->splat, SPLAT_PEEL, p->t);
        splat__stripe_begin(k, s->splat, &f, i);
        if ((rc = splat__visibility(k, s->splat, &f, err)) < 0 ||
            (rc = splat__attributes(k, s->splat, &f, err)) < 0)
            break;
        splat__resolve(k, s->splat, &f);
        /* 3: the layer over it */
        int height = d->view->height;
        int yb = f.y0 > 0 ? f.y0 - 1 : 0; /* the keys' first row (splat's halo) */
        int nb = (f.y0 + f.n < height ? f.y0 + f.n + 1 : f.y0 + f.n) - yb;
        compose(k, s, d, f.y0, f.n, yb, nb);
    }
    int end = splat__frame_end(k, s->splat, err);
    splat__set_set_hook(s->splat, NULL, NULL);
    s->fs = NULL;
    return rc < 0 ? rc : end;
}

const rnd_pipeline pipe_olt = {
    .name = "olt",
    .needs = 1u << RND_ATTR_POS | 1u << RND_ATTR_NORMAL | 1u << RND_ATTR_RADIUS |
             1u << RND_ATTR_RGBA | 1u << RND_ATTR_FIELD | 1u << RND_ATTR_INTENSITY |
             1u << RND_ATTR_SCAN | 1u << RND_ATTR_CLASS | 1u << RND_ATTR_SCALAR,
    .create = olt_create,
    .destroy = olt_destroy,
    .attach = olt_attach,
    .detach = olt_detach,
    .render = olt_render,
};
