/* lod_file.h — the LOD cache file (layout in lod.h): internal interface between lod_file.c
 * (header, checks, mapping, the atomic writer) and lod_build.c. */
#pragma once
#include <limits.h>
#include <pthread.h>
#include <stdint.h>

#include "lod.h"

/* Bump when the layout or the meaning of any value changes. */
#define LOD_VERSION 3u

typedef struct lod_src_key {
    uint64_t size, hash;      /* hash: sd_hash64 of the first and last MiB */
    int64_t mtime_ns;
} lod_src_key;

/* lod__src_key: the key of the regular file src. Returns 0 or SD_EIO. */
int lod__src_key(const char *src, lod_src_key *key, sd_err *err);

/* The writer: one unnamed (or randomly named) file in the cache directory, node data appended
 * by any thread, the table and header written at the end, then fsync and rename. */
typedef struct lod_writer {
    int dfd, fd, named;
    char tmp[PATH_MAX], base[PATH_MAX], path[PATH_MAX];
    uint64_t off;             /* end of the data so far */
    pthread_mutex_t mu;
} lod_writer;

int lod__writer_open(lod_writer *w, const char *cpath, sd_err *err);
/* lod__writer_append: appends len bytes at the next LOD_NODE_ALIGN boundary (thread-safe);
 * *off gets where. Returns 0 or SD_EIO. */
int lod__writer_append(lod_writer *w, const void *data, size_t len, uint64_t *off, sd_err *err);
/* lod__writer_commit: writes the node table and the header for c (c->nodes: the table in
 * memory), fsyncs, renames into place. Returns 0 or SD_EIO. */
int lod__writer_commit(lod_writer *w, const lod_cloud *c, const lod_src_key *key, sd_err *err);
/* lod__writer_abort: closes and forgets the file (nothing is left behind). */
void lod__writer_abort(lod_writer *w);
/* lod__pwrite_all, lod__pread_all: all len bytes at off (EINTR retried). 0 or -1 (errno). */
int lod__pwrite_all(int fd, const void *p, size_t len, uint64_t off);
int lod__pread_all(int fd, void *p, size_t len, uint64_t off);
/* lod__scratch: an unnamed scratch file in the writer's directory (gone when closed or when the
 * process dies). Returns the fd or SD_EIO. */
int lod__scratch(lod_writer *w, sd_err *err);
