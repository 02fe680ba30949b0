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
