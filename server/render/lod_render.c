/* lod_render.c — a LOD cloud's node pool and per-frame node choice (lod_render.h). */
#include "lod_render.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "camera.h"
#include "cloud.h"

enum { NBUF = RND_ATTR_COUNT + 1, B_RLOD = RND_ATTR_COUNT };
#define NOT_RESIDENT UINT32_MAX

typedef struct alloc {
    uint32_t first, count, node;
} alloc;

/* A loader slot: one node being read (page faults on the mapping, the checksum) into memory of
 * its own, off the render thread. A node that cannot be read as it was written (the cache file
 * was cut or changed in place under the daemon: lod_node_copy) makes the cloud fail: every
 * later frame returns that error. */
enum { SLOT_FREE = 0, SLOT_ASKED, SLOT_READY, SLOT_BROKEN };
typedef struct lslot {
    uint32_t node;
    int state;
    void *data;
} lslot;

struct rnd_lod {
    lod_cloud *c;
    /* the loader thread and its K slots */
    pthread_t th;
    int th_started, stop, k;
    pthread_mutex_t mu;
    pthread_cond_t cv_work, cv_done;
    lslot *slots;
    uint32_t *inflight;       /* per node: its slot + 1, 0 when not loading */
    uint32_t cap;
    GLuint buf[NBUF];
    int have_pool;
    uint32_t *first;          /* per node: pool position or NOT_RESIDENT */
    uint64_t *last;           /* per node: frame stamp when last wanted */
    uint8_t *broken;          /* per node: larger than the pool: never drawn (a frame without
                                 it can still be complete) */
    sd_err fail;              /* fail.code != 0: a node's read failed, the cloud with it (mu) */
    alloc *al;                /* resident ranges, by first */
    uint32_t nal;
    uint64_t stamp;
    /* prefetch: the missing nodes of the views a client announced (rnd__lod_prefetch), in
     * their order; handed to loader slots the frame leaves free, and uploaded when they arrive
     * (a frame's or an idle step's), while pmark[i] == pgen */
    uint32_t *pq, npq, pqhead;
    uint32_t *pmark, pgen;
    /* per frame */
    uint32_t *want, *heap;
    float *prio;
    uint8_t *drawn;
    rnd_chunk *chunks;
};

static void *loader_main(void *arg)
{
    rnd_lod *l = arg;
    pthread_mutex_lock(&l->mu);
    for (;;) {
        int k = -1;
        while (!l->stop) {
            for (int i = 0; i < l->k && k < 0; i++)
                if (l->slots[i].state == SLOT_ASKED && !l->slots[i].data) k = i;
            if (k >= 0) break;
            pthread_cond_wait(&l->cv_work, &l->mu);
        }
        if (l->stop) break;
        uint32_t node = l->slots[k].node;
        l->slots[k].data = (void *)1; /* taken */
        pthread_mutex_unlock(&l->mu);
        const lod_node *nd = &l->c->nodes[node];
        size_t len = (size_t)lod_node_bytes(nd->count);
        void *d = malloc(len ? len : 1);
        sd_err e = {0};
        int ok = d ? lod_node_copy(l->c, node, d, &e) == 0
                   : sd_errf(&e, SD_ENOMEM, "out of memory loading a LOD node") == 0;
        pthread_mutex_lock(&l->mu);
        if (!ok) {
            free(d);
            d = NULL;
            if (!l->fail.code) l->fail = e;
        }
        l->slots[k].data = d;
        l->slots[k].state = ok ? SLOT_READY : SLOT_BROKEN;
        pthread_cond_broadcast(&l->cv_done);
    }
    pthread_mutex_unlock(&l->mu);
    return NULL;
}

uint64_t rnd__lod_pool_bytes(uint32_t cap)
{
    return (uint64_t)cap * 44u;
}

