/* gl_names.c — EGL and GL error code names, software renderer names (see gl_names.h). */
#include "gl_names.h"

#include <stdio.h>
#include <string.h>

#define GL_ERROR_NAMES(X)                                                     \
    X(0x0000, "GL_NO_ERROR")                                                  \
    X(0x0500, "GL_INVALID_ENUM")                                              \
    X(0x0501, "GL_INVALID_VALUE")                                             \
    X(0x0502, "GL_INVALID_OPERATION")                                         \
    X(0x0503, "GL_STACK_OVERFLOW")                                            \
    X(0x0504, "GL_STACK_UNDERFLOW")                                           \
    X(0x0505, "GL_OUT_OF_MEMORY")                                             \
    X(0x0506, "GL_INVALID_FRAMEBUFFER_OPERATION")                             \
    X(0x0507, "GL_CONTEXT_LOST")                                              \
    X(0x8CD5, "GL_FRAMEBUFFER_COMPLETE")                                      \
    X(0x8CD6, "GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT")                         \
    X(0x8CD7, "GL_FRAMEBUFFER_INCOMPLETE_MISSING_ATTACHMENT")                 \
    X(0x8CDB, "GL_FRAMEBUFFER_INCOMPLETE_DRAW_BUFFER")                        \
    X(0x8CDC, "GL_FRAMEBUFFER_INCOMPLETE_READ_BUFFER")                        \
    X(0x8CDD, "GL_FRAMEBUFFER_UNSUPPORTED")                                   \
    X(0x8D56, "GL_FRAMEBUFFER_INCOMPLETE_MULTISAMPLE")                        \
    X(0x8DA8, "GL_FRAMEBUFFER_INCOMPLETE_LAYER_TARGETS")                      \
    X(0x8219, "GL_FRAMEBUFFER_UNDEFINED")

#define EGL_ERROR_NAMES(X)                                                    \
    X(0x3000, "EGL_SUCCESS")                                                  \
    X(0x3001, "EGL_NOT_INITIALIZED")                                          \
    X(0x3002, "EGL_BAD_ACCESS")                                               \
    X(0x3003, "EGL_BAD_ALLOC")                                                \
    X(0x3004, "EGL_BAD_ATTRIBUTE")                                            \
    X(0x3005, "EGL_BAD_CONFIG")                                               \
    X(0x3006, "EGL_BAD_CONTEXT")                                              \
    X(0x3007, "EGL_BAD_CURRENT_SURFACE")                                      \
    X(0x3008, "EGL_BAD_DISPLAY")                                              \
    X(0x3009, "EGL_BAD_MATCH")                                                \
    X(0x300A, "EGL_BAD_NATIVE_PIXMAP")                                        \
    X(0x300B, "EGL_BAD_NATIVE_WINDOW")                                        \
    X(0x300C, "EGL_BAD_PARAMETER")                                            \
    X(0x300D, "EGL_BAD_SURFACE")                                              \
    X(0x300E, "EGL_CONTEXT_LOST")                                             \
    X(0x322B, "EGL_BAD_DEVICE_EXT")

const char *gl_error_name(unsigned code, char *buf, unsigned long len)
{
    switch (code) {
#define CASE_(c, n) case c: return n;
        GL_ERROR_NAMES(CASE_)
    }
    snprintf(buf, len, "GL error 0x%04x", code);
    return buf;
}

const char *egl_error_name(unsigned code, char *buf, unsigned long len)
{
    switch (code) {
        EGL_ERROR_NAMES(CASE_)
#undef CASE_
    }
    snprintf(buf, len, "EGL error 0x%04x", code);
    return buf;
}

int gl_renderer_is_software(const char *renderer)
{
    return renderer && (strstr(renderer, "llvmpipe") || strstr(renderer, "softpipe") ||
                        strstr(renderer, "swrast"));
}
