/* gl_names.h — EGL and OpenGL error codes as names ("EGL_BAD_MATCH", "GL_INVALID_ENUM"), so
 * errors are reported by name (VirtualGL's EGLError.h), and the names of Mesa's software
 * rasterisers. Codes are plain unsigned ints here so that this header needs neither the EGL
 * nor the GL headers. */
#pragma once

/* gl_error_name: the name of a glGetError / glCheckFramebufferStatus code, or "0x%04x" written
 * into buf when unknown. Returns a static string or buf. */
const char *gl_error_name(unsigned code, char *buf, unsigned long len);

/* egl_error_name: the name of an eglGetError code, or "0x%04x" in buf when unknown. */
const char *egl_error_name(unsigned code, char *buf, unsigned long len);

/* gl_renderer_is_software: whether a GL_RENDERER string names one of Mesa's software
 * rasterisers (llvmpipe, softpipe, swrast), for a back end that has no better way to know
 * (gl_backend.h); 0 for NULL. */
int gl_renderer_is_software(const char *renderer);
