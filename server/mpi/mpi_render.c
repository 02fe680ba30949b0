/* mpi_render.c — the ranks of splatd --mpi: loads, frames and compositing (mpi_render.h). */
#include "mpi_render.h"

#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "boxorder.h"
#include "cache.h"
#include "compose.h"
#include "mr_msg.h"
#include "over.h"
#include "partition.h"

enum { MR_MAX_CLOUDS = 256, MR_MAX_TIMES = 4096 };

typedef struct mr_cloud {
    uint32_t key;              /* 0: free */
    uint32_t local_id;         /* 0: this rank's part is empty */
    uint64_t n_local, n_total;
    double offset[3];          /* the cloud's local origin (file coordinates) */
    bo_box *boxes;             /* every rank's part's bounding box: the order of "over" */
    int order_warned;          /* rank 0 said that no plane separates the boxes */
} mr_cloud;

struct mr_ctx {
    MPI_Comm comm;
    int rank, size;
    rt_hooks hooks;
    rnd_ctx *rnd;              /* workers: their own; rank 0: the render thread's */
    const char *cache_dir, *shader_dir;
    rnd_backend_kind backend;
    uint32_t next_key;
    mr_cloud clouds[MR_MAX_CLOUDS];
    rnd_frame frame;           /* workers' frame */
    uint8_t *img, *scratch, *out;
    size_t img_cap;
    rnd_exchange xchg;         /* splat's sort-last exchange (render.h) */
    double xchg_ms;            /* time in the exchange this frame */
    int xchg_calls;            /* exchanges this frame took part in */
    size_t xchg_first, xchg_count; /* the pixels exchanged: the rows of the union's rect */
    /* rank 0: how long it waits for the other ranks (ms, 0: forever) and whether one failed
     * to answer in time; the job cannot render after that */
    double timeout_ms;
    int broken;
    /* statistics: compositing time per frame (rank 0), bytes sent (every rank) */
    uint64_t frames, bytes_sent;
    double comp_ms[MR_MAX_TIMES];
    int ncomp;
    int *order, *order_tmp;    /* soft, olt: the ranks front to back (boxorder.h) */
};

static double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

/* rss_mib: this process's resident memory (VmRSS), MiB; -1 when unknown. */
static double rss_mib(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    if (!f) return -1;
    char line[256];
    double v = -1;
    while (fgets(line, sizeof line, f))
        if (!strncmp(line, "VmRSS:", 6)) v = atof(line + 6) / 1024.0;
    fclose(f);
    return v;
}

/* wait: completes rq; on rank 0 (timeout_ms > 0) gives up after timeout_ms and marks the job
 * broken (a rank died or hangs). Returns MPI_SUCCESS or an error code (MPI_ERR_OTHER for the
 * timeout). */
static int wait_rq(void *user, MPI_Request *rq)
{
    mr_ctx *m = user;
    if (m->timeout_ms <= 0) return MPI_Wait(rq, MPI_STATUS_IGNORE);
    double end = now_ms() + m->timeout_ms;
    for (;;) {
        int done = 0;
        int rc = MPI_Test(rq, &done, MPI_STATUS_IGNORE);
        if (rc != MPI_SUCCESS || done) return rc;
        if (now_ms() > end) {
            m->broken = 1;
            return MPI_ERR_OTHER;
        }
        struct timespec ts = {0, 100000}; /* 0.1 ms: the other ranks run meanwhile */
        nanosleep(&ts, NULL);
    }
}

/* mpi_err: err for a failed MPI call of what; the timeout names the likely cause. */
static int mpi_err(mr_ctx *m, int rc, const char *what, sd_err *err)
{
    if (m->broken)
        return sd_errf(err, SD_EIO, "MPI: %s: the other ranks did not answer within %.0f s (a "
                       "rank died or hangs); splatd --mpi cannot render until the job is "
                       "restarted", what, m->timeout_ms / 1e3);
    char msg[MPI_MAX_ERROR_STRING] = "";
    int len = 0;
    MPI_Error_string(rc, msg, &len);
    return sd_errf(err, SD_EIO, "MPI: %s: %s", what, msg);
}

/* bcast, allreduce: the collectives, completed through wait. */
static int bcast(mr_ctx *m, void *buf, int bytes, int root)
{
    MPI_Request rq;
    int rc = MPI_Ibcast(buf, bytes, MPI_BYTE, root, m->comm, &rq);
    return rc == MPI_SUCCESS ? wait_rq(m, &rq) : rc;
}

