/* soft_host.c — the `soft` pipeline's host compositor (the host paths, host.h; see pipe_soft.c's
 * file comment): the soft discs projected through the host paths (soft_proj.h) or by the GL and
 * read back, composited by the host paths' compositor (soft_cpu.h) either into a layer that
 * soft_resolve puts over the target,
 * or, on an opaque 8-bit frame with no GL pass after the pipeline (rnd_draw.host_after), over
 * the read-back pixels in the pipeline's `after` hook, tested against the visibility keys the
 * stripes kept; and the binning on a thread of its own while the GL makes those keys. */
#include <pthread.h>
#include <stdint.h>
#include <string.h>

#include "host.h"
#include "soft_pipe.h"
#include "soft_proj.h"
#include "splat_passes.h"

/* The host compositor composites at most this many bytes of float layer at a time (rows of a
 * band): a 1280x720 frame is one band; an 8192x8192 one, whose layer would be 1 GiB, sixteen. */
#define SOFT_CPU_LAYER (64ull << 20)

/* The binning of the host compositor (soft_cpu_bin) on a thread of its own, and its end. */
static void *bin_main(void *arg)
{
    soft_state *s = arg;
    s->bin_rc = s->host->soft_bin(&s->bin_job);
    return NULL;
}

void soft__bin_start(soft_state *s)
{
    s->bin_on = pthread_create(&s->bin_th, NULL, bin_main, s) == 0;
    if (!s->bin_on) bin_main(s); /* no thread: here, now */
}

int soft__bin_join(soft_state *s)
{
    if (s->bin_on) pthread_join(s->bin_th, NULL);
    s->bin_on = 0;
    return s->bin_rc;
}

/* host_project_set: soft_bin.comp PASS 0 through the host paths (soft_proj.h) for set si into out (8 floats
 * a disc): the set's positions, normals, radii and colour source mapped for reading (on a
 * software renderer the GL's own memory), then unmapped. Returns 0 or SD_EGL. */
static int host_project_set(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                            uint32_t si, float *out, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    const sp_params *p = d->params;
    const rnd_bufset *bs = &d->cloud->sets[si];
    const int attr[4] = {RND_ATTR_POS, RND_ATTR_NORMAL, RND_ATTR_RADIUS,
                         rnd_kit_color_source(p->color)};
    const void *m[4] = {NULL, NULL, NULL, NULL};
    int rc = 0;
    for (int a = 0; a < 4 && rc == 0; a++) {
        uint64_t bytes = (uint64_t)bs->n * (uint64_t)rnd_attrs[attr[a]].components * 4;
        gl->BindBuffer(GL_COPY_READ_BUFFER, bs->buf[attr[a]]);
        m[a] = gl->MapBufferRange(GL_COPY_READ_BUFFER, 0, (GLsizeiptr)(bytes ? bytes : 4),
                                  GL_MAP_READ_BIT);
        if (!m[a] && (rc = gl_check(gl, "soft: mapping a buffer set", err)) == 0)
            rc = sd_errf(err, SD_EGL, "soft: mapping buffer set %u's %s failed", si,
                         rnd_attrs[attr[a]].name);
    }
    if (rc == 0) {
        soft_proj_job job = {.pos = m[0], .nrm = m[1], .rad = m[2], .src = m[3],
                             .f = sc->fields.sets[si].f, .idx = sc->sets[si].idx,
                             .n = sc->sets[si].nsoft, .width = v->width, .height = v->height,
                             .scale = p->splat_scale, .znear = v->znear, .zfar = v->zfar,
                             .t = p->t, .lm = p->l_m, .color = p->color, .out = out,
                             .threads = s->threads};
        memcpy(job.view, v->view, sizeof job.view);
        memcpy(job.proj, v->proj, sizeof job.proj);
        soft_light(p, job.light);
        k->host->soft_project(&job);
    }
    for (int a = 0; a < 4; a++)
        if (m[a]) {
            gl->BindBuffer(GL_COPY_READ_BUFFER, bs->buf[attr[a]]);
            gl->UnmapBuffer(GL_COPY_READ_BUFFER);
        }
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    return rc;
}

