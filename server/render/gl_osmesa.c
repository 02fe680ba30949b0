/* gl_osmesa.c — the OSMesa back end: a core profile context from OSMesaCreateContextAttribs
 * (4.5, else 4.3). OSMesaMakeCurrent needs a colour buffer, so the context draws into a tiny
 * private one; all rendering goes into FBOs anyway. libOSMesa does not export every 4.5 entry
 * point (no glCreateBuffers), so GL functions come from OSMesaGetProcAddress. */
#include <GL/osmesa.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl_backend.h"

enum { OSM_BUF_SIDE = 4 };

struct gl_backend {
    OSMesaContext ctx;
    unsigned char buf[OSM_BUF_SIDE * OSM_BUF_SIDE * 4];
    char desc[96];
};

static int osm_make_current(gl_backend *b, sd_err *err)
{
    if (!OSMesaMakeCurrent(b->ctx, b->buf, GL_UNSIGNED_BYTE, OSM_BUF_SIDE, OSM_BUF_SIDE))
        return sd_errf(err, SD_EGL, "OSMesaMakeCurrent failed");
    return 0;
}

static void osm_destroy(gl_backend *b)
{
    if (!b) return;
    if (b->ctx) {
        if (OSMesaGetCurrentContext() == b->ctx) OSMesaMakeCurrent(NULL, NULL, 0, 0, 0);
        OSMesaDestroyContext(b->ctx);
    }
    memset(b, 0, sizeof *b);
    free(b);
}

static int osm_create(gl_backend **out, sd_err *err)
{
    *out = NULL;
    gl_backend *b = calloc(1, sizeof *b);
    if (!b) return sd_errf(err, SD_ENOMEM, "out of memory for the OSMesa back end");
    static const int versions[][2] = {{4, 5}, {4, 3}};
    int vi = 0;
    for (; vi < 2 && !b->ctx; vi++) {
        const int attr[] = {OSMESA_FORMAT, OSMESA_RGBA,
                            OSMESA_DEPTH_BITS, 0,
                            OSMESA_STENCIL_BITS, 0,
                            OSMESA_ACCUM_BITS, 0,
                            OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                            OSMESA_CONTEXT_MAJOR_VERSION, versions[vi][0],
                            OSMESA_CONTEXT_MINOR_VERSION, versions[vi][1],
                            0};
        b->ctx = OSMesaCreateContextAttribs(attr, NULL);
    }
    if (!b->ctx) {
        free(b);
        return sd_errf(err, SD_EGL, "OSMesaCreateContextAttribs: no OpenGL 4.3 core context");
    }
    snprintf(b->desc, sizeof b->desc, "OSMesa, GL %d.%d core", versions[vi - 1][0],
             versions[vi - 1][1]);
    int rc = osm_make_current(b, err);
    if (rc < 0) {
        osm_destroy(b);
        return rc;
    }
    *out = b;
    return 0;
}

static void *osm_getproc(void *b, const char *name)
{
    (void)b;
    OSMESAproc f = OSMesaGetProcAddress(name);
    void *p;
    memcpy(&p, &f, sizeof p);
    return p;
}

static const char *osm_describe(const gl_backend *b)
{
    return b->desc;
}

/* OSMesa is Mesa's off-screen software renderer (llvmpipe, softpipe or swrast beneath). */
static int osm_software(const gl_backend *b)
{
    (void)b;
    return 1;
}

const gl_backend_ops gl_backend_osmesa = {
    .name = "osmesa",
    .create = osm_create,
    .make_current = osm_make_current,
    .destroy = osm_destroy,
    .getproc = osm_getproc,
    .describe = osm_describe,
    .software = osm_software,
};
