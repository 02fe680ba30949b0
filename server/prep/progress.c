/* progress.c — progress reporting and the parallel chunk loop; see progress.h. */
#include "progress.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

void prep_progress_stderr(void *user, int phase_id, double fraction)
{
    (void)user;
    const char *phase = proto_phase_name(phase_id);
    if (!(fraction >= 0)) fraction = 0;
    if (fraction > 1) fraction = 1;
    int pct = (int)floor(fraction * 100 + 0.5);
    if (isatty(STDERR_FILENO)) {
        char bar[31];
        int fill = (int)(fraction * 30 + 0.5);
        for (int i = 0; i < 30; i++) bar[i] = i < fill ? '#' : ' ';
        bar[30] = 0;
        fprintf(stderr, "\r%-12s [%s] %3d%%%s", phase, bar, pct, fraction >= 1 ? "\n" : "");
        fflush(stderr);
        return;
    }
    /* Not a terminal: one line per 10 %. Reporters send multiples of 5 %, so print the even
     * twentieths (and anything that is a whole tenth). */
    double t = fraction * 10;
    if (fabs(t - floor(t + 0.5)) < 1e-9) fprintf(stderr, "%s: %d%%\n", phase, pct);
}

void prep_progress_begin(prep_progress *p, prep_progress_fn fn, void *user, int phase)
{
    p->fn = fn;
    p->user = user;
    p->phase = phase;
    p->step = 0;
    if (fn) fn(user, phase, 0.0);
}

void prep_progress_update(prep_progress *p, size_t done, size_t total)
{
    if (!p || !p->fn || total == 0) return;
    int step = (int)((double)done / (double)total * 20);
    if (step > 20) step = 20;
    /* every twentieth crossed is reported (a burst when several chunks finished at once), so
     * a reporter that prints only some of them (prep_progress_stderr: every tenth) misses none */
    while (p->step < step) {
        p->step++;
        p->fn(p->user, p->phase, p->step / 20.0);
    }
}

void prep_progress_end(prep_progress *p)
{
    if (!p || !p->fn || p->step >= 20) return;
    p->step = 20;
    p->fn(p->user, p->phase, 1.0);
}

typedef struct par_ctx {
    prep_par_fn fn;
    void *ctx;
    size_t nchunks;
    atomic_size_t next;      /* next chunk to hand out */
    atomic_size_t done;      /* chunks finished */
    atomic_int failed;       /* set by the first failure */
    pthread_mutex_t lock;    /* guards err and rc */
    sd_err *err;
    int rc;
} par_ctx;

typedef struct par_worker {
    par_ctx *pc;
    int tid;
} par_worker;

/* Runs chunks until none is left or one failed; the calling thread (tid 0) reports progress. */
static void par_run(par_ctx *pc, int tid, prep_progress *pr)
{
    for (;;) {
        if (atomic_load(&pc->failed)) return;
        size_t c = atomic_fetch_add(&pc->next, 1);
        if (c >= pc->nchunks) return;
        sd_err e = {0};
        int rc = pc->fn(pc->ctx, c, tid, &e);
        if (rc != 0) {
            pthread_mutex_lock(&pc->lock);
            if (pc->rc == 0) {
                pc->rc = rc;
                if (pc->err) *pc->err = e;
            }
            pthread_mutex_unlock(&pc->lock);
            atomic_store(&pc->failed, 1);
            return;
        }
        size_t d = atomic_fetch_add(&pc->done, 1) + 1;
        if (tid == 0) prep_progress_update(pr, d, pc->nchunks);
    }
}

static void *par_thread(void *arg)
{
    par_worker *w = arg;
    par_run(w->pc, w->tid, NULL);
    return NULL;
}

int prep_par_for(int threads, size_t nchunks, prep_par_fn fn, void *ctx, prep_progress *pr,
                 sd_err *err)
{
    enum { MAXT = 256 };
    if (threads < 1) threads = 1;
    if (threads > MAXT) threads = MAXT;
    if ((size_t)threads > nchunks) threads = nchunks > 0 ? (int)nchunks : 1;
    par_ctx pc = {.fn = fn, .ctx = ctx, .nchunks = nchunks, .err = err};
    atomic_init(&pc.next, 0);
    atomic_init(&pc.done, 0);
    atomic_init(&pc.failed, 0);
    pthread_mutex_init(&pc.lock, NULL);
    pthread_t th[MAXT];
    par_worker w[MAXT];
    int started = 0;
    for (int t = 1; t < threads; t++) {
        w[t] = (par_worker){&pc, t};
        if (pthread_create(&th[t], NULL, par_thread, &w[t]) != 0) break;
        started = t;
    }
    par_run(&pc, 0, pr);
    for (int t = 1; t <= started; t++) pthread_join(th[t], NULL);
    pthread_mutex_destroy(&pc.lock);
    if (pc.rc == 0) prep_progress_end(pr);
    return pc.rc;
}

int prep_default_threads(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n >= 1 ? (n > 256 ? 256 : (int)n) : 1;
}
