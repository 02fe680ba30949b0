/* render_thread.c — the render, encoder and prep workers of the daemon (see render_thread.h).
 *
 * One mutex guards all shared state (slots, queues, the frame pool, events); the work itself
 * (prep, upload, render, encode, pack) runs outside it. Three condition variables wake the
 * three threads. Frames: a pool of RT_NFRAMES rnd_frames; the render thread fills a free one,
 * the encoder thread encodes it and returns it, so render of frame k+1 overlaps encode of k. */
#include "view.h"
#include "render_thread.h"

#include <errno.h>
#include <malloc.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "encode.h"
#include "preview.h"
#include "ev.h"
#include "srv.h"

enum { RT_NFRAMES = 2, RT_MAX_PROV = 64 };

/* Large frames' memory is given back when the workers are idle: once a frame of more than
 * RT_TRIM_PX pixels has been made, RT_TRIM_IDLE_MS with nothing to render or encode frees the
 * frame pool's buffers, the renderer's output framebuffers and the encoder's buffers (each made
 * again at the next frame's size), then malloc_trim returns the heap's free pages. Frames up to
 * 4K UHD keep theirs, so an interactive client never pays for it. */
enum { RT_TRIM_PX = 3840 * 2160, RT_TRIM_IDLE_MS = 1000 };

/* A provisional cloud and the full cloud that replaced it (0 until then): requests still
 * naming the provisional id are drawn from the replacement. Render thread, mu held. */
typedef struct rt_prov {
    uint32_t job, prov_id, final_id;
} rt_prov;

typedef struct rt_slot {
    uint32_t id;                /* 0: free */
    int has_latest;
    rt_request latest;
    rt_request q[RT_QUEUE_MAX];
    int qhead, qn;
    int outstanding;            /* rendering + encoding + waiting at the loop */
    int stream_blocked;         /* a streamed frame waits unsent at the loop */
    uint64_t cost[RT_MAX_OUTSTANDING]; /* rt_frame_cost of each outstanding frame, oldest at
                                        * cost_head: frames leave in the order they started
                                        * (one render thread, one FIFO encoder, in-order
                                        * delivery), so a release gives back the oldest */
    int cost_head;
    uint64_t sending;           /* the cost of its frame being written to the socket: it left
                                 * the outstanding count (the next one may render) but its bytes
                                 * stay held until written (rt_frame_sent) */
    int has_prefetch;           /* a PREFETCH waits for the render thread (latest wins) */
    int npcams;
    uint32_t pcloud;
    sp_params pparams;
    rnd_camera pcams[PROTO_MAX_PREFETCH];
} rt_slot;

typedef struct rt_encjob {
    int frame;                  /* index into frames */
    rt_frame_meta meta;
    sp_params params;
} rt_encjob;

typedef struct rt_prepjob {
    uint32_t job;
    char *path;
    pc_prepared *prep;          /* set once prepared, waiting for upload */
    lod_cloud *lod;             /* or this, for a cloud in the LOD form */
    int provisional;            /* prep is a provisional cloud of job (preview.h) */
    int previewed;              /* a provisional cloud of this job was queued for upload */
    int failed;                 /* the prep failed after that (err): the render thread
                                 * releases the provisional cloud and posts FAILED */
    sd_err err;
    rt_cloud_info info;
    struct rt_prepjob *next;
} rt_prepjob;

struct rt_ctx {
    rt_desc d;
    ev_loop *loop;
    pthread_mutex_t mu;
    pthread_cond_t cv_render, cv_enc, cv_prep, cv_init;
    rt_slot *slots;
    int nslots, rr_next;
    rnd_frame frames[RT_NFRAMES];
    int frame_busy[RT_NFRAMES];
    rt_encjob encq[RT_NFRAMES];
    int enc_n, encoding, rendering;
    rt_prepjob *prep_head, *prep_tail;   /* waiting for prep */
    rt_prepjob *up_head, *up_tail;       /* prepared, waiting for upload */
    int prepping;
    rt_event *ev_head, *ev_tail;
    rt_prov prov[RT_MAX_PROV];          /* the latest provisional clouds, oldest dropped */
    int nprov;
    int stop, render_done;
    int enc_trim;               /* the encoder gives its buffers back (set by the render thread) */
    int init_state;                      /* 0 pending, 1 ok, -1 failed */
    sd_err init_err;
    char renderer[256], backend[32];
    uint64_t gpu_budget;        /* the renderer's cloud budget, bytes */
    uint64_t frame_budget;      /* --max-frame-bytes: frames outstanding may hold this much */
    uint64_t frame_held;        /* rt_frame_cost of every outstanding frame */
    pthread_t th_render, th_enc, th_prep;
    int started_render, started_enc, started_prep;
};

static uint64_t now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

/* post: appends ev to the event list (mu held) and wakes the loop. */
static void post(rt_ctx *rt, rt_event *ev)
{
    ev->next = NULL;
    if (rt->ev_tail) rt->ev_tail->next = ev;
    else rt->ev_head = ev;
    rt->ev_tail = ev;
    ev_wakeup(rt->loop);
}

static rt_slot *slot_of(rt_ctx *rt, uint32_t id)
{
    uint32_t i = id & 0xffffu;
    if (id == 0 || i >= (uint32_t)rt->nslots || rt->slots[i].id != id) return NULL;
    return &rt->slots[i];
}

uint64_t rt_frame_cost(const rt_request *rq)
{
    /* Bytes per pixel of the encoded output at most (JPEG's worst case stays under 3; LZ4
     * grows incompressible data by under 0.5 %: 4.02 rounded up; EXR: half RGBA + float Z). */
    static const unsigned enc_bpp[] = {[SP_FMT_JPEG] = 3, [SP_FMT_PNG] = 5, [SP_FMT_LZ4] = 5,
                                       [SP_FMT_RAW] = 4, [SP_FMT_EXR] = 12};
    unsigned f = rq->params.format >= 0 && rq->params.format <= SP_FMT_EXR
                     ? (unsigned)rq->params.format : SP_FMT_EXR;
    uint64_t px = (uint64_t)(rq->cam.width > 0 ? rq->cam.width : RND_DEFAULT_WIDTH) *
                  (uint64_t)(rq->cam.height > 0 ? rq->cam.height : RND_DEFAULT_HEIGHT);
    /* The read-back colour and depth (8 bytes a pixel), the encoder's output, and the packed
     * FRAME message it is copied into; plus the fixed headers. */
    return px * (8 + 2 * (uint64_t)enc_bpp[f]) + 65536;
}

