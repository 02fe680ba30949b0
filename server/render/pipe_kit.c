/* pipe_kit.c — what every pipeline shares (pipe.h): the back end's capability and the host
 * paths chosen from it, driver facts, the program builder, storage buffers that grow, the
 * colour source, a buffer set bound on the fixed texture units of bindings.h, and the per-set
 * range table of lib_ranges.glsl. */
#include <stdlib.h>
#include <string.h>

#include "pipe.h"
#include "shaders.h"

const rnd_attr_info rnd_attrs[RND_ATTR_COUNT] = {
#define RND_ATTR_ROW_(id, nm, comps, fmt) [RND_ATTR_##id] = {nm, comps, fmt},
    RND_ATTR_LIST(RND_ATTR_ROW_)
#undef RND_ATTR_ROW_
};

int rnd_kit_has_extension(const gl_api *gl, const char *name)
{
    GLint n = 0;
    gl->GetIntegerv(GL_NUM_EXTENSIONS, &n);
    for (GLint i = 0; i < n; i++) {
        const char *e = (const char *)gl->GetStringi(GL_EXTENSIONS, (GLuint)i);
        if (e && !strcmp(e, name)) return 1;
    }
    return 0;
}

int rnd_kit_init(rnd_kit *k, const gl_api *gl, const rnd_shaders *sh, const rnd_pipe_opts *o,
                 int software, int host, sd_err *err)
{
    memset(k, 0, sizeof *k);
    k->gl = gl;
    k->sh = sh;
    if (o) k->opts = *o;
    k->software = software != 0;
    k->host = host ? &rnd_host_cpu : NULL;
    k->float_atomics = rnd_kit_has_extension(gl, "GL_NV_shader_atomic_float");
    GLint v = 0;
    gl->GetIntegerv(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &v);
    k->max_ssbo = v > 0 ? v : (GLint64)1 << 27;
    v = 0;
    gl->GetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &v);
    k->max_texels = v > 0 ? v : 65536;
    gl->GenTextures(4, k->cloud_tex);
    gl->GenTextures(1, &k->range_tex);
    return gl_check(gl, "setting up the pipelines' shared state", err);
}

void rnd_kit_free(rnd_kit *k)
{
    if (!k || !k->gl) return;
    const gl_api *gl = k->gl;
    if (k->cloud_tex[0]) gl->DeleteTextures(4, k->cloud_tex);
    if (k->range_tex) gl->DeleteTextures(1, &k->range_tex);
    if (k->range_buf) gl->DeleteBuffers(1, &k->range_buf);
    free(k->range_tmp);
    memset(k, 0, sizeof *k);
}

GLuint rnd_kit_program(const rnd_kit *k, const char *const *names, int n, const char *defines,
                       sd_err *err)
{
    return gl_program_build(k->gl, k->sh, names, n, defines, err);
}

int rnd_kit_ensure_ssbo(const gl_api *gl, GLuint *buf, uint64_t *have, uint64_t bytes)
{
    if (*buf && *have >= bytes) return 0;
    if (!*buf) gl->GenBuffers(1, buf);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, *buf);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)bytes, NULL, GL_DYNAMIC_DRAW);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    *have = bytes;
    return 1;
}

int rnd_kit_color_source(int color)
{
    return color == SP_COLOR_FIELD ? RND_ATTR_FIELD
         : color == SP_COLOR_INTENSITY ? RND_ATTR_INTENSITY
         : color == SP_COLOR_SCAN ? RND_ATTR_SCAN : RND_ATTR_RGBA;
}

void rnd_kit_bind_set(rnd_kit *k, const rnd_bufset *s, int color)
{
    const gl_api *gl = k->gl;
    const int attr[4] = {RND_ATTR_POS, RND_ATTR_NORMAL, RND_ATTR_RADIUS,
                         rnd_kit_color_source(color)};
    const GLenum unit[4] = {RND_T_POS, RND_T_NRM, RND_T_RAD, RND_T_SRC};
    for (int i = 0; i < 4; i++) {
        gl->ActiveTexture(GL_TEXTURE0 + unit[i]);
        gl->BindTexture(GL_TEXTURE_BUFFER, k->cloud_tex[i]);
        gl->TexBuffer(GL_TEXTURE_BUFFER, rnd_attrs[attr[i]].texel, s->buf[attr[i]]);
    }
    gl->ActiveTexture(GL_TEXTURE0);
}

int64_t rnd_kit_set_ranges(rnd_kit *k, const rnd_view *v, uint32_t set, uint32_t *nranges,
                           uint32_t *first, sd_err *err)
{
    const gl_api *gl = k->gl;
    uint32_t a = 0;
    while (a < v->nchunks && v->chunks[a].set < set) a++;
    uint32_t b = a;
    while (b < v->nchunks && v->chunks[b].set == set) b++;
    *nranges = b - a;
    *first = a < b ? v->chunks[a].first : 0;
    if (a == b) return 0;
    uint32_t nr = b - a;
    if (nr > k->range_cap) {
        uint32_t cap = nr < 64 ? 64 : nr;
        uint32_t *t = realloc(k->range_tmp, (size_t)cap * 2 * sizeof *t);
        if (!t) return sd_errf(err, SD_ENOMEM, "out of memory for %u point ranges", nr);
        k->range_tmp = t;
        k->range_cap = cap;
        rnd_kit_ensure_ssbo(gl, &k->range_buf, &k->range_bytes, (uint64_t)cap * 8);
    }
    uint64_t total = 0;
    for (uint32_t i = 0; i < nr; i++) {
        k->range_tmp[2 * i] = v->chunks[a + i].first;
        k->range_tmp[2 * i + 1] = (uint32_t)total;
        total += v->chunks[a + i].count;
    }
    if (total > (uint64_t)UINT32_MAX - 64)
        return sd_errf(err, SD_ELIMIT, "%llu visible points in one buffer set are more than "
                       "a 32-bit index addresses", (unsigned long long)total);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, k->range_buf);
    gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)nr * 8, k->range_tmp);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_RANGES);
    gl->BindTexture(GL_TEXTURE_BUFFER, k->range_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_RG32UI, k->range_buf);
    gl->ActiveTexture(GL_TEXTURE0);
    return (int64_t)total;
}

void rnd_kit_over_rows(rnd_kit *k, GLuint vao, const rnd_target *t, int width, int height, int y0,
                       int n)
{
    const gl_api *gl = k->gl;
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    gl->Viewport(0, 0, width, height);
    gl->Enable(GL_SCISSOR_TEST);
    gl->Scissor(0, y0, width, n);
    gl->Disable(GL_DEPTH_TEST);
    gl->Enable(GL_BLEND);
    gl->BlendFuncSeparate(GL_ONE, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    gl->ColorMaski(1, GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    gl->BindVertexArray(vao);
    gl->DrawArrays(GL_TRIANGLES, 0, 6);
    gl->BindVertexArray(0);
    gl->ColorMaski(1, GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->Disable(GL_BLEND);
    gl->Disable(GL_SCISSOR_TEST);
}

void rnd_kit_unbind(rnd_kit *k)
{
    const gl_api *gl = k->gl;
    for (int u = RND_T_COUNT - 1; u >= 0; u--) {
        gl->ActiveTexture(GL_TEXTURE0 + (GLenum)u);
        gl->BindTexture(GL_TEXTURE_BUFFER, 0);
    }
}