rnd_lod *rnd__lod_new(lod_cloud *c, uint32_t cap, int k, rnd_gpu_cloud *g, sd_err *err)
{
    rnd_lod *l = calloc(1, sizeof *l);
    uint64_t nn = c->nnodes;
    if (l) {
        l->k = k > 0 ? k : 1;
        l->slots = calloc((size_t)l->k, sizeof *l->slots);
        l->inflight = calloc(nn, sizeof *l->inflight);
        l->first = malloc(nn * sizeof *l->first);
        l->last = calloc(nn, sizeof *l->last);
        l->broken = calloc(nn, 1);
        l->al = malloc(nn * sizeof *l->al);
        l->want = malloc(nn * sizeof *l->want);
        l->heap = malloc(nn * sizeof *l->heap);
        l->prio = malloc(nn * sizeof *l->prio);
        l->drawn = calloc(nn, 1);
        l->chunks = malloc(nn * sizeof *l->chunks);
        l->pq = malloc(nn * sizeof *l->pq);
        l->pmark = calloc(nn, sizeof *l->pmark);
    }
    if (l && l->slots && l->inflight) {
        pthread_mutex_init(&l->mu, NULL);
        pthread_cond_init(&l->cv_work, NULL);
        pthread_cond_init(&l->cv_done, NULL);
        l->c = c;
        l->th_started = pthread_create(&l->th, NULL, loader_main, l) == 0;
    }
    if (!l || !l->first || !l->last || !l->broken || !l->al || !l->want || !l->heap ||
        !l->prio || !l->drawn || !l->chunks || !l->pq || !l->pmark || !l->th_started) {
        if (l) {
            l->c = NULL; /* the caller still owns c */
            rnd__lod_free(l, NULL, g);
        }
        sd_errf(err, SD_ENOMEM, "out of memory for a LOD cloud of %llu nodes",
                (unsigned long long)nn);
        return NULL;
    }
    for (uint64_t i = 0; i < nn; i++) l->first[i] = NOT_RESIDENT;
    l->c = c;
    l->cap = cap;
    memset(g, 0, sizeof *g);
    g->n = cap;
    g->attrs = c->attrs;
    for (int a = 0; a < 3; a++) {
        g->offset[a] = c->offset[a];
        g->bmin[a] = (float)(c->bmin[a] - c->offset[a]);
        g->bmax[a] = (float)(c->bmax[a] - c->offset[a]);
        g->centroid[a] = (float)c->centroid[a];
    }
    g->sigma = c->sigma;
    g->radius_median = c->radius_median;
    return l;
}

void rnd__lod_drop_pool(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g)
{
    if (l->have_pool && gl) gl->DeleteBuffers(NBUF, l->buf);
    memset(l->buf, 0, sizeof l->buf);
    l->have_pool = 0;
    if (l->c)
        for (uint64_t i = 0; i < l->c->nnodes; i++) l->first[i] = NOT_RESIDENT;
    l->nal = 0;
    free(g->sets);
    g->sets = NULL;
    g->nsets = 0;
}

void rnd__lod_free(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g)
{
    if (!l) return;
    if (l->th_started) {
        pthread_mutex_lock(&l->mu);
        l->stop = 1;
        pthread_cond_broadcast(&l->cv_work);
        pthread_mutex_unlock(&l->mu);
        pthread_join(l->th, NULL);
    }
    if (l->slots && l->c) {
        pthread_mutex_destroy(&l->mu);
        pthread_cond_destroy(&l->cv_work);
        pthread_cond_destroy(&l->cv_done);
        for (int i = 0; i < l->k; i++)
            if (l->slots[i].state == SLOT_READY) free(l->slots[i].data);
    }
    free(l->slots);
    free(l->inflight);
    rnd__lod_drop_pool(l, gl, g);
    if (l->c) {
        lod_cloud_free(l->c);
        free(l->c);
    }
    free(l->first);
    free(l->last);
    free(l->broken);
    free(l->al);
    free(l->want);
    free(l->heap);
    free(l->prio);
    free(l->drawn);
    free(l->chunks);
    free(l->pq);
    free(l->pmark);
    free(l);
}