/* next_request: the request slot s would render next (its queue first), or NULL. */
static const rt_request *next_request(const rt_slot *s)
{
    if (!s->id || s->outstanding >= RT_MAX_OUTSTANDING) return NULL;
    if (s->qn) return &s->q[s->qhead];
    if (s->has_latest && !s->stream_blocked) return &s->latest;
    return NULL;
}

/* fits: whether a frame of cost c may start now under --max-frame-bytes. With nothing held it
 * always may (the loop refuses single frames over the budget before they are submitted). */
static int fits(const rt_ctx *rt, uint64_t c)
{
    return rt->frame_held == 0 || rt->frame_held + c <= rt->frame_budget;
}

/* pick: the next slot (round-robin) with work and room for a frame; fills rq and stream. When
 * that slot's frame does not fit the frame budget, nobody is picked (until frames are
 * released): later slots' smaller frames do not overtake it, so a large frame cannot starve.
 * mu held. */
static rt_slot *pick(rt_ctx *rt, rt_request *rq, int *stream)
{
    for (int k = 0; k < rt->nslots; k++) {
        int i = (rt->rr_next + k) % rt->nslots;
        rt_slot *s = &rt->slots[i];
        const rt_request *nx = next_request(s);
        if (!nx) continue;
        if (!fits(rt, rt_frame_cost(nx))) return NULL;
        if (s->qn) {
            *rq = s->q[s->qhead];
            s->qhead = (s->qhead + 1) % RT_QUEUE_MAX;
            s->qn--;
            *stream = 0;
        } else {
            *rq = s->latest;
            s->has_latest = 0;
            *stream = 1;
        }
        rt->rr_next = (i + 1) % rt->nslots;
        return s;
    }
    return NULL;
}

/* slot_hold: s starts a frame of cost c. mu held. */
static void slot_hold(rt_ctx *rt, rt_slot *s, uint64_t c)
{
    s->cost[(s->cost_head + s->outstanding) % RT_MAX_OUTSTANDING] = c;
    s->outstanding++;
    rt->frame_held += c;
}

/* slot_release: s's oldest outstanding frame is gone (sent, dropped or failed). mu held. */
static void slot_release(rt_ctx *rt, rt_slot *s)
{
    if (s->outstanding <= 0) return;
    uint64_t c = s->cost[s->cost_head];
    rt->frame_held = rt->frame_held >= c ? rt->frame_held - c : 0;
    s->cost_head = (s->cost_head + 1) % RT_MAX_OUTSTANDING;
    s->outstanding--;
}

static int free_frame(rt_ctx *rt)
{
    for (int i = 0; i < RT_NFRAMES; i++)
        if (!rt->frame_busy[i]) return i;
    return -1;
}

/* big_idle: whether the workers are idle (no frame rendering, queued or encoding) while the
 * frame pool holds a frame of more than RT_TRIM_PX pixels. mu held. */
static int big_idle(const rt_ctx *rt)
{
    if (rt->enc_n || rt->encoding) return 0;
    int big = 0;
    for (int i = 0; i < RT_NFRAMES; i++) {
        if (rt->frame_busy[i]) return 0;
        big |= (uint64_t)rt->frames[i].width * (uint64_t)rt->frames[i].height > RT_TRIM_PX;
    }
    return big;
}

static int render_once(rt_ctx *rt, rnd_ctx *rnd, const rt_request *rq, rnd_frame *f, sd_err *err);
static int prov_resolve(const rt_ctx *rt, rt_request *rq);

/* trim: gives a large frame's memory back (RT_TRIM_PX): the pool's buffers, the renderer's
 * targets and the pipelines' scratch here (render thread, workers idle), the encoder's in its
 * own thread. last: the last request rendered, drawn again at 1x1 so that the driver lets go
 * of what the large frame had bound (rnd_release_targets). Called with mu held; the work runs
 * without it (only this thread touches the pool frames while none is busy). */
static void trim(rt_ctx *rt, rnd_ctx *rnd, const rt_request *last)
{
    rt_request one = {0};
    int redraw = last && !(rt->d.hooks && rt->d.hooks->render); /* a local renderer's state */
    if (redraw) {
        one = *last;
        one.cam.width = one.cam.height = 1;
        one.refine = 0;
        prov_resolve(rt, &one);
    }
    rt->rendering = 1;
    pthread_mutex_unlock(&rt->mu);
    for (int i = 0; i < RT_NFRAMES; i++) rnd_frame_free(&rt->frames[i]);
    rnd_release_targets(rnd);
    if (redraw) {
        rnd_frame f = {0};
        sd_err err = {0};
        render_once(rt, rnd, &one, &f, &err); /* a cloud gone since: nothing to let go */
        rnd_frame_free(&f);
    }
    malloc_trim(0);
    pthread_mutex_lock(&rt->mu);
    rt->rendering = 0;
    rt->enc_trim = 1;
    pthread_cond_signal(&rt->cv_enc);
}

static int has_work(rt_ctx *rt)
{
    if (rt->up_head) return 1;
    for (int k = 0; k < rt->nslots; k++)
        if (rt->slots[k].has_prefetch) return 1;
    if (free_frame(rt) < 0) return 0;
    /* The same order as pick: the first slot with work decides. */
    for (int k = 0; k < rt->nslots; k++) {
        const rt_request *nx = next_request(&rt->slots[(rt->rr_next + k) % rt->nslots]);
        if (nx) return fits(rt, rt_frame_cost(nx));
    }
    return 0;
}