static int allreduce(mr_ctx *m, const void *in, void *out, int count, MPI_Datatype t, MPI_Op op)
{
    MPI_Request rq;
    int rc = MPI_Iallreduce(in, out, count, t, op, m->comm, &rq);
    return rc == MPI_SUCCESS ? wait_rq(m, &rq) : rc;
}

int mr_supported(const sp_params *params, sd_err *err)
{
    static const char *const names[] = {
#define MR_PIPE_NAME_(id, name) #name,
        SP_PIPELINE_LIST(MR_PIPE_NAME_)
#undef MR_PIPE_NAME_
    };
    int pi = params->pipeline;
    if (pi != SP_PIPE_POINTS && pi != SP_PIPE_SPLAT && pi != SP_PIPE_SOFT && pi != SP_PIPE_OLT)
        return sd_errf(err, SD_EUNSUP, "pipeline %s is not available with splatd --mpi: only "
                       "points, splat, soft and olt composite from the ranks' parts (kawata "
                       "fits planes to each pixel's points of the whole cloud)",
                       pi >= 0 && pi < SP_PIPE_COUNT ? names[pi] : "?");
    if (pi == SP_PIPE_SOFT && params->model != SP_MODEL_EXPRESS)
        return sd_errf(err, SD_EUNSUP, "soft model=%s is not available with splatd --mpi: "
                       "only model=express is composited from the ranks' parts (their images "
                       "go \"over\" each other front to back in the order of their boxes, "
                       "38-47 dB PSNR from the single image where splats and discs cross the "
                       "cuts, see README); base and concentric integrate overlapping spheres' "
                       "density together, and their composite was not measured",
                       params->model == SP_MODEL_BASE ? "base" : "concentric");
    if (params->shading == SP_SHADING_EDL)
        return sd_errf(err, SD_EUNSUP, "shading=edl is not available with splatd --mpi (it "
                       "needs the composited depth on one GL context)");
    return 0;
}

/* opt_value: the value of --name in argv ("--name V" or "--name=V"), or NULL. */
static const char *opt_value(int argc, char **argv, const char *name)
{
    size_t l = strlen(name);
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], name) && i + 1 < argc) return argv[i + 1];
        if (!strncmp(argv[i], name, l) && argv[i][l] == '=') return argv[i] + l + 1;
    }
    return NULL;
}

static void configure(void *user, rnd_desc *d)
{
    (void)user;
    /* The packed form breaks depth ties within a quantum by the point's index in the whole
     * cloud, which a rank does not have; the exact form orders by float depth, which the
     * composite reproduces across ranks. */
    d->pipe.points_raster = RND_RASTER_EXACT;
}

static mr_cloud *find_cloud(mr_ctx *m, uint32_t key)
{
    for (int i = 0; i < MR_MAX_CLOUDS; i++)
        if (m->clouds[i].key == key && key) return &m->clouds[i];
    return NULL;
}

/* agree: every rank's rc (0 or SD_E*) combined; the first failing rank's message is broadcast
 * into err. Returns 0 when all succeeded, else that rank's code. */
static int agree(mr_ctx *m, int rc, sd_err *err)
{
    struct { int v, r; } mine = {rc < 0 ? 1 : 0, m->rank}, worst;
    /* MAXLOC picks a failing rank (v = 1) and, among several, the lowest */
    int mrc = allreduce(m, &mine, &worst, 1, MPI_2INT, MPI_MAXLOC);
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "the ranks could not agree", err);
    if (!worst.v) return 0;
    mr_fail e = {0};
    if (m->rank == worst.r) {
        e.code = rc;
        int l = snprintf(e.msg, sizeof e.msg, "rank %d of %d: ", m->rank, m->size);
        if (l > 0 && (size_t)l < sizeof e.msg)
            memcpy(e.msg + l, err->msg, strnlen(err->msg, sizeof e.msg - (size_t)l - 1));
    }
    if ((mrc = bcast(m, &e, (int)sizeof e, worst.r)) != MPI_SUCCESS)
        return mpi_err(m, mrc, "the ranks could not agree", err);
    return mr_fail_decode(&e, sizeof e, err);
}