int rnd__lod_make_pool(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, sd_err *err)
{
    if (l->have_pool) return 0;
    g->sets = calloc(2, sizeof *g->sets);
    if (!g->sets) return sd_errf(err, SD_ENOMEM, "out of memory for the LOD pool");
    gl->GenBuffers(NBUF, l->buf);
    for (int b = 0; b < NBUF; b++) {
        int comps = b == B_RLOD ? 1 : rnd_attrs[b].components;
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, l->buf[b]);
        gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)((uint64_t)l->cap * 4 * comps), NULL,
                       GL_DYNAMIC_DRAW);
    }
    /* intensity and scan index: LOD clouds have none (0) */
    const GLuint zero = 0;
    const int none[2] = {RND_ATTR_INTENSITY, RND_ATTR_SCAN};
    for (int k = 0; k < 2; k++) {
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, l->buf[none[k]]);
        gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                            &zero);
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    for (int s = 0; s < 2; s++) {
        g->sets[s].base = 0;
        g->sets[s].n = l->cap;
        for (int a = 0; a < RND_ATTR_COUNT; a++) g->sets[s].buf[a] = l->buf[a];
    }
    g->sets[1].buf[RND_ATTR_RADIUS] = l->buf[B_RLOD];
    g->nsets = 2;
    l->have_pool = 1;
    int rc = gl_check(gl, "allocating the LOD node pool", err);
    if (rc < 0) rnd__lod_drop_pool(l, gl, g);
    return rc;
}

/* ---- the pool's ranges ---- */

static void al_remove(rnd_lod *l, uint32_t k)
{
    l->first[l->al[k].node] = NOT_RESIDENT;
    memmove(l->al + k, l->al + k + 1, (l->nal - k - 1) * sizeof *l->al);
    l->nal--;
}

/* First fit: the position of a hole of count points, or NOT_RESIDENT; *at = insertion index. */
static uint32_t find_hole(const rnd_lod *l, uint32_t count, uint32_t *at)
{
    uint32_t prev_end = 0;
    for (uint32_t k = 0; k <= l->nal; k++) {
        uint32_t start = k < l->nal ? l->al[k].first : l->cap;
        if (start - prev_end >= count) {
            *at = k;
            return prev_end;
        }
        if (k < l->nal) prev_end = l->al[k].first + l->al[k].count;
    }
    return NOT_RESIDENT;
}

/* Places node i, evicting nodes not wanted this frame, least recently wanted first; when the
 * pool is too fragmented even then, empties it (the wanted nodes come back in the next frames,
 * packed). Returns the position or NOT_RESIDENT. */
static uint32_t place(rnd_lod *l, uint32_t i, uint32_t *evicted)
{
    uint32_t count = l->c->nodes[i].count, at;
    if (count > l->cap) return NOT_RESIDENT; /* never fits: the caller gives it up */
    for (;;) {
        uint32_t pos = find_hole(l, count, &at);
        if (pos != NOT_RESIDENT) {
            memmove(l->al + at + 1, l->al + at, (l->nal - at) * sizeof *l->al);
            l->al[at] = (alloc){pos, count, i};
            l->nal++;
            l->first[i] = pos;
            return pos;
        }
        uint32_t lru = NOT_RESIDENT;
        for (uint32_t k = 0; k < l->nal; k++) {
            if (l->last[l->al[k].node] == l->stamp) continue; /* pinned: wanted now */
            if (lru == NOT_RESIDENT || l->last[l->al[k].node] < l->last[l->al[lru].node]) lru = k;
        }
        if (lru == NOT_RESIDENT) {
            while (l->nal) al_remove(l, l->nal - 1), (*evicted)++;
            return NOT_RESIDENT;
        }
        al_remove(l, lru);
        (*evicted)++;
    }
}

