/* shard.c — the frames of a camera path one farm worker renders (see shard.h). */
#include "shard.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { SHARD_MAX = 1000000 };

/* parse_num: a whole decimal number in [lo, hi], nothing else (digits only: strtol alone would
 * take leading white space and a sign). 0 or -1. */
static int parse_num(const char *s, long lo, long hi, long *out)
{
    if (!s || !isdigit((unsigned char)*s)) return -1;
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi) return -1;
    *out = v;
    return 0;
}

int shard_parse(const char *s, long *index, long *count)
{
    const char *slash = s ? strchr(s, '/') : NULL;
    if (!slash || slash == s || (size_t)(slash - s) > 16) return -1;
    char a[20];
    memcpy(a, s, (size_t)(slash - s));
    a[slash - s] = 0;
    long i, n;
    if (parse_num(a, 0, SHARD_MAX - 1, &i) < 0 || parse_num(slash + 1, 1, SHARD_MAX, &n) < 0 ||
        i >= n)
        return -1;
    *index = i;
    *count = n;
    return 0;
}

static int set(shard *out, long i, long n, const char *src, char *err, size_t errlen)
{
    if (i < 0 || i >= n) {
        snprintf(err, errlen, "%s: index %ld is not below the shard count %ld", src, i, n);
        return -1;
    }
    out->index = i;
    out->count = n;
    snprintf(out->source, sizeof out->source, "%s", src);
    return 0;
}

int shard_resolve(const shard_env *e, shard *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    out->count = 1;
    long i, n, lo = 0;
    if (e->shard_flag) {
        if (shard_parse(e->shard_flag, &i, &n) < 0) {
            snprintf(err, errlen, "--shard '%s' is not I/N with 0 <= I < N <= %d",
                     e->shard_flag, SHARD_MAX);
            return -1;
        }
        return set(out, i, n, "--shard", err, errlen);
    }
    if (e->shards_flag && parse_num(e->shards_flag, 1, SHARD_MAX, &n) < 0) {
        snprintf(err, errlen, "--shards '%s' is not a count in 1..%d", e->shards_flag, SHARD_MAX);
        return -1;
    }
    if (e->job_index && *e->job_index) {
        if (parse_num(e->job_index, 0, SHARD_MAX - 1, &i) < 0) {
            snprintf(err, errlen, "JOB_COMPLETION_INDEX '%.40s' is not an index", e->job_index);
            return -1;
        }
        if (!e->shards_flag) {
            if (!e->shard_count || !*e->shard_count) {
                snprintf(err, errlen, "JOB_COMPLETION_INDEX is set but the shard count is not: "
                         "give --shards N or SPLAT_SHARD_COUNT (the Job's completions)");
                return -1;
            }
            if (parse_num(e->shard_count, 1, SHARD_MAX, &n) < 0) {
                snprintf(err, errlen, "SPLAT_SHARD_COUNT '%.40s' is not a count in 1..%d",
                         e->shard_count, SHARD_MAX);
                return -1;
            }
        }
        return set(out, i, n, "JOB_COMPLETION_INDEX", err, errlen);
    }
    if (e->slurm_id && *e->slurm_id) {
        if (parse_num(e->slurm_id, 0, 100000000, &i) < 0) {
            snprintf(err, errlen, "SLURM_ARRAY_TASK_ID '%.40s' is not an index", e->slurm_id);
            return -1;
        }
        if (e->slurm_min && *e->slurm_min && parse_num(e->slurm_min, 0, i, &lo) < 0) {
            snprintf(err, errlen, "SLURM_ARRAY_TASK_MIN '%.40s' is not an index at most "
                     "SLURM_ARRAY_TASK_ID (%ld)", e->slurm_min, i);
            return -1;
        }
        if (!e->shards_flag) {
            if (!e->slurm_count || !*e->slurm_count) {
                snprintf(err, errlen, "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT "
                         "is not (or give --shards N)");
                return -1;
            }
            if (parse_num(e->slurm_count, 1, SHARD_MAX, &n) < 0) {
                snprintf(err, errlen, "SLURM_ARRAY_TASK_COUNT '%.40s' is not a count in 1..%d",
                         e->slurm_count, SHARD_MAX);
                return -1;
            }
        }
        return set(out, i - lo, n, "SLURM_ARRAY_TASK_ID", err, errlen);
    }
    if (e->shards_flag) {
        snprintf(err, errlen, "--shards N needs an index: --shard I/N, JOB_COMPLETION_INDEX or "
                 "SLURM_ARRAY_TASK_ID");
        return -1;
    }
    return 0;
}

long shard_filter(const shard *s, long *todo, long n)
{
    if (s->count <= 1) return n;
    long k = 0;
    for (long j = 0; j < n; j++)
        if (todo[j] % s->count == s->index) todo[k++] = todo[j];
    return k;
}
