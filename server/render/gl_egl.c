/* gl_egl.c — the EGL back end: no window, no X.
 *
 * Order of attempts: EGL_EXT_platform_device with every device eglQueryDevicesEXT lists,
 * hardware devices first and then Mesa's software device (the one whose extension string has
 * EGL_MESA_device_software, which is also how the back end reports a software renderer); then
 * EGL_MESA_platform_surfaceless (software when its renderer's name says so). On each display:
 * a 4.5 core context (4.6 fails with EGL_BAD_MATCH on Mesa 22), else 4.3, without a config
 * (EGL_KHR_no_config_context), current with EGL_NO_SURFACE (a 1x1 pbuffer on drivers without
 * those extensions); rendering goes into FBOs. */
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl_backend.h"
#include "gl_names.h"

enum { EGL_MAX_DEVICES = 16 };

struct gl_backend {
    EGLDisplay dpy;
    EGLContext ctx;
    EGLSurface surf; /* EGL_NO_SURFACE, or a 1x1 pbuffer where surfaceless contexts are missing */
    int software;    /* the context rasterises on the CPU (gl_backend_ops.software) */
    char desc[256];
};

/* Whether the space-separated extension list exts contains name. */
static int has_ext(const char *exts, const char *name)
{
    size_t l = strlen(name);
    for (const char *s = exts; s && (s = strstr(s, name)) != NULL; s += l)
        if ((s == exts || s[-1] == ' ') && (s[l] == ' ' || s[l] == 0)) return 1;
    return 0;
}

static const char *egl_err_now(char *buf, size_t len)
{
    return egl_error_name((unsigned)eglGetError(), buf, len);
}

static void *egl_proc(const char *name)
{
    __eglMustCastToProperFunctionPointerType f = eglGetProcAddress(name);
    void *p;
    memcpy(&p, &f, sizeof p);
    return p;
}

/* Initialises dpy and creates a core context on it, current without a surface. Where the
 * display lacks EGL_KHR_no_config_context or EGL_KHR_surfaceless_context (older GPU drivers),
 * it takes a pbuffer-capable config and a 1x1 pbuffer instead; rendering goes to FBOs either
 * way. Returns 0 with b->dpy/ctx/surf set, or SD_EGL with err naming the step and the EGL
 * error. dpy stays initialised either way (see egl_destroy). */