static int upload(rnd_lod *l, const gl_api *gl, uint32_t i, uint32_t pos, const void *data)
{
    uint32_t n = l->c->nodes[i].count;
    lod_node_data d; /* the layout of lod.h, over the loader's copy */
    d.pos = data;
    d.normal = d.pos + 3 * (size_t)n;
    d.radius = d.normal + 3 * (size_t)n;
    d.radius_lod = d.radius + n;
    d.F = d.radius_lod + n;
    d.rgba = (const uint32_t *)(d.F + n);
    const void *src[NBUF] = {0};
    src[RND_ATTR_POS] = d.pos;
    src[RND_ATTR_NORMAL] = d.normal;
    src[RND_ATTR_RADIUS] = d.radius;
    src[RND_ATTR_RGBA] = d.rgba;
    src[RND_ATTR_FIELD] = d.F;
    src[B_RLOD] = d.radius_lod;
    for (int b = 0; b < NBUF; b++) {
        if (!src[b]) continue;
        int comps = b == B_RLOD ? 1 : rnd_attrs[b].components;
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, l->buf[b]);
        gl->BufferSubData(GL_SHADER_STORAGE_BUFFER, (GLintptr)((uint64_t)pos * 4 * comps),
                          (GLsizeiptr)((uint64_t)n * 4 * comps), src[b]);
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    return 0;
}

/* ---- the frame ---- */

static float priority(const lod_node *nd, const rnd_view *v)
{
    float c[3], r2 = 0, d2 = 0;
    for (int a = 0; a < 3; a++) {
        c[a] = 0.5f * (nd->sbmin[a] + nd->sbmax[a]);
        float h = 0.5f * (nd->sbmax[a] - nd->sbmin[a]);
        r2 += h * h;
        d2 += (c[a] - v->eye[a]) * (c[a] - v->eye[a]);
    }
    float r = sqrtf(r2), d = sqrtf(d2);
    if (d <= r) return INFINITY; /* the eye is inside: first */
    return r / d;
}

static void heap_push(rnd_lod *l, uint32_t *n, uint32_t node, float p)
{
    uint32_t k = (*n)++;
    l->heap[k] = node;
    l->prio[node] = p;
    while (k) {
        uint32_t up = (k - 1) / 2;
        if (l->prio[l->heap[up]] >= p) break;
        l->heap[k] = l->heap[up];
        l->heap[up] = node;
        k = up;
    }
}

static uint32_t heap_pop(rnd_lod *l, uint32_t *n)
{
    uint32_t top = l->heap[0];
    uint32_t last = l->heap[--*n], k = 0;
    if (!*n) return top;
    for (;;) {
        uint32_t a = 2 * k + 1, m = a;
        if (a >= *n) break;
        if (a + 1 < *n && l->prio[l->heap[a + 1]] > l->prio[l->heap[a]]) m = a + 1;
        if (!(l->prio[l->heap[m]] > l->prio[last])) break;
        l->heap[k] = l->heap[m];
        k = m;
    }
    l->heap[k] = last;
    return top;
}

static int cmp_chunk(const void *x, const void *y)
{
    const rnd_chunk *a = x, *b = y;
    if (a->set != b->set) return a->set < b->set ? -1 : 1;
    return a->first < b->first ? -1 : a->first > b->first;
}

int rnd__lod_wait(rnd_lod *l, int timeout_ms)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_sec += timeout_ms / 1000;
    ts.tv_nsec += (long)(timeout_ms % 1000) * 1000000L;
    if (ts.tv_nsec >= 1000000000L) ts.tv_sec++, ts.tv_nsec -= 1000000000L;
    pthread_mutex_lock(&l->mu);
    int ready = 0, busy = 0;
    for (;;) {
        ready = busy = 0;
        for (int k = 0; k < l->k; k++) {
            ready += l->slots[k].state == SLOT_READY || l->slots[k].state == SLOT_BROKEN;
            busy += l->slots[k].state == SLOT_ASKED;
        }
        if (ready || !busy) break;
        if (pthread_cond_timedwait(&l->cv_done, &l->mu, &ts) != 0) break;
    }
    pthread_mutex_unlock(&l->mu);
    return ready;
}