/* prep_prog: where a cloud job's progress goes (the job's events), throttled per phase. */
typedef struct prep_prog {
    rt_ctx *rt;
    uint32_t job;
    int phase;                  /* the last phase reported (-1: none) */
    uint64_t last_us;
} prep_prog;

static void on_progress(void *user, int phase, double fraction);

/* prov_add: records provisional cloud id of job (mu held). */
static void prov_add(rt_ctx *rt, uint32_t job, uint32_t id)
{
    if (rt->nprov == RT_MAX_PROV) {
        memmove(rt->prov, rt->prov + 1, sizeof rt->prov[0] * (RT_MAX_PROV - 1));
        rt->nprov--;
    }
    rt->prov[rt->nprov++] = (rt_prov){job, id, 0};
}

/* prov_finish: job's full cloud is final_id (0: it failed); returns the provisional id to
 * release, 0 when job had none (mu held). */
static uint32_t prov_finish(rt_ctx *rt, uint32_t job, uint32_t final_id)
{
    for (int i = 0; i < rt->nprov; i++)
        if (rt->prov[i].job == job && rt->prov[i].final_id == 0 && rt->prov[i].prov_id) {
            uint32_t old = rt->prov[i].prov_id;
            rt->prov[i].final_id = final_id;
            if (!final_id) rt->prov[i].prov_id = 0; /* its requests fail as of an unknown cloud */
            return old;
        }
    return 0;
}

/* prov_resolve: rq's cloud after swaps; 1 when that is still a provisional cloud (mu held). */
static int prov_resolve(const rt_ctx *rt, rt_request *rq)
{
    for (int i = 0; i < rt->nprov; i++)
        if (rt->prov[i].prov_id && rt->prov[i].prov_id == rq->cloud_id) {
            if (!rt->prov[i].final_id) return 1;
            rq->cloud_id = rt->prov[i].final_id;
            return 0;
        }
    return 0;
}

/* do_upload: uploads one prepared cloud (mu not held), reports the upload phase complete, and
 * posts READY or FAILED. */
static void do_upload(rt_ctx *rt, rnd_ctx *rnd, rt_prepjob *j)
{
    rt_event *ev = calloc(1, sizeof *ev);
    sd_err err = {0};
    const rt_hooks *h = rt->d.hooks;
    /* the renderer (or the hook) owns it now, even on failure; a LOD cloud never reaches a
     * hook (splatd --mpi prepares every cloud flat) */
    int64_t id = j->failed ? (err = j->err, (int64_t)-1)
                 : j->lod ? rnd_adopt_lod(rnd, j->lod, &err)
                 : h && h->adopt && !j->provisional ? h->adopt(h->user, rnd, j->path, j->prep, &err)
                                                    : rnd_adopt(rnd, j->prep, &err);
    j->prep = NULL;
    j->lod = NULL;
    if (j->provisional) {
        pthread_mutex_lock(&rt->mu);
        if (id > 0) prov_add(rt, j->job, (uint32_t)id);
        if (ev && id > 0) {
            ev->kind = RT_EV_CLOUD_PROVISIONAL;
            ev->job = j->job;
            ev->info = j->info;
            ev->cloud_id = (uint32_t)id;
            post(rt, ev);
        } else {
            free(ev); /* no first image: the full prep goes on and answers */
        }
        pthread_mutex_unlock(&rt->mu);
        free(j->path);
        free(j);
        return;
    }
    /* The swap: from here on the job's provisional cloud is drawn from the full one. */
    pthread_mutex_lock(&rt->mu);
    uint32_t old = prov_finish(rt, j->job, id > 0 ? (uint32_t)id : 0);
    pthread_mutex_unlock(&rt->mu);
    if (old) {
        rnd_release(rnd, old);
        srv_log(NULL, NULL, "first image of %s released: %s", j->path,
                id > 0 ? "the full cloud replaces it" : "the prep failed");
    }
    if (id > 0) {
        prep_prog pp = {.rt = rt, .job = j->job, .phase = -1};
        on_progress(&pp, PROTO_PHASE_UPLOAD, 1.0);
    }
    pthread_mutex_lock(&rt->mu);
    if (ev) {
        ev->job = j->job;
        ev->info = j->info;
        if (id > 0) {
            ev->kind = RT_EV_CLOUD_READY;
            ev->cloud_id = (uint32_t)id;
        } else {
            ev->kind = RT_EV_CLOUD_FAILED;
            ev->err = err;
        }
        post(rt, ev);
    }
    pthread_mutex_unlock(&rt->mu);
    free(j->path);
    free(j);
}

/* render_once: one frame of rq into f, through the distributed renderer's hook when there is
 * one (splatd --mpi), else rnd_render. */
static int render_once(rt_ctx *rt, rnd_ctx *rnd, const rt_request *rq, rnd_frame *f, sd_err *err)
{
    const rt_hooks *h = rt->d.hooks;
    int want_float = rq->params.format == SP_FMT_EXR;
    f->complete = 1; /* a hook's frame is a flat cloud's: whole */
    f->flags = 0;
    if (h && h->render)
        return h->render(h->user, rnd, rq->cloud_id, &rq->cam, &rq->params, want_float, f, err);
    return rnd_render(rnd, rq->cloud_id, &rq->cam, &rq->params, want_float, f, err);
}