/* load: every rank's part of the cloud at path (full: the prepared cloud when this rank has it,
 * freed here; NULL: open it through the cache). */
static int load(mr_ctx *m, const mr_cmd *c, pc_prepared *full, sd_err *err)
{
    int rc = 0;
    pc_prepared mine = {0}, *heap = NULL;
    cache_result res;
    uint16_t *part = NULL;
    bo_box *boxes = NULL;
    double offset[3] = {0, 0, 0};
    mr_cloud *slot = NULL;
    for (int i = 0; i < MR_MAX_CLOUDS && !slot; i++)
        if (!m->clouds[i].key) slot = &m->clouds[i];
    if (!slot) rc = sd_errf(err, SD_ELIMIT, "more than %d clouds loaded", MR_MAX_CLOUDS);
    pc_prepared own = {0};
    if (rc == 0 && !full) {
        cache_desc cd = {.dir = m->cache_dir};
        rc = cache_open_cloud(c->path, &cd, &own, &res, err);
        if (rc == 0) full = &own;
    }
    uint64_t total = full ? full->n : 0;
    if (rc == 0 && total < (uint64_t)m->size)
        rc = sd_errf(err, SD_EINVAL, "the cloud has %llu points, fewer than the %d ranks",
                     (unsigned long long)total, m->size);
    if (rc == 0) {
        part = malloc((size_t)(full->n ? full->n : 1) * sizeof *part);
        rc = part ? pc_partition(full->pos, full->radius, full->n, m->size, part, NULL, err)
                  : sd_errf(err, SD_ENOMEM, "out of memory for the partition");
    }
    if (rc == 0) rc = pc_prepared_subset(full, part, m->rank, &mine, err);
    if (rc == 0) { /* every part's box, for the order of soft's and olt's "over" */
        boxes = malloc((size_t)m->size * sizeof *boxes);
        if (!boxes) rc = sd_errf(err, SD_ENOMEM, "out of memory for the parts' boxes");
        else bo_boxes(full->pos, full->n, part, m->size, boxes);
        memcpy(offset, full->offset, sizeof offset);
    }
    free(part);
    if (full) pc_prepared_free(full);
    int64_t id = 0;
    uint64_t n_local = rc == 0 ? mine.n : 0;
    if (rc == 0 && mine.n > 0) {
        heap = malloc(sizeof *heap);
        if (!heap) {
            pc_prepared_free(&mine);
            rc = sd_errf(err, SD_ENOMEM, "out of memory");
        } else {
            *heap = mine;
            id = rnd_adopt(m->rnd, heap, err); /* owns heap now */
            if (id < 0) rc = (int)id;
        }
    } else if (rc == 0) {
        pc_prepared_free(&mine);
    }
    int all = agree(m, rc, err);
    if (all < 0) {
        if (id > 0) rnd_release(m->rnd, (uint32_t)id);
        free(boxes);
        return all;
    }
    *slot = (mr_cloud){.key = c->key, .local_id = (uint32_t)id, .n_local = n_local,
                       .n_total = total, .boxes = boxes};
    memcpy(slot->offset, offset, sizeof offset);
    const char *name = strrchr(c->path, '/');
    fprintf(stderr, "splatd-mpi: rank %d of %d: %s: %llu of %llu points, resident %.0f MiB\n",
            m->rank, m->size, name ? name + 1 : c->path, (unsigned long long)slot->n_local,
            (unsigned long long)total, rss_mib());
    return 0;
}

static int64_t hook_adopt(void *user, rnd_ctx *rnd, const char *path, pc_prepared *p, sd_err *err)
{
    mr_ctx *m = user;
    m->rnd = rnd;
    mr_cmd c = {.op = MR_LOAD, .key = ++m->next_key};
    if (snprintf(c.path, sizeof c.path, "%s", path) >= (int)sizeof c.path) {
        pc_prepared_free(p);
        free(p);
        return sd_errf(err, SD_ELIMIT, "path too long for the ranks: %.80s...", path);
    }
    uint8_t rec[MR_CMD_BYTES];
    int rc = mr_cmd_encode(&c, rec, err);
    int mrc = rc < 0 || m->broken ? MPI_ERR_OTHER : bcast(m, rec, (int)sizeof rec, 0);
    if (mrc != MPI_SUCCESS) {
        pc_prepared_free(p);
        free(p);
        return rc < 0 ? rc : mpi_err(m, mrc, "loading the cloud", err);
    }
    rc = load(m, &c, p, err);
    free(p);
    return rc < 0 ? rc : (int64_t)c.key;
}

