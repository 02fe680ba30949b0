/* lod_ahead.c — a lod_src pass read ahead on a thread of its own (lod_ahead.h). */
#include "lod_ahead.h"

#include <stdlib.h>
#include <string.h>

/* The reader: fills buffer 0, 1, 0, ... each once the caller has released it. */
static void *ahead_run(void *arg)
{
    lod_ahead *a = arg;
    for (int i = 0;; i ^= 1) {
        pthread_mutex_lock(&a->mu);
        while (a->full[i] && !a->stop) pthread_cond_wait(&a->cv, &a->mu);
        int stop = a->stop;
        pthread_mutex_unlock(&a->mu);
        if (stop) break;
        int64_t m = lod_src_next(a->s, a->pos[i], a->rgba[i], a->block, &a->err);
        pthread_mutex_lock(&a->mu);
        a->m[i] = m;
        a->full[i] = 1;
        pthread_cond_broadcast(&a->cv);
        pthread_mutex_unlock(&a->mu);
        if (m <= 0) break; /* the end, or the error: nothing more to read */
    }
    return NULL;
}

int lod_ahead_start(lod_ahead *a, lod_src *s, size_t block, sd_err *err)
{
    memset(a, 0, sizeof *a);
    a->s = s;
    a->block = block;
    for (int i = 0; i < 2; i++) {
        a->pos[i] = malloc(block * 12);
        a->rgba[i] = malloc(block * 4);
        if (!a->pos[i] || !a->rgba[i]) {
            for (int j = 0; j <= i; j++) free(a->pos[j]), free(a->rgba[j]);
            return sd_errf(err, SD_ENOMEM, "lod: out of memory for the read-ahead");
        }
    }
    int rc = lod_src_rewind(s, err);
    if (rc == 0) {
        pthread_mutex_init(&a->mu, NULL);
        pthread_cond_init(&a->cv, NULL);
        a->started = pthread_create(&a->th, NULL, ahead_run, a) == 0;
        if (!a->started) { /* no thread: each block is read when it is asked for */
            pthread_mutex_destroy(&a->mu);
            pthread_cond_destroy(&a->cv);
        }
    }
    if (rc < 0)
        for (int i = 0; i < 2; i++) free(a->pos[i]), free(a->rgba[i]);
    return rc;
}

int64_t lod_ahead_next(lod_ahead *a, const float **pos, const uint32_t **rgba, sd_err *err)
{
    int i = a->cur;
    int64_t m;
    if (!a->started) {
        m = lod_src_next(a->s, a->pos[i], a->rgba[i], a->block, err);
    } else {
        pthread_mutex_lock(&a->mu);
        /* the block handed out last time is released: the reader may fill it. Only then: at
         * the first call the reader may already have filled both buffers, and releasing the
         * second would drop its block (or, at the end, the end itself, and wait forever). */
        if (a->handed) {
            a->full[i ^ 1] = 0;
            pthread_cond_broadcast(&a->cv);
        }
        while (!a->full[i]) pthread_cond_wait(&a->cv, &a->mu);
        m = a->m[i];
        pthread_mutex_unlock(&a->mu);
        if (m < 0 && err) *err = a->err;
        if (m > 0) a->cur = i ^ 1, a->handed = 1;
    }
    *pos = a->pos[i];
    *rgba = a->rgba[i];
    return m;
}

void lod_ahead_stop(lod_ahead *a)
{
    if (a->started) {
        pthread_mutex_lock(&a->mu);
        a->stop = 1;
        pthread_cond_broadcast(&a->cv);
        pthread_mutex_unlock(&a->mu);
        pthread_join(a->th, NULL);
        pthread_mutex_destroy(&a->mu);
        pthread_cond_destroy(&a->cv);
    }
    for (int i = 0; i < 2; i++) free(a->pos[i]), free(a->rgba[i]);
    memset(a, 0, sizeof *a);
}