static void *render_main(void *arg)
{
    rt_ctx *rt = arg;
    sd_err err = {0};
    rnd_ctx *rnd = rnd_create(&rt->d.rnd, &err);
    pthread_mutex_lock(&rt->mu);
    if (!rnd) {
        rt->init_err = err;
        rt->init_state = -1;
        rt->render_done = 1;
        pthread_cond_broadcast(&rt->cv_init);
        pthread_cond_broadcast(&rt->cv_enc);
        pthread_mutex_unlock(&rt->mu);
        return NULL;
    }
    snprintf(rt->renderer, sizeof rt->renderer, "%s", rnd_renderer_string(rnd));
    snprintf(rt->backend, sizeof rt->backend, "%s", rnd_backend_name(rnd));
    rnd_stats st;
    rnd_get_stats(rnd, &st);
    rt->gpu_budget = st.budget;
    rt->init_state = 1;
    pthread_cond_broadcast(&rt->cv_init);
    int prefetching = 0; /* a LOD cloud's prefetch has nodes left to load and upload */
    rt_request last_rq;  /* the last request rendered (trim draws it again at 1x1) */
    int have_last = 0;
    for (;;) {
        while (!rt->stop && !has_work(rt)) {
            if (!prefetching && big_idle(rt)) {
                /* A large frame's buffers wait RT_TRIM_IDLE_MS for another frame, then go. */
                struct timespec ts;
                clock_gettime(CLOCK_REALTIME, &ts);
                ts.tv_sec += RT_TRIM_IDLE_MS / 1000;
                ts.tv_nsec += (long)(RT_TRIM_IDLE_MS % 1000) * 1000000L;
                if (ts.tv_nsec >= 1000000000L) ts.tv_sec++, ts.tv_nsec -= 1000000000L;
                if (pthread_cond_timedwait(&rt->cv_render, &rt->mu, &ts) == ETIMEDOUT &&
                    !rt->stop && !has_work(rt) && big_idle(rt))
                    trim(rt, rnd, have_last ? &last_rq : NULL);
                continue;
            }
            if (!prefetching) {
                pthread_cond_wait(&rt->cv_render, &rt->mu);
                continue;
            }
            /* idle: upload what the loaders read ahead, hand them the next nodes, and look
             * again in 5 ms (or at once when work arrives) */
            rt->rendering = 1;
            pthread_mutex_unlock(&rt->mu);
            int more = rnd_lod_idle(rnd, &err);
            pthread_mutex_lock(&rt->mu);
            rt->rendering = 0;
            prefetching = more > 0;
            if (prefetching && !rt->stop && !has_work(rt)) {
                struct timespec ts;
                clock_gettime(CLOCK_REALTIME, &ts);
                ts.tv_nsec += 5000000L;
                if (ts.tv_nsec >= 1000000000L) ts.tv_sec++, ts.tv_nsec -= 1000000000L;
                pthread_cond_timedwait(&rt->cv_render, &rt->mu, &ts);
            }
        }
        if (rt->stop) break;
        rt_slot *ps = NULL;
        for (int k = 0; k < rt->nslots && !ps; k++)
            if (rt->slots[k].has_prefetch) ps = &rt->slots[k];
        if (ps) {
            /* a PREFETCH: the nodes of its cameras become the cloud's prefetch queue */
            rnd_camera cams[PROTO_MAX_PREFETCH];
            int n = ps->npcams;
            rt_request cr = {.cloud_id = ps->pcloud};
            prov_resolve(rt, &cr); /* a provisional cloud's id names its replacement */
            uint32_t cloud = cr.cloud_id;
            sp_params params = ps->pparams;
            memcpy(cams, ps->pcams, (size_t)n * sizeof *cams);
            ps->has_prefetch = 0;
            pthread_mutex_unlock(&rt->mu);
            sd_err perr = {0};
            int q = rnd_lod_prefetch(rnd, cloud, cams, n, &params, &perr);
            pthread_mutex_lock(&rt->mu);
            if (q > 0) prefetching = 1;
            continue;
        }
        if (rt->up_head) {
            rt_prepjob *j = rt->up_head;
            rt->up_head = j->next;
            if (!rt->up_head) rt->up_tail = NULL;
            rt->rendering = 1;
            pthread_mutex_unlock(&rt->mu);
            do_upload(rt, rnd, j);
            pthread_mutex_lock(&rt->mu);
            rt->rendering = 0;
            continue;
        }
        rt_request rq;
        int stream = 0;
        int fi = free_frame(rt);
        rt_slot *s = fi >= 0 ? pick(rt, &rq, &stream) : NULL;
        if (!s) continue;
        slot_hold(rt, s, rt_frame_cost(&rq));
        int prov = prov_resolve(rt, &rq);
        if (prov) {
            /* a provisional cloud has no normals, radii or F: `points`, in its colours */
            rq.params.pipeline = SP_PIPE_POINTS;
            if (rq.params.color == SP_COLOR_FIELD || rq.params.color == SP_COLOR_NORMAL)
                rq.params.color = SP_COLOR_RGB;
        }
        rt->frame_busy[fi] = 1;
        rt->rendering = 1;
        rt_encjob job = {.frame = fi, .params = rq.params};
        job.meta.client = s->id;
        job.meta.req_seq = rq.req_seq;
        job.meta.camera_seq = rq.camera_seq;
        job.meta.stream = stream;
        job.meta.pipeline = rq.params.pipeline;
        job.meta.format = rq.params.format;
        job.meta.provisional = prov;
        pthread_mutex_unlock(&rt->mu);

        rnd_frame *f = &rt->frames[fi];
        if (rq.refine) rnd_lod_wait(rnd, rq.cloud_id, 1000); /* until a node more is ready */
        /* A RENDER of a LOD cloud answers the complete frame (unless lod_first): its nodes are
         * loaded first, without drawing the frame again after each of them */
        int rc = 0;
        if (!stream && !rq.params.lod_first && !(rt->d.hooks && rt->d.hooks->render))
            rc = rnd_lod_settle(rnd, rq.cloud_id, &rq.cam, &rq.params, 60000, &err);
        if (rc >= 0) rc = render_once(rt, rnd, &rq, f, &err);
        /* Should the settling above have stopped short (time, a view the pool cannot hold),
         * frames load the rest, a few nodes each. The bound only guards against a view whose
         * nodes cannot all be made resident. */
        uint64_t spent = f->render_us;
        for (int again = 0; rc == 0 && !stream && !f->complete && !rq.params.lod_first &&
                            again < 100000; again++) {
            rnd_lod_wait(rnd, rq.cloud_id, 1000);
            rc = render_once(rt, rnd, &rq, f, &err);
            spent += f->render_us;
        }
        if (rc == 0) f->render_us = spent;
        pthread_mutex_lock(&rt->mu);
        rt->rendering = 0;
        if (rc == SD_ESTALE) {
            /* The cloud's cache file changed under the daemon: the cloud is gone (its data
             * cannot be trusted); the loop forgets it, and the next OPEN rebuilds it. */
            pthread_mutex_unlock(&rt->mu);
            rnd_release(rnd, rq.cloud_id);
            pthread_mutex_lock(&rt->mu);
        }
        if (rc != 0) {
            rt->frame_busy[fi] = 0;
            rt_slot *s2 = slot_of(rt, job.meta.client);
            if (s2) slot_release(rt, s2);
            rt_event *ev = calloc(1, sizeof *ev);
            if (ev) {
                ev->kind = RT_EV_FRAME_FAILED;
                ev->meta = job.meta;
                ev->err = err;
                post(rt, ev);
            }
            continue;
        }
        last_rq = rq;
        have_last = 1;
        job.meta.width = f->width;
        job.meta.height = f->height;
        job.meta.render_us = f->render_us;
        job.meta.readback_us = f->readback_us;
        job.meta.points_drawn = f->points_drawn;
        job.meta.flags = f->flags;
        job.meta.complete = f->complete;
        /* Progressive refinement: a streamed frame that missed nodes is followed by another of
         * the same request, unless a newer one is pending already. */
        if (stream && !f->complete && !s->has_latest) {
            s->latest = rq;
            s->latest.refine = 1;
            s->has_latest = 1;
        }
        rt->encq[rt->enc_n++] = job;
        pthread_cond_signal(&rt->cv_enc);
    }
    rt->render_done = 1;
    pthread_cond_broadcast(&rt->cv_enc);
    /* The encoder may still use frames: wait until it is done before freeing them. */
    while (rt->enc_n || rt->encoding) pthread_cond_wait(&rt->cv_render, &rt->mu);
    pthread_mutex_unlock(&rt->mu);
    for (int i = 0; i < RT_NFRAMES; i++) rnd_frame_free(&rt->frames[i]);
    rnd_destroy(rnd);
    return NULL;
}