/* ensure_img: the pack, scratch and (rank 0) output buffers for bytes each. */
static int ensure_img(mr_ctx *m, size_t bytes, sd_err *err)
{
    if (bytes <= m->img_cap) return 0;
    free(m->img);
    free(m->scratch);
    free(m->out);
    m->img = malloc(bytes);
    m->scratch = malloc(bytes);
    m->out = m->rank == 0 ? malloc(bytes) : NULL;
    m->img_cap = m->img && m->scratch && (m->rank || m->out) ? bytes : 0;
    return m->img_cap ? 0 : sd_errf(err, SD_ENOMEM, "out of memory for compositing buffers");
}

/* A composited pixel: eye depth (+inf: empty), RGBA8, and for float frames RGBA16F. */
enum { PX8 = 8, PXF = 16 };

/* empty_frame: f sized w x h with every pixel the background (a rank with no points). */
static int empty_frame(rnd_frame *f, int w, int h, const sp_params *p, sd_err *err)
{
    size_t npix = (size_t)w * (size_t)h;
    if (f->width != w || f->height != h || !f->rgba8 || !f->depth || !f->rgba16f) {
        free(f->rgba8);
        free(f->rgba16f);
        free(f->depth);
        f->rgba8 = malloc(npix * 4);
        f->rgba16f = malloc(npix * 8);
        f->depth = malloc(npix * sizeof *f->depth);
        f->width = w;
        f->height = h;
        if (!f->rgba8 || !f->rgba16f || !f->depth)
            return sd_errf(err, SD_ENOMEM, "out of memory for a %dx%d frame", w, h);
    }
    uint8_t bg[4];
    for (int i = 0; i < 3; i++) bg[i] = (uint8_t)lrintf(fminf(fmaxf(p->background[i], 0), 1) * 255);
    bg[3] = 255;
    for (size_t i = 0; i < npix; i++) {
        memcpy(f->rgba8 + 4 * i, bg, 4);
        f->depth[i] = INFINITY;
        memset(f->rgba16f + 4 * i, 0, 8); /* the float target's clear: alpha 0 */
    }
    f->render_us = f->readback_us = f->points_drawn = 0;
    return 0;
}

/* op_sum: adds splat's per-pixel sums (8 words: 7 sums, float or wrapping integers, a pad). */
static void op_sum(const uint8_t *lo, const uint8_t *hi, uint8_t *dst, size_t npix,
                   size_t stride, void *user)
{
    int is_float = *(const int *)user;
    for (size_t i = 0; i < npix * stride / 32; i++) {
        for (int w = 0; w < 7; w++) {
            size_t o = 32 * i + 4 * (size_t)w;
            if (is_float) {
                float a, b;
                memcpy(&a, lo + o, 4);
                memcpy(&b, hi + o, 4);
                a += b;
                memcpy(dst + o, &a, 4);
            } else {
                uint32_t a, b;
                memcpy(&a, lo + o, 4);
                memcpy(&b, hi + o, 4);
                a += b;
                memcpy(dst + o, &a, 4);
            }
        }
    }
}

