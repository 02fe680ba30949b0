/* soft_host.c — the `soft` pipeline's host compositor (the host paths, host.h; see pipe_soft.c's
 * file comment): the soft discs projected by the GL and read back, composited by the host
 * paths' compositor (soft_cpu.h) either into a layer that soft_resolve puts over the target,
 * or, on an opaque 8-bit frame with no GL pass after the pipeline (rnd_draw.host_after), over
 * the read-back pixels in the pipeline's `after` hook, tested against the visibility keys the
 * stripes kept; and the binning on a thread of its own while the GL makes those keys. */
#include <pthread.h>
#include <stdint.h>
#include <string.h>

#include "host.h"
#include "soft_pipe.h"
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

/* soft__cpu_project: the host compositor's discs: soft_bin.comp PASS 0 over every set (as for
 * the sprites), read back into s->h_proj, one segment per set in the sets' order. Returns 0 or
 * SD_E*. */
int soft__cpu_project(rnd_kit *k, soft_state *s, const rnd_draw *d, const soft_cloud *sc,
                      const soft_order *o, sd_err *err)
{
    const gl_api *gl = k->gl;
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
        int rc = soft__project_set(k, s, d, sc, o, si, err);
        if (rc < 0) return rc;
        gl->MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, s->proj_buf);
        gl->GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)ss->nsoft * 32,
                             s->h_proj + at);
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
