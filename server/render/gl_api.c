/* gl_api.c — loads the GL function table from the active back end; GL error checks. */
#include "gl_api.h"

#include <stdio.h>
#include <string.h>

#include "gl_names.h"

int gl_api_load(gl_api *gl, gl_getproc_fn getproc, void *user, sd_err *err)
{
    memset(gl, 0, sizeof *gl);
    /* Object pointers and function pointers share a representation on every platform that
     * has EGL (POSIX requires it for dlsym); the memcpy keeps -Wpedantic quiet about it. */
#define GL_API_LOAD_(name, type)                                                         \
    do {                                                                                 \
        void *p_ = getproc(user, "gl" #name);                                            \
        if (!p_) {                                                                       \
            memset(gl, 0, sizeof *gl);                                                   \
            return sd_errf(err, SD_EGL, "the GL back end does not provide gl%s", #name); \
        }                                                                                \
        memcpy(&gl->name, &p_, sizeof gl->name);                                         \
    } while (0);
    GL_API_LIST(GL_API_LOAD_)
#undef GL_API_LOAD_
    return 0;
}

int gl_check(const gl_api *gl, const char *what, sd_err *err)
{
    char names[256] = "", tmp[32];
    size_t used = 0;
    int n = 0;
    GLenum e;
    /* Bounded: a lost context may report errors forever. */
    while (n < 16 && (e = gl->GetError()) != GL_NO_ERROR) {
        int w = snprintf(names + used, sizeof names - used, "%s%s", n ? ", " : "",
                         gl_error_name(e, tmp, sizeof tmp));
        if (w > 0 && (size_t)w < sizeof names - used) used += (size_t)w;
        n++;
    }
    if (!n) return 0;
    return sd_errf(err, SD_EGL, "OpenGL error after %s: %s", what, names);
}