/* xchg_keys: splat's visibility keys of all ranks (the nearest surface per pixel). */
static int xchg_keys(void *user, int rc, uint32_t *keys, size_t n, int width, int32_t rect[4],
                     sd_err *err)
{
    mr_ctx *m = user;
    double t0 = now_ms();
    m->xchg_calls++;
    m->xchg_first = m->xchg_count = 0;
    if ((rc = agree(m, rc, err)) < 0) return rc;
    if (n > INT_MAX || width < 1) return sd_errf(err, SD_ELIMIT, "frame too large to exchange");
    /* the union of the rectangles first: only its rows are exchanged */
    int32_t r[4] = {rect[0], rect[1], -rect[2], -rect[3]};
    int mrc = allreduce(m, MPI_IN_PLACE, r, 4, MPI_INT32_T, MPI_MIN);
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "exchanging the visibility rectangle", err);
    rect[0] = r[0], rect[1] = r[1], rect[2] = -r[2], rect[3] = -r[3];
    int64_t rows = (int64_t)(n / (size_t)width);
    int64_t y0 = rect[1] < 0 ? 0 : rect[1], y1 = rect[3] >= rows ? rows - 1 : rect[3];
    if (rect[0] > rect[2] || y0 > y1) {
        m->xchg_ms += now_ms() - t0;
        return 0; /* nothing drawn anywhere */
    }
    m->xchg_first = (size_t)y0 * (size_t)width;
    m->xchg_count = (size_t)(y1 - y0 + 1) * (size_t)width;
    mrc = allreduce(m, MPI_IN_PLACE, keys + m->xchg_first, (int)m->xchg_count, MPI_UINT32_T,
                    MPI_MAX);
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "exchanging the visibility keys", err);
    /* a ring allreduce sends about 2 (N - 1) / N of the array from each rank */
    m->bytes_sent += (uint64_t)(2.0 * (m->size - 1) / m->size * (double)m->xchg_count * 4);
    m->xchg_ms += now_ms() - t0;
    return 0;
}

/* xchg_sums: splat's weighted sums of all ranks, added up by binary swap, at rank 0. */
static int xchg_sums(void *user, int rc, uint32_t *px, size_t n, int is_float, sd_err *err)
{
    mr_ctx *m = user;
    double t0 = now_ms();
    if ((rc = agree(m, rc, err)) < 0) return rc;
    size_t first = m->xchg_first, count = m->xchg_count;
    if (first + count > n) return sd_errf(err, SD_EINVAL, "splat sums: %zu pixels", n);
    if ((rc = agree(m, ensure_img(m, count * 32, err), err)) < 0) return rc;
    if (count) {
        cmp_stats st;
        int mrc = cmp_composite(m->comm, (uint8_t *)(px + 8 * first), m->scratch, m->out, count,
                                32, op_sum, &is_float, wait_rq, m, &st);
        m->bytes_sent += st.bytes_sent;
        if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "adding up the splat sums", err);
        if (m->rank == 0) memcpy(px + 8 * first, m->out, count * 32);
    }
    m->xchg_ms += now_ms() - t0;
    return m->rank == 0;
}

/* clear_frame: f sized w x h, nothing drawn: colour and coverage 0, depth +inf (a rank with
 * no points under soft or olt). */
static int clear_frame(rnd_frame *f, int w, int h, sd_err *err)
{
    sp_params black = {0};
    int rc = empty_frame(f, w, h, &black, err);
    if (rc == 0)
        for (size_t i = 0; i < (size_t)w * (size_t)h; i++) f->rgba8[4 * i + 3] = 0;
    return rc;
}

/* frame_over: soft and olt. Every rank renders its part with a black background and coverage
 * in alpha, and the ranks' images go "over" each other front to back by their boxes
 * (boxorder.h) through the ordered binary swap (compose.h); rank 0 puts the background under
 * the result (over.h). */