static void *enc_main(void *arg)
{
    rt_ctx *rt = arg;
    sd_err err = {0};
    enc_ctx *enc = enc_create(&err);
    pthread_mutex_lock(&rt->mu);
    for (;;) {
        while (!rt->enc_n && !rt->render_done && !rt->enc_trim)
            pthread_cond_wait(&rt->cv_enc, &rt->mu);
        if (rt->enc_trim && !rt->enc_n) {
            /* Idle after a large frame: a fresh encoder, without the large buffers. */
            rt->enc_trim = 0;
            pthread_mutex_unlock(&rt->mu);
            enc_destroy(enc);
            enc = enc_create(&err);
            malloc_trim(0);
            pthread_mutex_lock(&rt->mu);
            continue;
        }
        if (!rt->enc_n) break; /* render thread gone and nothing left */
        rt_encjob job = rt->encq[0];
        memmove(rt->encq, rt->encq + 1, (size_t)(--rt->enc_n) * sizeof rt->encq[0]);
        rt->encoding = 1;
        pthread_mutex_unlock(&rt->mu);

        const uint8_t *out = NULL;
        size_t len = 0;
        uint8_t *msg = NULL;
        size_t msglen = 0;
        uint64_t t0 = now_us();
        int rc = enc ? enc_encode(enc, &rt->frames[job.frame], &job.params, &out, &len, &err) : SD_ENOMEM;
        job.meta.encode_us = now_us() - t0;
        if (rc == 0 && (rc = rt->d.pack(rt->d.pack_user, &job.meta, out, len, &msg, &msglen))) {
            char fmt[32];
            const char *fname = sp_enum_name(SP_FORMAT, job.params.format, fmt, sizeof fmt);
            if (rc == SD_ELIMIT)
                sd_errf(&err, SD_ELIMIT, "the %dx%d frame encoded as %s is %zu bytes of image "
                        "data, over the protocol's frame limit of %u bytes of FRAME payload "
                        "(PROTOCOL.md section 3): ask for a smaller size or a format that "
                        "compresses it more", job.meta.width, job.meta.height,
                        fname ? fname : "?", len, (unsigned)PROTO_MAX_FRAME);
            else
                sd_errf(&err, SD_ENOMEM, "out of memory packing a %zu-byte frame", len);
        }
        rt_event *ev = calloc(1, sizeof *ev);

        pthread_mutex_lock(&rt->mu);
        rt->encoding = 0;
        rt->frame_busy[job.frame] = 0;
        if (ev) {
            ev->meta = job.meta;
            if (rc == 0) {
                ev->kind = RT_EV_FRAME;
                ev->msg = msg;
                ev->msglen = msglen;
            } else {
                ev->kind = RT_EV_FRAME_FAILED;
                ev->err = err;
                free(msg);
            }
            post(rt, ev);
        } else {
            free(msg);
        }
        if (rc != 0 || !ev) { /* nothing reaches the loop's waiting slot */
            rt_slot *s = slot_of(rt, job.meta.client);
            if (s) slot_release(rt, s);
        }
        pthread_cond_broadcast(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
    enc_destroy(enc);
    return NULL;
}

/* on_cache_warn: a damaged cache being rebuilt, or a cache that cannot be written (the cloud
 * is served without one): one line in the daemon's log, as clean text (prep thread; stdio
 * serialises the line). */
static void on_cache_warn(void *user, const char *msg)
{
    (void)user;
    char clean[1200];
    srv_clean_text(msg, clean, sizeof clean);
    srv_log(NULL, NULL, "cache: %s", clean);
}

/* Progress of one prep job, throttled to one event per 100 ms per phase. */
static void on_progress(void *user, int phase, double fraction)
{
    prep_prog *p = user;
    uint64_t t = now_us();
    int same = p->phase == phase;
    if (same && t - p->last_us < 100000 && fraction < 1.0) return;
    p->phase = phase;
    p->last_us = t;
    rt_event *ev = calloc(1, sizeof *ev);
    if (!ev) return;
    ev->kind = RT_EV_PROGRESS;
    ev->job = p->job;
    ev->phase = phase;
    ev->fraction = fraction;
    pthread_mutex_lock(&p->rt->mu);
    post(p->rt, ev);
    pthread_mutex_unlock(&p->rt->mu);
}

/* info_fill: the INFO summary of a prepared cloud (flat or LOD). */
static void info_fill(proto_info *in, uint64_t n, uint64_t dropped, const double bmin[3],
                      const double bmax[3], const double offset[3], uint32_t attrs, uint32_t k,
                      float sigma, const char *format)
{
    in->points = n;
    in->dropped = dropped;
    memcpy(in->bmin, bmin, sizeof in->bmin);
    memcpy(in->bmax, bmax, sizeof in->bmax);
    memcpy(in->offset, offset, sizeof in->offset);
    in->attrs = attrs;
    in->k = k;
    in->sigma = sigma;
    snprintf(in->format, sizeof in->format, "%s", format);
}

static int is_copc_name(const char *path)
{
    size_t n = strlen(path);
    return n >= 9 && !strcasecmp(path + n - 9, ".copc.laz");
}

/* prep_provisional: for a COPC file without a flat cache (a LOD cache is not probed: a COPC
 * file big enough for the LOD form always gets one), its top levels (rt_desc.preview_points)
 * as a provisional cloud, queued for upload ahead of the full prep. A failure is only logged:
 * the full prep runs anyway and answers the OPEN (with the loader's error when the file is
 * bad). Prep thread, mu not held. */
static void prep_provisional(rt_ctx *rt, rt_prepjob *j, int use_lod)
{
    if (!rt->d.preview_points || !is_copc_name(j->path)) return;
    if (!use_lod && cache_probe(j->path, rt->d.cache_dir, 0)) return; /* opens fast anyway */
    uint64_t t0 = now_us();
    pc_raw raw = {0};
    pc_cloud cl = {0};
    sd_err err = {0};
    int level = 0;
    rt_prepjob *pj = calloc(1, sizeof *pj);
    pc_prepared *p = calloc(1, sizeof *p);
    char *path = strdup(j->path);
    int rc = !pj || !p || !path ? sd_errf(&err, SD_ENOMEM, "out of memory for a first image")
                                : pc_read_copc_budget(j->path, rt->d.preview_points, &raw, &level, &err);
    if (rc == 0) rc = pc_finalize(&raw, &cl, j->path, &err);
    pc_raw_free(&raw);
    if (rc == 0) rc = prep_preview(&cl, p, &err);
    pc_cloud_free(&cl);
    if (rc) {
        char clean[1200];
        srv_clean_text(err.msg, clean, sizeof clean);
        srv_log(NULL, NULL, "no first image of %s: %s", j->path, clean);
        if (p) pc_prepared_free(p);
        free(p);
        free(pj);
        free(path);
        return;
    }
    info_fill(&pj->info.summary, p->n, p->n_dropped, p->bmin, p->bmax, p->offset,
              p->attrs | PROTO_INFO_PROVISIONAL, 0, 0.0f, p->format);
    view_of_prepared(p, &pj->info.summary.view);
    srv_log(NULL, NULL, "first image of %s: COPC levels 0-%d, %llu points, read in %.3f s",
            j->path, level, (unsigned long long)p->n, (double)(now_us() - t0) / 1e6);
    pj->job = j->job;
    pj->path = path;
    pj->prep = p;
    pj->provisional = 1;
    j->previewed = 1;
    pthread_mutex_lock(&rt->mu);
    if (rt->up_tail) rt->up_tail->next = pj;
    else rt->up_head = pj;
    rt->up_tail = pj;
    pthread_cond_signal(&rt->cv_render);
    pthread_mutex_unlock(&rt->mu);
}

static void *prep_main(void *arg)
{
    rt_ctx *rt = arg;
    pthread_mutex_lock(&rt->mu);
    for (;;) {
        while (!rt->prep_head && !rt->stop) pthread_cond_wait(&rt->cv_prep, &rt->mu);
        if (rt->stop) break;
        rt_prepjob *j = rt->prep_head;
        rt->prep_head = j->next;
        if (!rt->prep_head) rt->prep_tail = NULL;
        j->next = NULL;
        rt->prepping = 1;
        pthread_mutex_unlock(&rt->mu);

        prep_prog pp = {.rt = rt, .job = j->job, .phase = -1};
        cache_desc cd = {.dir = rt->d.cache_dir, .threads = rt->d.prep_threads,
                         .progress = on_progress, .warn = on_cache_warn, .user = &pp};
        cache_result res;
        sd_err err = {0};
        struct stat st;
        int use_lod = stat(j->path, &st) == 0 && lod_want(rt->d.lod_mode, (uint64_t)st.st_size);
        prep_provisional(rt, j, use_lod);
        pc_prepared *p = use_lod ? NULL : calloc(1, sizeof *p);
        lod_cloud *lc = use_lod ? calloc(1, sizeof *lc) : NULL;
        int rc;
        if (use_lod) {
            lod_desc ld = {.dir = rt->d.cache_dir, .threads = rt->d.prep_threads,
                           .memory = rt->d.prep_memory, .progress = on_progress,
                           .warn = on_cache_warn, .user = &pp};
            lod_result lr;
            rc = lc ? lod_open_cloud(j->path, &ld, lc, &lr, &err)
                    : sd_errf(&err, SD_ENOMEM, "out of memory");
            if (rc == 0) {
                info_fill(&j->info.summary, lc->n, lc->n_dropped, lc->bmin, lc->bmax, lc->offset,
                          lc->attrs, lc->k, lc->sigma, lc->format);
                view_of_lod(lc, &j->info.summary.view);
                j->info.cache_hit = lr.hit;
                j->lod = lc;
                on_progress(&pp, PROTO_PHASE_UPLOAD, 0.0);
            } else {
                free(lc);
            }
        } else
            rc = p ? cache_open_cloud(j->path, &cd, p, &res, &err)
                   : sd_errf(&err, SD_ENOMEM, "out of memory");
        if (rc == 0 && !use_lod) {
            info_fill(&j->info.summary, p->n, p->n_dropped, p->bmin, p->bmax, p->offset, p->attrs,
                      p->k, p->sigma, p->format);
            view_of_prepared(p, &j->info.summary.view);
            j->info.cache_hit = res.hit;
            j->prep = p;
            on_progress(&pp, PROTO_PHASE_UPLOAD, 0.0);
        } else {
            free(p);
        }
        if (rc != 0 && j->previewed) { /* the render thread releases the first image */
            j->failed = 1;
            j->err = err;
            rc = 0;
        }
        pthread_mutex_lock(&rt->mu);
        rt->prepping = 0;
        if (rc == 0) {
            if (rt->up_tail) rt->up_tail->next = j;
            else rt->up_head = j;
            rt->up_tail = j;
            pthread_cond_signal(&rt->cv_render);
        } else {
            rt_event *ev = calloc(1, sizeof *ev);
            if (ev) {
                ev->kind = RT_EV_CLOUD_FAILED;
                ev->job = j->job;
                ev->err = err;
                post(rt, ev);
            }
            free(j->path);
            free(j);
        }
    }
    pthread_mutex_unlock(&rt->mu);
    return NULL;
}

rt_ctx *rt_create(const rt_desc *d, ev_loop *loop, sd_err *err)
{
    rt_ctx *rt = calloc(1, sizeof *rt);
    if (!rt) { sd_errf(err, SD_ENOMEM, "out of memory"); return NULL; }
    rt->d = *d;
    if (d->hooks && d->hooks->configure) d->hooks->configure(d->hooks->user, &rt->d.rnd);
    rt->loop = loop;
    rt->nslots = d->max_clients > 0 ? d->max_clients : 64;
    rt->frame_budget = d->frame_budget;
    if (!rt->frame_budget) {
        /* Default: a quarter of the machine's memory, at least 256 MiB. */
        long pages = sysconf(_SC_PHYS_PAGES), psz = sysconf(_SC_PAGESIZE);
        uint64_t ram = pages > 0 && psz > 0 ? (uint64_t)pages * (uint64_t)psz : 0;
        rt->frame_budget = ram / 4 > (256u << 20) ? ram / 4 : (256u << 20);
    }
    if (rt->nslots > 0xffff) rt->nslots = 0xffff;
    rt->slots = calloc((size_t)rt->nslots, sizeof *rt->slots);
    pthread_mutex_init(&rt->mu, NULL);
    pthread_cond_init(&rt->cv_render, NULL);
    pthread_cond_init(&rt->cv_enc, NULL);
    pthread_cond_init(&rt->cv_prep, NULL);
    pthread_cond_init(&rt->cv_init, NULL);
    if (!rt->slots) { sd_errf(err, SD_ENOMEM, "out of memory"); goto fail; }
    if (pthread_create(&rt->th_render, NULL, render_main, rt) != 0) {
        sd_errf(err, SD_ENOMEM, "cannot start the render thread");
        goto fail;
    }
    rt->started_render = 1;
    pthread_mutex_lock(&rt->mu);
    while (rt->init_state == 0) pthread_cond_wait(&rt->cv_init, &rt->mu);
    pthread_mutex_unlock(&rt->mu);
    if (rt->init_state < 0) {
        if (err) *err = rt->init_err;
        goto fail;
    }
    if (pthread_create(&rt->th_enc, NULL, enc_main, rt) != 0) {
        sd_errf(err, SD_ENOMEM, "cannot start the encoder thread");
        goto fail;
    }
    rt->started_enc = 1;
    if (pthread_create(&rt->th_prep, NULL, prep_main, rt) != 0) {
        sd_errf(err, SD_ENOMEM, "cannot start the prep thread");
        goto fail;
    }
    rt->started_prep = 1;
    return rt;
fail:
    rt_destroy(rt);
    return NULL;
}

static void free_jobs(rt_prepjob *j)
{
    while (j) {
        rt_prepjob *n = j->next;
        if (j->prep) { pc_prepared_free(j->prep); free(j->prep); }
        if (j->lod) { lod_cloud_free(j->lod); free(j->lod); }
        free(j->path);
        free(j);
        j = n;
    }
}

/* stop_workers: stops and joins the render and encoder threads, and the prep thread unless
 * wait_prep is 0 and it is preparing a cloud. Returns 1 when the prep thread was left running. */
static int stop_workers(rt_ctx *rt, int wait_prep)
{
    pthread_mutex_lock(&rt->mu);
    rt->stop = 1;
    pthread_cond_broadcast(&rt->cv_render);
    pthread_cond_broadcast(&rt->cv_enc);
    pthread_cond_broadcast(&rt->cv_prep);
    pthread_mutex_unlock(&rt->mu);
    if (rt->started_render) pthread_join(rt->th_render, NULL);
    if (rt->started_enc) pthread_join(rt->th_enc, NULL);
    rt->started_render = rt->started_enc = 0;
    pthread_mutex_lock(&rt->mu);
    int busy = rt->prepping;
    pthread_mutex_unlock(&rt->mu);
    if (busy && !wait_prep) return 1;
    if (rt->started_prep) pthread_join(rt->th_prep, NULL);
    rt->started_prep = 0;
    return 0;
}

int rt_stop_for_exit(rt_ctx *rt)
{
    if (!rt) return 0;
    if (stop_workers(rt, 0)) return 1;
    rt_destroy(rt);
    return 0;
}

void rt_destroy(rt_ctx *rt)
{
    if (!rt) return;
    stop_workers(rt, 1);
    free_jobs(rt->prep_head);
    free_jobs(rt->up_head);
    rt_event *ev = rt->ev_head;
    while (ev) {
        rt_event *n = ev->next;
        rt_event_free(ev);
        ev = n;
    }
    pthread_cond_destroy(&rt->cv_render);
    pthread_cond_destroy(&rt->cv_enc);
    pthread_cond_destroy(&rt->cv_prep);
    pthread_cond_destroy(&rt->cv_init);
    pthread_mutex_destroy(&rt->mu);
    free(rt->slots);
    free(rt);
}

const char *rt_renderer_string(const rt_ctx *rt) { return rt->renderer; }
const char *rt_backend_name(const rt_ctx *rt) { return rt->backend; }
uint64_t rt_gpu_budget(const rt_ctx *rt) { return rt->gpu_budget; }
uint64_t rt_frame_budget(const rt_ctx *rt) { return rt->frame_budget; }

int rt_client_open(rt_ctx *rt, uint32_t id)
{
    uint32_t i = id & 0xffffu;
    if (id == 0 || i >= (uint32_t)rt->nslots) return SD_ELIMIT;
    pthread_mutex_lock(&rt->mu);
    memset(&rt->slots[i], 0, sizeof rt->slots[i]);
    rt->slots[i].id = id;
    pthread_mutex_unlock(&rt->mu);
    return 0;
}

void rt_client_close(rt_ctx *rt, uint32_t id)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s) {
        /* Its frames in flight are dropped when they arrive at the loop; their bytes are
         * given back now (for a moment the budget counts less than is held). */
        while (s->outstanding > 0) slot_release(rt, s);
        rt->frame_held = rt->frame_held >= s->sending ? rt->frame_held - s->sending : 0;
        memset(s, 0, sizeof *s);
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
}

int rt_submit_prefetch(rt_ctx *rt, uint32_t id, uint32_t cloud_id, const rnd_camera *cams,
                       int n, const sp_params *params)
{
    if (n < 1) return 0;
    if (n > (int)PROTO_MAX_PREFETCH) n = (int)PROTO_MAX_PREFETCH;
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s) {
        s->has_prefetch = 1;
        s->npcams = n;
        s->pcloud = cloud_id;
        s->pparams = *params;
        memcpy(s->pcams, cams, (size_t)n * sizeof *cams);
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
    return 0;
}

int rt_submit_latest(rt_ctx *rt, uint32_t id, const rt_request *rq)
{
    int replaced = 0;
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s) {
        replaced = s->has_latest;
        s->latest = *rq;
        s->has_latest = 1;
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
    return replaced;
}

int rt_submit_queue(rt_ctx *rt, uint32_t id, const rt_request *rq)
{
    int rc = 0;
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (!s || s->qn >= RT_QUEUE_MAX) {
        rc = SD_ELIMIT;
    } else {
        s->q[(s->qhead + s->qn) % RT_QUEUE_MAX] = *rq;
        s->qn++;
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
    return rc;
}

void rt_frame_sending(rt_ctx *rt, uint32_t id)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s && s->outstanding > 0) {
        uint64_t c = s->cost[s->cost_head];
        s->cost_head = (s->cost_head + 1) % RT_MAX_OUTSTANDING;
        s->outstanding--;
        s->sending += c;
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
}

void rt_frame_sent(rt_ctx *rt, uint32_t id)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s && s->sending) {
        rt->frame_held = rt->frame_held >= s->sending ? rt->frame_held - s->sending : 0;
        s->sending = 0;
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
}

