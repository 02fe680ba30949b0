/* gl_backend.h — a headless OpenGL context, behind one small interface with one file per
 * implementation: gl_egl.c (EGL device or surfaceless platform) and gl_osmesa.c (OSMesa).
 * The choice happens at run time (--backend), so callers go through a gl_backend_ops table
 * (redis ConnectionType), never through `if (egl)` branches. No GL headers here.
 *
 * Whether the context rasterises on the CPU (Mesa's llvmpipe, softpipe, swrast) is decided
 * here, once, by the back end that opened it (ops->software): the renderer derives from it the
 * pipelines' host paths and their tunings for a software rasteriser (pipe.h, rnd_kit). */
#pragma once

#include "sd_err.h"

typedef struct gl_backend gl_backend; /* the implementation's private state */

typedef struct gl_backend_ops {
    const char *name; /* "egl", "osmesa" */
    /* create: opens a display/device and a 4.5 (or at least 4.3) core context, and makes it
     * current on the calling thread. Returns 0 with *out set, or SD_EGL / SD_EUNSUP / SD_ENOMEM
     * with err naming the EGL error or what was missing. */
    int (*create)(gl_backend **out, sd_err *err);
    /* make_current: makes the context current on the calling thread. Returns 0 or SD_EGL. */
    int (*make_current)(gl_backend *b, sd_err *err);
    /* destroy: releases the context (and display); NULL is fine. */
    void (*destroy)(gl_backend *b);
    /* getproc: the address of a GL function ("glGenBuffers"), or NULL; matches gl_getproc_fn
     * with user = the gl_backend. */
    void *(*getproc)(void *b, const char *name);
    /* describe: what was opened ("EGL 1.5 device 1 of 2 (software)", "OSMesa 4.5 core"). */
    const char *(*describe)(const gl_backend *b);
    /* software: 1 when the context rasterises on the CPU, 0 on a GPU. EGL: the device's
     * EGL_MESA_device_software, or on the surfaceless platform the GL renderer's name
     * (gl_renderer_is_software); OSMesa: always 1 (Mesa's off-screen software renderer). */
    int (*software)(const gl_backend *b);
} gl_backend_ops;

extern const gl_backend_ops gl_backend_egl;
extern const gl_backend_ops gl_backend_osmesa;
