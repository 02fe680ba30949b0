/* edl.h — Eye-Dome Lighting (Boucheny 2009, in the form Potree and CloudCompare use), a pass
 * over a finished frame's eye depth for every pipeline (internal to the renderer; render.c
 * runs it when shading=edl). */
#pragma once
#include "pipe.h"

/* The darkening per unit of mean log2-depth obscurance at edl_strength 1: Potree's constant,
 * so that strength 1 gives the look its users know. */
#define RND_EDL_SCALE 300.0f

typedef struct rnd_edl {
    GLuint prog, vao;
    GLint u_org, u_pw, u_r, u_k;
    GLuint copy_buf, copy_tex;   /* depth_eye copied into a buffer, read as a buffer texture */
    uint64_t copy_bytes;
    float *host;                 /* edl_pass=cpu: the rectangle's eye depth framed by +inf */
    size_t host_cap;             /* floats allocated at host */
} rnd_edl;

/* rnd__edl_init: compiles edl.vert/edl.frag. Returns 0 or SD_E* with err filled.
 * rnd__edl_free: releases it; safe on a zeroed struct. */
int rnd__edl_init(rnd_edl *e, rnd_kit *k, sd_err *err);
void rnd__edl_free(rnd_edl *e, const gl_api *gl);

/* rnd__edl_apply: multiplies the colour of target t (bound state is left as the renderer
 * expects: no blending, both draw buffers of the float target, alpha untouched) by the EDL
 * shade exp(-RND_EDL_SCALE * strength * sum_n max(0, log2 z - log2 z_n) / 4) of its 4
 * neighbours at `radius` pixels (rounded to whole pixels, at least 1: right, up, left,
 * down), read from t->depth_eye; background pixels (+inf) and neighbours
 * outside the frame or on the background add nothing. Only the pixels of rect (x0, y0, x1, y1;
 * the cloud's screen rectangle: nothing else has a depth) are read and shaded. strength 0
 * draws nothing. */
void rnd__edl_apply(rnd_edl *e, const gl_api *gl, const rnd_target *t, const int rect[4],
                    float strength, float radius);

/* rnd__edl_host: the same pass on the host (edl_pass=cpu, edl_host.c), after the frame's
 * read-back: reads t->depth_eye over rect into e->host framed by +inf and multiplies the colour
 * of the read-back frame (rgba8, and rgba16f when not NULL: width x height pixels, rows
 * bottom-up as glReadPixels left them) by the shade, alpha untouched. strength 0 touches
 * nothing. Returns 0 or SD_ENOMEM with err filled (the frame is then left unshaded). */
int rnd__edl_host(rnd_edl *e, const gl_api *gl, const rnd_target *t, const int rect[4],
                  float strength, float radius, uint8_t *rgba8, uint16_t *rgba16f, int width,
                  sd_err *err);

/* rnd__edl_host_shade: the arithmetic of rnd__edl_host, for tests. z: the depth of a w x h
 * rectangle at z[(y + r) * pw + x + r], framed by r rows and columns of +inf, pw = w + 2r,
 * with 8 more readable floats after the last row (+inf); rgba8 / rgba16f: the rectangle's
 * bottom-left pixel in frames of `stride` pixels a row; k = RND_EDL_SCALE * strength / 4. */
void rnd__edl_host_shade(const float *z, int pw, int r, int w, int h, float k, uint8_t *rgba8,
                         uint16_t *rgba16f, int stride);