/* choose: the nodes of view v within limit points, by priority, into l->want (parents before
 * children); marks them wanted at the current stamp. Returns their count. */
static uint32_t choose(rnd_lod *l, const rnd_view *v, uint64_t limit)
{
    const lod_cloud *c = l->c;
    uint32_t nh = 0, nw = 0;
    uint64_t total = 0;
    heap_push(l, &nh, 0, INFINITY);
    while (nh) {
        uint32_t i = heap_pop(l, &nh);
        const lod_node *nd = &c->nodes[i];
        if (!rnd__aabb_in_frustum(v->viewproj, nd->sbmin, nd->sbmax)) continue;
        if (total + nd->count > limit) {
            if (nw == 0) { /* the root alone is over the budget: a prefix of it */
                l->want[nw++] = i;
                l->last[i] = l->stamp;
                total = limit;
            }
            break;
        }
        l->want[nw++] = i;
        l->last[i] = l->stamp;
        total += nd->count;
        for (uint32_t k = 0; k < nd->nchildren; k++)
            heap_push(l, &nh, nd->first_child + k, priority(&c->nodes[nd->first_child + k], v));
    }
    return nw;
}

/* take_ready: the loader's finished nodes (l->mu held): uploaded when wanted this frame or
 * prefetched, else dropped; their slots freed. */
static void take_ready(rnd_lod *l, const gl_api *gl, rnd_lod_frame *out)
{
    for (int k = 0; k < l->k; k++) {
        lslot *sl = &l->slots[k];
        if (sl->state != SLOT_READY && sl->state != SLOT_BROKEN) continue;
        uint32_t i = sl->node;
        int keep = l->last[i] == l->stamp || (l->pgen && l->pmark[i] == l->pgen);
        if (sl->state == SLOT_BROKEN) {
            out->broken++;
        } else if (keep && l->first[i] == NOT_RESIDENT) {
            if (l->c->nodes[i].count > l->cap) l->broken[i] = 1; /* larger than the pool */
            uint32_t pos = place(l, i, &out->evicted);
            if (pos != NOT_RESIDENT) {
                upload(l, gl, i, pos, sl->data);
                out->uploaded++;
            }
        }
        free(sl->data);
        sl->data = NULL;
        sl->state = SLOT_FREE;
        l->inflight[i] = 0;
    }
}

/* ask: hands the missing nodes of list[0..n) to free loader slots, in order (l->mu held);
 * *from (when not NULL) advances past the nodes handed out or not needing it. Returns how
 * many were asked for. */
static int ask(rnd_lod *l, const uint32_t *list, uint32_t n, uint32_t *from)
{
    int asked = 0;
    uint32_t k = from ? *from : 0;
    if (l->fail.code) return 0; /* the cloud failed: nothing more is read */
    for (uint32_t s = 0; k < n; k++) {
        uint32_t i = list[k];
        if (l->first[i] != NOT_RESIDENT || l->broken[i] || l->inflight[i]) continue;
        while (s < (uint32_t)l->k && l->slots[s].state != SLOT_FREE) s++;
        if (s == (uint32_t)l->k) break;
        l->slots[s].node = i;
        l->slots[s].state = SLOT_ASKED;
        l->slots[s].data = NULL;
        l->inflight[i] = s + 1;
        asked++;
    }
    if (from) *from = k;
    return asked;
}

/* load_root: the root has no ancestor to stand in for it: read here, on the render thread,
 * when the view wants it and it is missing (once per cloud). l->mu held. */