static int frame_over(mr_ctx *m, const mr_cmd *c, mr_cloud *cl, sp_params *p, rnd_frame *f,
                      double t0, sd_err *err)
{
    int rc = 0;
    if (m->size == 1) {
        /* one image: the GL puts it over the background as it draws (rounding at each blend,
         * as the single process does); nothing to composite */
        if (!cl) return sd_errf(err, SD_EINVAL, "cloud %u is not loaded", c->key);
        rc = rnd_render(m->rnd, cl->local_id, &c->cam, p, c->want_float, f, err);
        if (rc < 0) return rc;
        m->frames++;
        if (m->ncomp < MR_MAX_TIMES) m->comp_ms[m->ncomp++] = 0;
        f->render_us = (uint64_t)((now_ms() - t0) * 1e3);
        f->readback_us = 0;
        f->points_drawn = cl->n_total;
        return 0;
    }
    float bg[3];
    memcpy(bg, p->background, sizeof bg);
    memset(p->background, 0, sizeof p->background);
    if (!cl) {
        rc = sd_errf(err, SD_EINVAL, "cloud %u is not loaded on this rank", c->key);
    } else if (cl->local_id) {
        rnd_set_coverage(m->rnd, 1);
        rc = rnd_render(m->rnd, cl->local_id, &c->cam, p, c->want_float, f, err);
        rnd_set_coverage(m->rnd, 0);
    } else {
        rc = clear_frame(f, c->cam.width, c->cam.height, err);
    }
    size_t npix = (size_t)c->cam.width * (size_t)c->cam.height;
    size_t stride = c->want_float ? OV_PXF : OV_PX8;
    if (rc == 0) rc = ensure_img(m, npix * stride, err);
    if ((rc = agree(m, rc, err)) < 0) return rc;
    double t1 = now_ms();
    /* the order: every rank computes it from the same boxes and camera */
    double eye[3];
    for (int a = 0; a < 3; a++) eye[a] = c->cam.eye[a] - cl->offset[a];
    if (!bo_order(cl->boxes, m->size, eye, m->order, m->order_tmp) && m->rank == 0 &&
        !cl->order_warned) {
        /* parts that are not cut by planes (boxorder.h): said once per cloud */
        cl->order_warned = 1;
        fprintf(stderr, "splatd-mpi: the parts' boxes overlap (no plane separates them): soft "
                "and olt composite them nearest first, which can be wrong where they overlap\n");
    }
    if (stride == OV_PX8) {
        memcpy(m->img, f->rgba8, npix * 4);
    } else {
        for (size_t i = 0; i < npix; i++) {
            uint8_t *px = m->img + i * stride;
            memcpy(px, &f->depth[i], 4);
            memcpy(px + 4, f->rgba16f + 4 * i, 8);
        }
    }
    cmp_stats st;
    int mrc = cmp_composite_ordered(m->comm, m->order, m->img, m->scratch, m->out, npix, stride,
                                    ov_op, NULL, wait_rq, m, &st);
    m->bytes_sent += st.bytes_sent;
    m->frames++;
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "compositing", err);
    if (m->rank == 0) {
        if (stride == OV_PX8) {
            memcpy(f->rgba8, m->out, npix * 4);
            ov_background8(f->rgba8, npix, bg);
        } else {
            ov_backgroundf(m->out, npix, bg, f->rgba16f, f->rgba8, f->depth);
        }
        double t2 = now_ms();
        if (m->ncomp < MR_MAX_TIMES) m->comp_ms[m->ncomp++] = t2 - t1;
        f->render_us = (uint64_t)((t1 - t0) * 1e3);
        f->readback_us = (uint64_t)((t2 - t1) * 1e3); /* compositing: the frame's "read-back" */
        f->points_drawn = cl->n_total;
    }
    return 0;
}

