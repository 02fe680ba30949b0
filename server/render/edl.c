/* edl.c — Eye-Dome Lighting as one fragment pass over the cloud's screen rectangle (edl.h,
 * shaders/edl.frag.glsl), on every back end (a host copy of the pass was measured to save too
 * little of a frame to keep: docs/performance.md, "Host paths").
 *
 * The shade only darkens, so it is applied by blending (dst = dst * src, glBlendFunc(GL_ZERO,
 * GL_SRC_COLOR)) instead of a copy of the colour: the pass never reads the colour it writes, so
 * no feedback loop and no second colour texture. A fragment pass rather than compute because
 * llvmpipe shades whole pixel quads at once. The depth is first copied (glReadPixels into a
 * pixel-pack buffer, the rectangle's rows) and read as a buffer texture: on llvmpipe that copy
 * costs well under a millisecond and makes each of the 5 fetches a pixel a gather; through the
 * 2-D texture the pass took ~14 ms of CPU a 1280x720 frame, ~3 ms for the copy path (render_bench,
 * bunnyData.pts, which fills most of the frame).
 *
 * The copy is framed by r rows and columns of +inf (the buffer is cleared to +inf, then the
 * rectangle is read into its interior), so a neighbour outside the rectangle reads as
 * background and the shader needs neither bounds tests nor `discard`, both of which llvmpipe
 * pays for on every lane (it runs both sides of a branch, masked). Measured on Guanyin.ply's
 * rectangle (~345k pixels, process CPU between glFinish calls, a loaded 2-core machine): the
 * pass 5.4 -> 4.1 ms, the clear and copy 0.4 ms as the copy alone was. Of the 4.1 ms, ~0.8 is
 * llvmpipe's raster and blend (a shader writing a constant), ~2.3 the 5 fetches and ratios,
 * ~1 the log2 and exp; one reciprocal instead of the 4 divisions saved nothing measurable. */
#include "edl.h"

#include <math.h>
#include <string.h>

#include "shaders.h"

int rnd__edl_init(rnd_edl *e, rnd_kit *k, sd_err *err)
{
    memset(e, 0, sizeof *e);
    const char *const files[2] = {"edl.vert", "edl.frag"};
    e->prog = rnd_kit_program(k, files, 2, NULL, err);
    if (!e->prog) return err && err->code ? err->code : SD_EGL;
    const gl_api *gl = k->gl;
    e->u_org = gl_uniform(gl, e->prog, "u_org");
    e->u_pw = gl_uniform(gl, e->prog, "u_pw");
    e->u_r = gl_uniform(gl, e->prog, "u_r");
    e->u_k = gl_uniform(gl, e->prog, "u_k");
    gl->GenVertexArrays(1, &e->vao);
    gl->GenBuffers(1, &e->copy_buf);
    gl->GenTextures(1, &e->copy_tex);
    int rc = gl_check(gl, "creating the EDL pass", err);
    if (rc < 0) rnd__edl_free(e, gl);
    return rc;
}

void rnd__edl_free(rnd_edl *e, const gl_api *gl)
{
    if (!e) return;
    if (e->prog) gl->DeleteProgram(e->prog);
    if (e->vao) gl->DeleteVertexArrays(1, &e->vao);
    if (e->copy_buf) gl->DeleteBuffers(1, &e->copy_buf);
    if (e->copy_tex) gl->DeleteTextures(1, &e->copy_tex);
    memset(e, 0, sizeof *e);
}

void rnd__edl_apply(rnd_edl *e, const gl_api *gl, const rnd_target *t, const int rect[4],
                    float strength, float radius)
{
    if (!(strength > 0.0f) || !e->prog) return; /* strength 0: the frame stays bit for bit */
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) return;
    int r = (int)floorf(radius + 0.5f);
    r = r > 1 ? r : 1;
    /* The rectangle of depth_eye into the interior of copy_buf, a (w + 2r) x (h + 2r) grid
     * cleared to +inf: the frame of r texels around it is background. */
    int w = rect[2] - rect[0], h = rect[3] - rect[1], pw = w + 2 * r;
    uint64_t bytes = (uint64_t)pw * (uint64_t)(h + 2 * r) * 4;
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, e->copy_buf);
    if (e->copy_bytes < bytes) {
        gl->BufferData(GL_PIXEL_PACK_BUFFER, (GLsizeiptr)bytes, NULL, GL_STREAM_COPY);
        e->copy_bytes = bytes;
    }
    const float inf = INFINITY;
    gl->ClearBufferSubData(GL_PIXEL_PACK_BUFFER, GL_R32F, 0, (GLsizeiptr)bytes, GL_RED, GL_FLOAT,
                           &inf);
    gl->BindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, pw);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT1);
    gl->ReadPixels(rect[0], rect[1], w, h, GL_RED, GL_FLOAT,
                   (void *)(uintptr_t)(((uint64_t)r * (uint64_t)pw + (uint64_t)r) * 4));
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, 0);
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    gl->MemoryBarrier(GL_PIXEL_BUFFER_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
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
    gl->BindTexture(GL_TEXTURE_BUFFER, e->copy_tex);
    gl->TexBuffer(GL_TEXTURE_BUFFER, GL_R32F, e->copy_buf);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->UseProgram(e->prog);
    gl->Uniform2i(e->u_org, rect[0] - r, rect[1] - r);
    gl->Uniform1i(e->u_pw, pw);
    gl->Uniform1i(e->u_r, r);
    gl->Uniform1f(e->u_k, RND_EDL_SCALE * strength / 4.0f);
    gl->Enable(GL_SCISSOR_TEST);
    gl->Scissor(rect[0], rect[1], rect[2] - rect[0], rect[3] - rect[1]);
    gl->BindVertexArray(e->vao);
    gl->DrawArrays(GL_TRIANGLES, 0, 3);
    gl->BindVertexArray(0);
    gl->Disable(GL_SCISSOR_TEST);
    gl->UseProgram(0);
    gl->ActiveTexture(GL_TEXTURE0 + RND_T_EDL_DEPTH);
    gl->BindTexture(GL_TEXTURE_BUFFER, 0);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->Disable(GL_BLEND);
    gl->BlendFunc(GL_ONE, GL_ZERO);
    const GLenum both[2] = {GL_COLOR_ATTACHMENT0, t->is_float ? GL_COLOR_ATTACHMENT1 : GL_NONE};
    gl->DrawBuffers(2, both);
}