void rt_frame_released(rt_ctx *rt, uint32_t id)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s && s->outstanding > 0) {
        slot_release(rt, s);
        pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
}

void rt_set_stream_blocked(rt_ctx *rt, uint32_t id, int blocked)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    if (s && s->stream_blocked != blocked) {
        s->stream_blocked = blocked;
        if (!blocked) pthread_cond_signal(&rt->cv_render);
    }
    pthread_mutex_unlock(&rt->mu);
}

int rt_pending(rt_ctx *rt, uint32_t id)
{
    pthread_mutex_lock(&rt->mu);
    rt_slot *s = slot_of(rt, id);
    int n = s ? s->qn + s->has_latest + s->outstanding : 0;
    pthread_mutex_unlock(&rt->mu);
    return n;
}

int rt_prepare(rt_ctx *rt, const char *path, uint32_t key)
{
    rt_prepjob *j = calloc(1, sizeof *j);
    char *p = strdup(path);
    if (!j || !p) { free(j); free(p); return -1; }
    j->path = p;
    j->job = key;
    pthread_mutex_lock(&rt->mu);
    if (rt->prep_tail) rt->prep_tail->next = j;
    else rt->prep_head = j;
    rt->prep_tail = j;
    pthread_cond_signal(&rt->cv_prep);
    pthread_mutex_unlock(&rt->mu);
    return 0;
}

rt_event *rt_take_events(rt_ctx *rt)
{
    pthread_mutex_lock(&rt->mu);
    rt_event *h = rt->ev_head;
    rt->ev_head = rt->ev_tail = NULL;
    pthread_mutex_unlock(&rt->mu);
    return h;
}

void rt_event_free(rt_event *ev)
{
    if (!ev) return;
    free(ev->msg);
    free(ev);
}

int rt_busy(rt_ctx *rt)
{
    pthread_mutex_lock(&rt->mu);
    int busy = rt->rendering || rt->encoding || rt->enc_n || rt->ev_head;
    for (int i = 0; !busy && i < rt->nslots; i++)
        busy = rt->slots[i].id && (rt->slots[i].qn || rt->slots[i].has_latest);
    pthread_mutex_unlock(&rt->mu);
    return busy;
}

void rt_drop_requests(rt_ctx *rt)
{
    pthread_mutex_lock(&rt->mu);
    for (int i = 0; i < rt->nslots; i++) rt->slots[i].has_latest = 0;
    free_jobs(rt->prep_head);
    rt->prep_head = rt->prep_tail = NULL;
    pthread_mutex_unlock(&rt->mu);
}
