/* lod_ahead.h — a lod_src pass read ahead on a thread of its own.
 *
 * The LOD build's count and distribution passes are serial: decoding a block of the source and
 * working on it would each leave the other core idle. lod_ahead reads the next block into the
 * second of two buffers while the caller works on the first; the blocks come in the stream's
 * order, exactly as lod_src_next hands them out. */
#pragma once
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "lod_src.h"
#include "sd_err.h"

typedef struct lod_ahead {
    lod_src *s;
    size_t block;             /* points a block at most */
    float *pos[2];
    uint32_t *rgba[2];
    int64_t m[2];             /* points in buffer i, 0 at the end, or the read's error */
    int full[2];              /* 1: filled, not yet released */
    int stop, cur, started;
    int handed;               /* 1: the caller holds a block (buffer cur ^ 1) */
    sd_err err;               /* the read's error */
    pthread_t th;
    pthread_mutex_t mu;
    pthread_cond_t cv;
} lod_ahead;

/* lod_ahead_start: rewinds s and starts reading blocks of up to block points. 0 or SD_E*. */
int lod_ahead_start(lod_ahead *a, lod_src *s, size_t block, sd_err *err);

/* lod_ahead_next: the next block (its buffers stay valid until the next call): the count, 0 at
 * the end, or a negative SD_E* (the read's error in err). */
int64_t lod_ahead_next(lod_ahead *a, const float **pos, const uint32_t **rgba, sd_err *err);

/* lod_ahead_stop: stops the reader (mid-stream too) and frees the buffers. */
void lod_ahead_stop(lod_ahead *a);
