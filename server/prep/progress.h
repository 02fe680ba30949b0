/* progress.h — progress reporting for preprocessing, and the parallel loop that drives it.
 *
 * Progress callbacks run on the calling (main) thread only, with fractions that are exact
 * multiples of 0.05 (j / 20.0), increasing: at most 21 calls per phase, the first 0 and the
 * last 1. While work runs every twentieth crossed is reported (several at once when chunks
 * finished between two reports); the end of a phase jumps to 1, so an instant phase is just
 * 0 and 1. */
#pragma once
#include <stddef.h>

#include "proto.h"
#include "sd_err.h"

/* phase: PROTO_PHASE_* (protocol/proto.h), whose names proto_phase_name gives. */
typedef void (*prep_progress_fn)(void *user, int phase, double fraction);

/* prep_progress_stderr: a prep_progress_fn that draws "phase [#####     ]  50%" with \r on
 * stderr when stderr is a terminal, and otherwise prints one plain line per 10 %. user is
 * unused (NULL is fine). */
void prep_progress_stderr(void *user, int phase, double fraction);

/* A progress reporter for one phase: calls fn when the done fraction crosses the next 5 %. */
typedef struct prep_progress {
    prep_progress_fn fn;
    void *user;
    int phase;               /* PROTO_PHASE_* */
    int step;                /* last reported twentieth, -1 before the first report */
} prep_progress;

/* prep_progress_begin: starts a phase (reports 0 when fn is set). */
void prep_progress_begin(prep_progress *p, prep_progress_fn fn, void *user, int phase);

/* prep_progress_update: reports every twentieth that done/total crossed since the last call
 * (main thread). */
void prep_progress_update(prep_progress *p, size_t done, size_t total);

/* prep_progress_end: reports 1 unless already reported. */
void prep_progress_end(prep_progress *p);

/* The work of one chunk: returns 0 or a negative SD_E* code (filling err). tid is the worker's
 * number in [0, threads): 0 is the calling thread. */
typedef int (*prep_par_fn)(void *ctx, size_t chunk, int tid, sd_err *err);

/* prep_par_for: runs fn(ctx, c, tid, ...) for every chunk c in [0, nchunks) on threads threads
 * (the calling thread works too and is the only one that reports progress through pr, which
 * may be NULL). Chunks are handed out in increasing order; each runs exactly once. After the
 * first failure no new chunk starts, and the first error is returned in err. If a thread
 * cannot be created the work runs on fewer. Returns 0 or the first chunk's error code. */
int prep_par_for(int threads, size_t nchunks, prep_par_fn fn, void *ctx, prep_progress *pr,
                 sd_err *err);

/* prep_default_threads: the number of online cores (at least 1). */
int prep_default_threads(void);