static int open_display(gl_backend *b, EGLDisplay dpy, const char *what, sd_err *err)
{
    char en[40];
    EGLint major = 0, minor = 0;
    if (dpy == EGL_NO_DISPLAY)
        return sd_errf(err, SD_EGL, "EGL %s: no display (%s)", what, egl_err_now(en, sizeof en));
    if (!eglInitialize(dpy, &major, &minor))
        return sd_errf(err, SD_EGL, "EGL %s: eglInitialize failed (%s)", what,
                       egl_err_now(en, sizeof en));
    const char *exts = eglQueryString(dpy, EGL_EXTENSIONS);
    int no_config = has_ext(exts, "EGL_KHR_no_config_context");
    int surfaceless = has_ext(exts, "EGL_KHR_surfaceless_context");
    EGLConfig cfg = EGL_NO_CONFIG_KHR;
    if (!no_config || !surfaceless) {
        const EGLint ca[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                             EGL_OPENGL_BIT, EGL_RED_SIZE, 8, EGL_GREEN_SIZE, 8, EGL_BLUE_SIZE, 8,
                             EGL_NONE};
        EGLint n = 0;
        if (!eglChooseConfig(dpy, ca, &cfg, 1, &n) || n < 1)
            return sd_errf(err, SD_EUNSUP, "EGL %s: no config-less or surfaceless contexts and "
                           "no pbuffer OpenGL config (%s)", what, egl_err_now(en, sizeof en));
    }
    if (!eglBindAPI(EGL_OPENGL_API))
        return sd_errf(err, SD_EGL, "EGL %s: eglBindAPI(EGL_OPENGL_API) failed (%s)", what,
                       egl_err_now(en, sizeof en));
    static const EGLint versions[][2] = {{4, 5}, {4, 3}};
    EGLContext ctx = EGL_NO_CONTEXT;
    int vi = 0;
    for (; vi < 2 && ctx == EGL_NO_CONTEXT; vi++) {
        const EGLint attr[] = {EGL_CONTEXT_MAJOR_VERSION, versions[vi][0],
                               EGL_CONTEXT_MINOR_VERSION, versions[vi][1],
                               EGL_CONTEXT_OPENGL_PROFILE_MASK,
                               EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
        ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, attr);
    }
    if (ctx == EGL_NO_CONTEXT)
        return sd_errf(err, SD_EGL, "EGL %s: no OpenGL 4.3 core context (%s)", what,
                       egl_err_now(en, sizeof en));
    EGLSurface surf = EGL_NO_SURFACE;
    if (!surfaceless) {
        const EGLint pa[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
        surf = eglCreatePbufferSurface(dpy, cfg, pa);
        if (surf == EGL_NO_SURFACE) {
            sd_errf(err, SD_EGL, "EGL %s: eglCreatePbufferSurface failed (%s)", what,
                    egl_err_now(en, sizeof en));
            eglDestroyContext(dpy, ctx);
            return SD_EGL;
        }
    }
    if (!eglMakeCurrent(dpy, surf, surf, ctx)) {
        sd_errf(err, SD_EGL, "EGL %s: eglMakeCurrent failed (%s)", what,
                egl_err_now(en, sizeof en));
        if (surf != EGL_NO_SURFACE) eglDestroySurface(dpy, surf);
        eglDestroyContext(dpy, ctx);
        return SD_EGL;
    }
    b->dpy = dpy;
    b->ctx = ctx;
    b->surf = surf;
    snprintf(b->desc, sizeof b->desc, "EGL %d.%d %s, GL %d.%d core", (int)major, (int)minor, what,
             (int)versions[vi - 1][0], (int)versions[vi - 1][1]);
    return 0;
}

/* Tries every EGL device, hardware before software. Returns 0 or the last error. */
static int try_devices(gl_backend *b, sd_err *err)
{
    PFNEGLQUERYDEVICESEXTPROC query_devices = (PFNEGLQUERYDEVICESEXTPROC)0;
    PFNEGLQUERYDEVICESTRINGEXTPROC device_string = (PFNEGLQUERYDEVICESTRINGEXTPROC)0;
    PFNEGLGETPLATFORMDISPLAYEXTPROC platform_display = (PFNEGLGETPLATFORMDISPLAYEXTPROC)0;
    void *p;
    p = egl_proc("eglQueryDevicesEXT");
    memcpy(&query_devices, &p, sizeof p);
    p = egl_proc("eglQueryDeviceStringEXT");
    memcpy(&device_string, &p, sizeof p);
    p = egl_proc("eglGetPlatformDisplayEXT");
    memcpy(&platform_display, &p, sizeof p);
    if (!query_devices || !device_string || !platform_display)
        return sd_errf(err, SD_EUNSUP, "EGL: the device enumeration functions are missing");
    EGLDeviceEXT devs[EGL_MAX_DEVICES];
    EGLint n = 0;
    char en[40];
    if (!query_devices(EGL_MAX_DEVICES, devs, &n) || n <= 0)
        return sd_errf(err, SD_EGL, "EGL: eglQueryDevicesEXT found no device (%s)",
                       egl_err_now(en, sizeof en));
    int rc = SD_EGL;
    for (int pass = 0; pass < 2; pass++) { /* 0: hardware, 1: software */
        for (EGLint i = 0; i < n; i++) {
            const char *dexts = device_string(devs[i], EGL_EXTENSIONS);
            int soft = has_ext(dexts, "EGL_MESA_device_software");
            if (soft != pass) continue;
            char what[96];
            snprintf(what, sizeof what, "device %d of %d (%s)", (int)i + 1, (int)n,
                     soft ? "software" : "hardware");
            EGLDisplay dpy = platform_display(EGL_PLATFORM_DEVICE_EXT, devs[i], NULL);
            rc = open_display(b, dpy, what, err);
            if (rc == 0) {
                b->software = soft;
                return 0;
            }
        }
    }
    return rc;
}

static int surfaceless(gl_backend *b, sd_err *err)
{
    PFNEGLGETPLATFORMDISPLAYEXTPROC platform_display = (PFNEGLGETPLATFORMDISPLAYEXTPROC)0;
    void *p = egl_proc("eglGetPlatformDisplayEXT");
    memcpy(&platform_display, &p, sizeof p);
    if (!platform_display)
        return sd_errf(err, SD_EUNSUP, "EGL: eglGetPlatformDisplayEXT is missing");
    EGLDisplay dpy = platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
    int rc = open_display(b, dpy, "surfaceless platform", err);
    if (rc < 0) return rc;
    /* the platform names no device: the current context's renderer says what it is */
    typedef const unsigned char *(*get_string_fn)(unsigned);
    get_string_fn get_string = (get_string_fn)0;
    p = egl_proc("glGetString");
    memcpy(&get_string, &p, sizeof p);
    b->software = get_string && gl_renderer_is_software(
                                    (const char *)get_string(0x1F01 /* GL_RENDERER */));
    return 0;
}

/* The display is left initialised: an EGL display is one per device and process, and
 * eglTerminate is not reference-counted (no EGL_KHR_display_reference in Mesa 22), so
 * terminating it would pull the ground from under every other context on that device, e.g. a
 * second renderer in the same process. The driver stays loaded until exit. */
static void egl_destroy(gl_backend *b)
{
    if (!b) return;
    if (b->dpy != EGL_NO_DISPLAY) {
        if (eglGetCurrentContext() == b->ctx)
            eglMakeCurrent(b->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        if (b->ctx != EGL_NO_CONTEXT) eglDestroyContext(b->dpy, b->ctx);
        if (b->surf != EGL_NO_SURFACE) eglDestroySurface(b->dpy, b->surf);
    }
    memset(b, 0, sizeof *b);
    free(b);
}

static int egl_create(gl_backend **out, sd_err *err)
{
    *out = NULL;
    gl_backend *b = calloc(1, sizeof *b);
    if (!b) return sd_errf(err, SD_ENOMEM, "out of memory for the EGL back end");
    b->dpy = EGL_NO_DISPLAY;
    b->ctx = EGL_NO_CONTEXT;
    b->surf = EGL_NO_SURFACE;
    const char *cexts = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!cexts) cexts = "";
    int rc = SD_EUNSUP;
    sd_err e1 = {0}, e2 = {0};
    if (has_ext(cexts, "EGL_EXT_platform_device") && has_ext(cexts, "EGL_EXT_device_enumeration"))
        rc = try_devices(b, &e1);
    else
        sd_errf(&e1, SD_EUNSUP, "EGL: no EGL_EXT_platform_device");
    if (rc < 0 && has_ext(cexts, "EGL_MESA_platform_surfaceless")) rc = surfaceless(b, &e2);
    else if (rc < 0) sd_errf(&e2, SD_EUNSUP, "EGL: no EGL_MESA_platform_surfaceless");
    if (rc < 0) {
        sd_errf(err, SD_EGL, "no EGL context: %s; %s", e1.msg, e2.msg);
        egl_destroy(b);
        return SD_EGL;
    }
    *out = b;
    return 0;
}

static int egl_make_current(gl_backend *b, sd_err *err)
{
    char en[40];
    if (!eglMakeCurrent(b->dpy, b->surf, b->surf, b->ctx))
        return sd_errf(err, SD_EGL, "eglMakeCurrent failed (%s)", egl_err_now(en, sizeof en));
    return 0;
}

static void *egl_getproc(void *b, const char *name)
{
    (void)b;
    return egl_proc(name);
}

static const char *egl_describe(const gl_backend *b)
{
    return b->desc;
}

static int egl_software(const gl_backend *b)
{
    return b->software;
}

const gl_backend_ops gl_backend_egl = {
    .name = "egl",
    .create = egl_create,
    .make_current = egl_make_current,
    .destroy = egl_destroy,
    .getproc = egl_getproc,
    .describe = egl_describe,
    .software = egl_software,
};