static void load_root(rnd_lod *l, const gl_api *gl, uint32_t nw, rnd_lod_frame *out)
{
    const lod_cloud *c = l->c;
    if (!nw || l->want[0] != 0 || l->first[0] != NOT_RESIDENT || l->broken[0] ||
        l->inflight[0] || l->fail.code)
        return;
    if (c->nodes[0].count > l->cap) {
        l->broken[0] = 1;
        out->broken++;
        return;
    }
    void *d = malloc((size_t)lod_node_bytes(c->nodes[0].count));
    if (!d) {
        sd_errf(&l->fail, SD_ENOMEM, "out of memory loading a LOD node");
        return;
    }
    if (lod_node_copy(c, 0, d, &l->fail) == 0) {
        uint32_t pos = place(l, 0, &out->evicted);
        if (pos != NOT_RESIDENT) {
            upload(l, gl, 0, pos, d);
            out->uploaded++;
        }
    }
    free(d);
}

/* failed: 0, or the error of a node the cloud could not read (into err). l->mu held. */
static int failed(const rnd_lod *l, sd_err *err)
{
    if (!l->fail.code) return 0;
    if (err) *err = l->fail;
    return l->fail.code;
}

int rnd__lod_settle(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, const rnd_view *v,
                    uint64_t budget, int timeout_ms, rnd_lod_frame *out, sd_err *err)
{
    memset(out, 0, sizeof *out);
    int rc = rnd__lod_make_pool(l, gl, g, err);
    if (rc < 0) return rc;
    uint64_t limit = budget && budget < l->cap ? budget : l->cap;
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (;;) {
        l->stamp++;
        uint32_t nw = choose(l, v, limit);
        pthread_mutex_lock(&l->mu);
        take_ready(l, gl, out);
        load_root(l, gl, nw, out);
        uint32_t missing = 0;
        for (uint32_t k = 0; k < nw; k++)
            missing += l->first[l->want[k]] == NOT_RESIDENT && !l->broken[l->want[k]];
        int asked = ask(l, l->want, nw, NULL);
        asked += ask(l, l->pq, l->npq, &l->pqhead);
        if (asked) pthread_cond_broadcast(&l->cv_work);
        int loading = 0;
        for (int k = 0; k < l->k; k++) loading += l->slots[k].state != SLOT_FREE;
        rc = failed(l, err);
        pthread_mutex_unlock(&l->mu);
        if (rc < 0) return rc;
        out->wanted = nw;
        out->complete = missing == 0;
        clock_gettime(CLOCK_MONOTONIC, &t);
        double ms = (t.tv_sec - t0.tv_sec) * 1e3 + (t.tv_nsec - t0.tv_nsec) / 1e6;
        /* done, out of time, or nothing can come (the pool cannot hold the view) */
        if (!missing || ms >= timeout_ms || !loading) break;
        rnd__lod_wait(l, 1000);
    }
    out->changed = out->uploaded || out->evicted;
    return gl_check(gl, "uploading LOD nodes", err);
}

int rnd__lod_prefetch(rnd_lod *l, const rnd_view *views, int n, uint64_t budget)
{
    uint64_t limit = budget && budget < l->cap ? budget : l->cap;
    l->pgen++;
    l->npq = l->pqhead = 0;
    /* choose marks the views' nodes wanted at the current stamp: until the next frame they are
     * kept like its nodes (uploaded, not evicted); after it, pmark keeps them */
    for (int j = 0; j < n; j++) {
        uint32_t nw = choose(l, &views[j], limit);
        for (uint32_t k = 0; k < nw; k++) {
            uint32_t i = l->want[k];
            if (l->pmark[i] == l->pgen || l->broken[i]) continue;
            l->pmark[i] = l->pgen;
            if (l->first[i] == NOT_RESIDENT) l->pq[l->npq++] = i;
        }
    }
    return (int)l->npq;
}