/* frame: every rank renders its part and the ranks composite; rank 0 gets the result in f. */
static int frame(mr_ctx *m, const mr_cmd *c, rnd_frame *f, sd_err *err)
{
    double t0 = now_ms();
    int rc = 0;
    mr_cloud *cl = find_cloud(m, c->key);
    sp_params p = c->params;
    if (p.point_budget > 0) p.point_budget = (p.point_budget + m->size - 1) / m->size;
    if (p.pipeline == SP_PIPE_SOFT || p.pipeline == SP_PIPE_OLT)
        return frame_over(m, c, cl, &p, f, t0, err);
    int splat = p.pipeline == SP_PIPE_SPLAT;
    m->xchg_ms = 0;
    m->xchg_calls = 0;
    if (splat) {
        /* the ranks exchange splat's per-pixel state inside the pipeline (render_sortlast in
         * pipe_splat.c); rank 0 resolves the frame, so nothing is composited afterwards */
        rnd_set_exchange(m->rnd, &m->xchg);
        if (!cl) rc = sd_errf(err, SD_EINVAL, "cloud %u is not loaded on this rank", c->key);
        else if (!cl->local_id) rc = sd_errf(err, SD_EINVAL, "this rank holds no point");
        else rc = rnd_render(m->rnd, cl->local_id, &c->cam, &p, c->want_float, f, err);
        rnd_set_exchange(m->rnd, NULL);
        if (rc < 0 && !m->xchg_calls) {
            /* failed before the exchange: take part in its first step (which then fails on
             * every rank), so that the others do not wait */
            sd_err e2 = *err;
            xchg_keys(m, rc, NULL, 0, 0, NULL, &e2);
        }
        if ((rc = agree(m, rc, err)) < 0) return rc;
        m->frames++;
        if (m->rank == 0) {
            if (m->ncomp < MR_MAX_TIMES) m->comp_ms[m->ncomp++] = m->xchg_ms;
            f->render_us = (uint64_t)((now_ms() - t0 - m->xchg_ms) * 1e3);
            f->readback_us = (uint64_t)(m->xchg_ms * 1e3);
            f->points_drawn = cl->n_total;
        }
        return 0;
    }
    if (!cl) rc = sd_errf(err, SD_EINVAL, "cloud %u is not loaded on this rank", c->key);
    else if (cl->local_id)
        rc = rnd_render(m->rnd, cl->local_id, &c->cam, &p, 1, f, err);
    else
        rc = empty_frame(f, c->cam.width, c->cam.height, &p, err);
    size_t npix = (size_t)c->cam.width * (size_t)c->cam.height;
    size_t stride = c->want_float ? PXF : PX8;
    if (rc == 0) rc = ensure_img(m, npix * stride, err);
    if ((rc = agree(m, rc, err)) < 0) return rc;
    double t1 = now_ms();
    if (m->size == 1) { /* nothing to composite */
        m->frames++;
        if (m->ncomp < MR_MAX_TIMES) m->comp_ms[m->ncomp++] = 0;
        f->render_us = (uint64_t)((t1 - t0) * 1e3);
        f->readback_us = 0;
        f->points_drawn = cl->n_total;
        return 0;
    }
    for (size_t i = 0; i < npix; i++) {
        uint8_t *px = m->img + i * stride;
        memcpy(px, &f->depth[i], 4);
        memcpy(px + 4, f->rgba8 + 4 * i, 4);
        if (stride == PXF) memcpy(px + 8, f->rgba16f + 4 * i, 8);
    }
    cmp_stats st;
    int mrc = cmp_composite(m->comm, m->img, m->scratch, m->out, npix, stride, cmp_op_nearest,
                            NULL, wait_rq, m, &st);
    m->bytes_sent += st.bytes_sent;
    m->frames++;
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "compositing", err);
    if (m->rank == 0) {
        for (size_t i = 0; i < npix; i++) {
            const uint8_t *px = m->out + i * stride;
            memcpy(&f->depth[i], px, 4);
            memcpy(f->rgba8 + 4 * i, px + 4, 4);
            if (stride == PXF) memcpy(f->rgba16f + 4 * i, px + 8, 8);
        }
        double t2 = now_ms();
        if (m->ncomp < MR_MAX_TIMES) m->comp_ms[m->ncomp++] = t2 - t1;
        f->render_us = (uint64_t)((t1 - t0) * 1e3);
        f->readback_us = (uint64_t)((t2 - t1) * 1e3); /* compositing: the frame's "read-back" */
        f->points_drawn = cl ? cl->n_total : 0;
    }
    return 0;
}

static int hook_render(void *user, rnd_ctx *rnd, uint32_t key, const rnd_camera *cam,
                       const sp_params *params, int want_float, rnd_frame *f, sd_err *err)
{
    mr_ctx *m = user;
    m->rnd = rnd;
    int rc = mr_supported(params, err);
    if (rc < 0) return rc;
    mr_cmd c = {.op = MR_RENDER, .key = key, .want_float = want_float, .cam = *cam,
                .params = *params};
    uint8_t rec[MR_CMD_BYTES];
    if ((rc = mr_cmd_encode(&c, rec, err)) < 0) return rc;
    int mrc = m->broken ? MPI_ERR_OTHER : bcast(m, rec, (int)sizeof rec, 0);
    if (mrc != MPI_SUCCESS) return mpi_err(m, mrc, "starting the frame", err);
    return frame(m, &c, f, err);
}

mr_ctx *mr_create(MPI_Comm comm, int argc, char **argv)
{
    mr_ctx *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->comm = comm;
    MPI_Comm_rank(comm, &m->rank);
    MPI_Comm_size(comm, &m->size);
    m->order = malloc((size_t)m->size * sizeof *m->order);
    m->order_tmp = malloc((size_t)m->size * sizeof *m->order_tmp);
    if (!m->order || !m->order_tmp) {
        free(m->order);
        free(m->order_tmp);
        free(m);
        return NULL;
    }
    m->hooks = (rt_hooks){.user = m, .configure = configure, .adopt = hook_adopt,
                          .render = hook_render};
    m->xchg = (rnd_exchange){.user = m, .keys = xchg_keys, .sums = xchg_sums};
    /* rank 0 waits at most $SPLATD_MPI_TIMEOUT seconds (default 60) for the others */
    const char *to = getenv("SPLATD_MPI_TIMEOUT");
    double sec = to && *to ? atof(to) : 60;
    m->timeout_ms = m->rank == 0 && sec > 0 ? sec * 1e3 : 0;
    m->cache_dir = opt_value(argc, argv, "--cache");
    m->shader_dir = opt_value(argc, argv, "--shader-dir");
    const char *be = opt_value(argc, argv, "--backend");
    m->backend = be && !strcmp(be, "egl") ? RND_BACKEND_EGL
               : be && !strcmp(be, "osmesa") ? RND_BACKEND_OSMESA : RND_BACKEND_AUTO;
    return m;
}

