/* edl.c — Eye-Dome Lighting as one full-frame fragment pass (edl.h, shaders/edl.frag.glsl).
 *
 * The shade only darkens, so it is applied by blending (dst = dst * src, glBlendFunc(GL_ZERO,
 * GL_SRC_COLOR)) instead of a copy of the colour: the pass reads depth_eye, never the colour it
 * writes, so no feedback loop and no second colour texture. A fragment pass rather than compute
 * because llvmpipe shades whole pixel quads at once. */
#include "edl.h"

#include <string.h>

#include "shaders.h"

int rnd__edl_init(rnd_edl *e, rnd_kit *k, sd_err *err)
{
    memset(e, 0, sizeof *e);
    const char *const files[2] = {"edl.vert", "edl.frag"};
    e->prog = rnd_kit_program(k, files, 2, NULL, err);
    if (!e->prog) return err && err->code ? err->code : SD_EGL;
    const gl_api *gl = k->gl;
    e->u_size = gl_uniform(gl, e->prog, "u_size");
    e->u_radius = gl_uniform(gl, e->prog, "u_radius");
    e->u_k = gl_uniform(gl, e->prog, "u_k");
    gl->GenVertexArrays(1, &e->vao);
    int rc = gl_check(gl, "creating the EDL pass", err);
    if (rc < 0) rnd__edl_free(e, gl);
    return rc;
}

void rnd__edl_free(rnd_edl *e, const gl_api *gl)
{
    if (!e) return;
    if (e->prog) gl->DeleteProgram(e->prog);
    if (e->vao) gl->DeleteVertexArrays(1, &e->vao);
    memset(e, 0, sizeof *e);
}

void rnd__edl_apply(const rnd_edl *e, const gl_api *gl, const rnd_target *t, float strength,
                    float radius)
{
    if (!(strength > 0.0f) || !e->prog) return; /* strength 0: the frame stays bit for bit */
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    /* depth_eye is read, so it must not be a draw buffer during the pass. */
    const GLenum one[2] = {GL_COLOR_ATTACHMENT0, GL_NONE};
    gl->DrawBuffers(2, one);
    gl->Viewport(0, 0, t->width, t->height);
    gl->ColorMaski(0, GL_TRUE, GL_TRUE, GL_TRUE, GL_FALSE); /* alpha: coverage or opaque */
    gl->Disable(GL_DEPTH_TEST);
    gl->Disable(GL_SCISSOR_TEST);
    gl->Enable(GL_BLEND);
    gl->BlendFunc(GL_ZERO, GL_SRC_COLOR);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_EDL_DEPTH);
    gl->BindTexture(GL_TEXTURE_2D, t->depth_eye);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->UseProgram(e->prog);
    gl->Uniform2i(e->u_size, t->width, t->height);
    gl->Uniform1f(e->u_radius, radius);
    gl->Uniform1f(e->u_k, RND_EDL_SCALE * strength / 8.0f);
    gl->BindVertexArray(e->vao);
    gl->DrawArrays(GL_TRIANGLES, 0, 3);
    gl->BindVertexArray(0);
    gl->UseProgram(0);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_EDL_DEPTH);
    gl->BindTexture(GL_TEXTURE_2D, 0);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->Disable(GL_BLEND);
    gl->BlendFunc(GL_ONE, GL_ZERO);
    const GLenum both[2] = {GL_COLOR_ATTACHMENT0, t->is_float ? GL_COLOR_ATTACHMENT1 : GL_NONE};
    gl->DrawBuffers(2, both);
}