int rnd__lod_idle(rnd_lod *l, const gl_api *gl, rnd_lod_frame *out, int *pending)
{
    memset(out, 0, sizeof *out);
    *pending = 0;
    if (!l->have_pool) return 0; /* no frame yet: nothing to upload into */
    pthread_mutex_lock(&l->mu);
    take_ready(l, gl, out);
    if (ask(l, l->pq, l->npq, &l->pqhead)) pthread_cond_broadcast(&l->cv_work);
    for (int k = 0; k < l->k; k++) out->loading += l->slots[k].state != SLOT_FREE;
    pthread_mutex_unlock(&l->mu);
    *pending = out->loading > 0 || l->pqhead < l->npq;
    out->changed = out->uploaded || out->evicted;
    return 0;
}

int rnd__lod_frame(rnd_lod *l, const gl_api *gl, rnd_gpu_cloud *g, const rnd_view *v,
                   uint64_t budget, rnd_lod_frame *out, sd_err *err)
{
    memset(out, 0, sizeof *out);
    int rc = rnd__lod_make_pool(l, gl, g, err);
    if (rc < 0) return rc;
    const lod_cloud *c = l->c;
    uint64_t limit = budget && budget < l->cap ? budget : l->cap;
    l->stamp++;
    uint32_t nw = choose(l, v, limit);
    out->wanted = nw;
    /* the loader's finished nodes: uploaded when still wanted (or prefetched), else dropped;
     * then the missing wanted nodes, in priority order, are handed to free loader slots, and
     * the slots left free to the prefetched ones */
    pthread_mutex_lock(&l->mu);
    take_ready(l, gl, out);
    load_root(l, gl, nw, out);
    int asked = ask(l, l->want, nw, NULL);
    asked += ask(l, l->pq, l->npq, &l->pqhead);
    if (asked) pthread_cond_broadcast(&l->cv_work);
    for (int k = 0; k < l->k; k++) out->loading += l->slots[k].state != SLOT_FREE;
    rc = failed(l, err);
    pthread_mutex_unlock(&l->mu);
    if (rc < 0) return rc;
    if ((rc = gl_check(gl, "uploading LOD nodes", err)) < 0) return rc;
    out->changed = out->uploaded || out->evicted;
    /* draw: wanted, resident, ancestors drawn (want is in an order where parents come first) */
    uint32_t nc = 0, missing = 0;
    for (uint32_t k = 0; k < nw; k++) l->drawn[l->want[k]] = 0;
    for (uint32_t k = 0; k < nw; k++) {
        uint32_t i = l->want[k];
        const lod_node *nd = &c->nodes[i];
        int ok = l->first[i] != NOT_RESIDENT && (k == 0 || l->drawn[nd->parent]);
        if (!ok) {
            missing += !l->broken[i];
            continue;
        }
        l->drawn[i] = 1;
    }
    uint64_t pts = 0;
    for (uint32_t k = 0; k < nw; k++) {
        uint32_t i = l->want[k];
        if (!l->drawn[i]) continue;
        const lod_node *nd = &c->nodes[i];
        int all = 1; /* every child drawn: its own radius; else radius_lod */
        for (uint32_t q = 0; q < nd->nchildren; q++)
            if (l->last[nd->first_child + q] != l->stamp || !l->drawn[nd->first_child + q]) all = 0;
        rnd_chunk *ch = &l->chunks[nc++];
        ch->set = all ? 0 : 1;
        ch->first = l->first[i];
        ch->count = nd->count;
        if (pts + ch->count > limit) ch->count = (uint32_t)(limit - pts);
        ch->level = nd->level;
        memcpy(ch->bmin, nd->bmin, sizeof ch->bmin);
        memcpy(ch->bmax, nd->bmax, sizeof ch->bmax);
        pts += ch->count;
    }
    for (uint32_t k = 0; k < nw; k++) l->drawn[l->want[k]] = 0;
    qsort(l->chunks, nc, sizeof *l->chunks, cmp_chunk);
    out->chunks = l->chunks;
    out->nchunks = nc;
    out->points = pts;
    out->drawn = nc;
    out->complete = missing == 0;
    return 0;
}