int mr_broken(const mr_ctx *m)
{
    return m->broken;
}

const rt_hooks *mr_hooks(mr_ctx *m)
{
    return &m->hooks;
}

void mr_destroy(mr_ctx *m)
{
    if (!m) return;
    free(m->img);
    free(m->scratch);
    free(m->out);
    for (int i = 0; i < MR_MAX_CLOUDS; i++) free(m->clouds[i].boxes);
    free(m->order);
    free(m->order_tmp);
    rnd_frame_free(&m->frame);
    free(m);
}

int mr_worker(mr_ctx *m)
{
    /* Rank 0 stops the workers (mr_quit) after its own graceful stop: the SIGTERM or SIGINT
     * mpirun forwards to every rank is rank 0's alone to act on. */
    signal(SIGTERM, SIG_IGN);
    signal(SIGINT, SIG_IGN);
    sd_err err = {0};
    rnd_desc d = {.backend = m->backend, .shader_dir = m->shader_dir, .max_width = 8192,
                  .max_height = 8192};
    configure(m, &d);
    m->rnd = rnd_create(&d, &err);
    if (!m->rnd)
        fprintf(stderr, "splatd-mpi: rank %d: cannot start the renderer: %s\n", m->rank, err.msg);
    for (;;) {
        uint8_t rec[MR_CMD_BYTES];
        if (bcast(m, rec, (int)sizeof rec, 0) != MPI_SUCCESS) break;
        sd_err e = {0};
        mr_cmd c;
        int rc = mr_cmd_decode(rec, sizeof rec, &c, &e);
        if (rc < 0 && c.op != MR_LOAD && c.op != MR_RENDER) {
            /* no step this rank knows to take part in: the job cannot go on */
            fprintf(stderr, "splatd-mpi: rank %d: %s; stopping\n", m->rank, e.msg);
            break;
        }
        if (rc == 0 && c.op == MR_QUIT) break;
        if (rc == 0 && !m->rnd) rc = sd_errf(&e, SD_EGL, "no renderer: %s", err.msg);
        /* a LOAD or RENDER this rank cannot take: its error goes to rank 0 */
        if (rc < 0) agree(m, rc, &e);
        else if (c.op == MR_LOAD) load(m, &c, NULL, &e);
        else frame(m, &c, &m->frame, &e);
    }
    fprintf(stderr, "splatd-mpi: rank %d of %d: %llu frames, %.1f MiB sent compositing, "
            "resident %.0f MiB\n", m->rank, m->size, (unsigned long long)m->frames,
            m->bytes_sent / 1048576.0, rss_mib());
    rnd_frame_free(&m->frame);
    if (m->rnd) rnd_destroy(m->rnd);
    m->rnd = NULL;
    return 0;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

void mr_quit(mr_ctx *m)
{
    mr_cmd c = {.op = MR_QUIT};
    uint8_t rec[MR_CMD_BYTES];
    if (!m->broken && mr_cmd_encode(&c, rec, NULL) == 0) bcast(m, rec, (int)sizeof rec, 0);
    double med = 0;
    if (m->ncomp) {
        qsort(m->comp_ms, (size_t)m->ncomp, sizeof m->comp_ms[0], cmp_double);
        med = m->comp_ms[m->ncomp / 2];
    }
    fprintf(stderr, "splatd-mpi: rank 0 of %d: %llu frames, compositing median %.2f ms, "
            "%.1f MiB sent compositing, resident %.0f MiB\n", m->size,
            (unsigned long long)m->frames, med, m->bytes_sent / 1048576.0, rss_mib());
}
