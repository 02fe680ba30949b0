/* shard.h — which frames of a camera path one worker of a farm renders (`splat path --shard`,
 * Kubernetes Indexed Jobs, Slurm job arrays). Not part of the public library API.
 *
 * Shard I of N renders the frames i with i % N == I, in order: shards write the same file names
 * a single run would, so the union of N shards is exactly the single run's output. */
#pragma once
#include <stddef.h>

typedef struct shard_env {
    const char *shard_flag;       /* --shard I/N, or NULL */
    const char *shards_flag;      /* --shards N (the count when the index comes from the
                                     environment), or NULL */
    const char *job_index;        /* $JOB_COMPLETION_INDEX (Kubernetes Indexed Job) */
    const char *shard_count;      /* $SPLAT_SHARD_COUNT (the Job's completions) */
    const char *slurm_id;         /* $SLURM_ARRAY_TASK_ID */
    const char *slurm_count;      /* $SLURM_ARRAY_TASK_COUNT */
    const char *slurm_min;        /* $SLURM_ARRAY_TASK_MIN (0 when unset) */
} shard_env;

typedef struct shard {
    long index, count;            /* 0 <= index < count; 0/1 when not sharded */
    char source[96];              /* "--shard", "JOB_COMPLETION_INDEX", "SLURM_ARRAY_TASK_ID"
                                     or "" (not sharded) */
} shard;

/* shard_parse: "I/N" (0 <= I < N <= 1000000) into index and count. 0 or -1. */
int shard_parse(const char *s, long *index, long *count);

/* shard_resolve: the shard this process is, from (in this order) --shard, then
 * JOB_COMPLETION_INDEX with the count from --shards or SPLAT_SHARD_COUNT, then
 * SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN with SLURM_ARRAY_TASK_COUNT (--shards overrides
 * the count); none of them set: index 0 of 1. Returns 0, or -1 with err naming the variable or
 * option that is malformed, out of range, or missing its count. */
int shard_resolve(const shard_env *e, shard *out, char *err, size_t errlen);

/* shard_filter: keeps the entries of todo[0..n) that belong to shard s (in place, in order).
 * Returns the new count. */
long shard_filter(const shard *s, long *todo, long n);