/* soft__cpu_project: the host compositor's discs, one segment per set in the sets' order, into
 * s->h_proj: projected through the host paths (not for color=field or color=scan, whose
 * colour map is a shader polynomial, nor under rnd_pipe_opts.soft_proj_gl), or by the GL (soft_bin.comp PASS 0,
 * as for the sprites) and read back. Returns 0 or SD_E*. */
int soft__cpu_project(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                      const soft_order *o, sd_err *err)
{
    const gl_api *gl = k->gl;
    int host = k->host->soft_project && d->params->color != SP_COLOR_FIELD &&
               d->params->color != SP_COLOR_SCAN && !k->opts.soft_proj_gl;
    uint32_t nsets = sc->nsets < 64 ? sc->nsets : 64;
    size_t total = 0;
    for (uint32_t si = 0; si < nsets; si++) total += sc->sets[si].nsoft;
    if (soft_cpu_grow((void **)&s->h_proj, &s->h_proj_cap, 8 * total, sizeof(float)))
        return sd_errf(err, SD_ENOMEM, "soft: out of memory for %zu soft discs", total);
    s->nsegs = 0;
    size_t at = 0;
    for (uint32_t oi = 0; oi < nsets; oi++) {
        uint32_t si = o->set_order[oi];
        const soft_set *ss = &sc->sets[si];
        if (ss->nsoft == 0) continue;
        int rc = host ? host_project_set(k, s, d, sc, si, s->h_proj + at, err)
                      : soft__project_set(k, s, d, sc, o, si, err);
        if (rc < 0) return rc;
        if (!host) {
            gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
            gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->proj_buf);
            gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)ss->nsoft * 32,
                                 s->h_proj + at);
        }
        s->segs[s->nsegs++] = (soft_cpu_seg){s->h_proj + at, ss->idx + (size_t)(1 + o->axis) *
                                             ss->nsoft, ss->nsoft, o->rev};
        at += 8 * (size_t)ss->nsoft;
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    return 0;
}

/* soft__cpu_blend: the host compositor over rows [y0, y0 + n): the stripe's visibility keys read back (keys,
 * yb, nb as draw_soft), then in bands of at most SOFT_CPU_LAYER bytes of layer (and of a storage
 * block) the discs composited on the host (soft_cpu.h), the rows they reached uploaded as the
 * layer and put over the target by soft_resolve. Returns 0 or SD_E*. */
int soft__cpu_blend(rnd_kit *k, soft_state *s, const rnd_draw *d, int keys, int y0, int n,
                     int yb, int nb, sd_err *err)
{
    const gl_api *gl = k->gl;
    const rnd_view *v = d->view;
    size_t w = (size_t)v->width;
    if (s->nsegs == 0) return 0; /* no soft disc */
    uint64_t cap = SOFT_CPU_LAYER < (uint64_t)k->max_ssbo ? SOFT_CPU_LAYER : (uint64_t)k->max_ssbo;
    uint64_t band = cap / (w * 16);
    if (band < 1) band = 1;
    if (band > (uint64_t)n) band = (uint64_t)n;
    if (soft_cpu_grow((void **)&s->h_layer, &s->h_layer_cap, w * band * 4, sizeof(float)) ||
        (keys && soft_cpu_grow((void **)&s->h_keys, &s->h_keys_cap, w * (size_t)nb, 4)))
        return sd_errf(err, SD_ENOMEM, "soft: out of memory for a %dx%d layer", v->width,
                       (int)band);
    if (keys) {
        uint64_t have = 0;
        GLuint kbuf = splat__keys_buffer(s->splat, &have);
        if (have < (uint64_t)w * (uint64_t)nb * 4)
            return sd_errf(err, SD_EINVAL, "soft: the visibility keys hold %llu bytes, not the "
                           "%d rows of the stripe", (unsigned long long)have, nb);
        gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, kbuf);
        gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)(w * (size_t)nb * 4),
                             s->h_keys);
    }
    for (int b0 = y0; b0 < y0 + n; b0 += (int)band) {
        int bn = y0 + n - b0 < (int)band ? y0 + n - b0 : (int)band;
        soft_cpu_job job = {.segs = s->segs, .nsegs = s->nsegs, .lambda = d->params->lambda,
                            .width = v->width, .y0 = b0, .rows = bn,
                            .keys = keys ? s->h_keys : NULL, .kb = yb, .nk = nb,
                            .layer = s->h_layer, .mem = &s->mem, .threads = s->threads};
        if (k->host->soft_composite(&job) != 0)
            return sd_errf(err, SD_ENOMEM, "soft: out of memory compositing the soft discs");
        if (job.touched[0] < 0) continue; /* no disc reached these rows */
        int r0 = job.touched[0], rn = job.touched[1] - job.touched[0] + 1;
        uint64_t bytes = (uint64_t)w * (uint64_t)rn * 16;
        soft__buf_tex(gl, &s->layer_buf, &s->layer_bytes, bytes, s->layer_tex, GL_RGBA32F);
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->layer_buf);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)bytes,
                          s->h_layer + (size_t)(r0 - b0) * w * 4);
        soft__resolve_layer(k, s, d, r0, rn);
    }
    return 0;
}

/* soft__keep_keys: the host compositor with rnd_draw.host_after: the stripe's own rows [y0, y0 + n) of its
 * visibility keys (whose buffer starts at row yb) read back into the frame's keys, for
 * soft__after. Returns 0 or SD_E*. */
int soft__keep_keys(rnd_kit *k, soft_state *s, const rnd_draw *d, int y0, int n, int yb,
                     sd_err *err)
{
    const gl_api *gl = k->gl;
    size_t w = (size_t)d->view->width;
    if (soft_cpu_grow((void **)&s->h_fkeys, &s->h_fkeys_cap, w * (size_t)d->view->height, 4))
        return sd_errf(err, SD_ENOMEM, "soft: out of memory for a %dx%d frame's keys",
                       d->view->width, d->view->height);
    uint64_t have = 0;
    GLuint kbuf = splat__keys_buffer(s->splat, &have);
    uint64_t off = (uint64_t)(y0 - yb) * w * 4, bytes = (uint64_t)n * w * 4;
    if (have < off + bytes)
        return sd_errf(err, SD_EINVAL, "soft: the visibility keys hold %llu bytes, not the %d "
                       "rows of the stripe", (unsigned long long)have, n);
    gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, kbuf);
    gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)off, (GLsizeiptr)bytes,
                         s->h_fkeys + (size_t)y0 * w);
    return 0;
}

/* soft__after: the host compositor with rnd_draw.host_after: the discs soft__cpu_project made composited over
 * the read-back frame (soft_cpu.h), tile by tile, tested against the keys soft__keep_keys kept: no
 * layer to upload and no GL pass to put it over the target. Returns 0 or SD_ENOMEM. */
int soft__after(rnd_kit *k, void *state, const rnd_draw *d, uint8_t *rgba8, sd_err *err)
{
    soft_state *s = state;
    const rnd_view *v = d->view;
    if (soft__bin_join(s) != 0)
        return sd_errf(err, SD_ENOMEM, "soft: out of memory binning the soft discs");
    soft_cpu_job *job = &s->bin_job;
    job->lambda = d->params->lambda;
    job->keys = s->after_keys ? s->h_fkeys : NULL, job->kb = 0, job->nk = v->height;
    job->rgba8 = rgba8;
    return k->host->soft_blend(job) != 0
               ? sd_errf(err, SD_ENOMEM, "soft: out of memory blending the soft discs")
               : 0;
}
