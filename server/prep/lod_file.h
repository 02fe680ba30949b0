/* lod_file.h — the LOD cache file (layout in lod.h), through cachefile.h: internal interface
 * between lod_file.c (header, checks, loading, the writer) and lod_build.c. */
#pragma once
#include <pthread.h>
#include <stdint.h>

#include "cachefile.h"
#include "lod.h"

typedef cf_key lod_src_key;   /* size, mtime, sd_hash64 of the first and last MiB */

/* lod__src_key: the key of the regular file src. Returns 0 or SD_EIO. */
int lod__src_key(const char *src, lod_src_key *key, sd_err *err);

/* lod__options: the build options of d that a cache is keyed by (k, grid_bits, leaf_max, each
 * with its default when 0), folded into one number. */
uint64_t lod__options(const lod_desc *d);

/* The writer: one unnamed (or randomly named) file, node data appended by any thread, the
 * table and header written at the end, then fsync and rename (cachefile.h). When the cache
 * directory cannot be written, an unnamed file in the temporary directory instead, never
 * published: the cloud is loaded from it (lod__load_built) and it is gone when closed. */
typedef struct lod_writer {
    cf_writer cf;
    uint64_t off;             /* end of the data so far */
    pthread_mutex_t mu;
    int have_mu;
} lod_writer;

/* lod__writer_open: a writer for the LOD cache cpath of d (d->warn is told when it falls back
 * to the temporary directory). Returns 0, or SD_EIO naming both directories when neither can
 * be written. */
int lod__writer_open(lod_writer *w, const char *cpath, const lod_desc *d, sd_err *err);
/* lod__writer_append: appends len bytes at the next LOD_NODE_ALIGN boundary (thread-safe);
 * *off gets where. Returns 0 or SD_EIO. */
int lod__writer_append(lod_writer *w, const void *data, size_t len, uint64_t *off, sd_err *err);
/* lod__writer_commit: writes the node table and the header for c (c->nodes: the table in
 * memory; its k, grid_bits and leaf_max are the build's options), fsyncs, renames into place.
 * Returns 0 or SD_EIO. */
int lod__writer_commit(lod_writer *w, const lod_cloud *c, const lod_src_key *key, sd_err *err);
/* lod__load_built: loads what w committed for src (the cache file, or the writer's unnamed
 * temporary file). Returns as lod_load_file. */
int lod__load_built(const lod_writer *w, const char *src, const lod_desc *d, lod_cloud *out,
                    char *why, size_t whylen);
/* lod__build_failed: rc (a failed build's code) with err naming the directory the build wrote
 * its cache and scratch files in, when rc is an I/O error and w was open (a full or failing
 * disk must be findable from the message). Returns rc. */
int lod__build_failed(const lod_writer *w, int rc, sd_err *err);
/* lod__writer_abort: closes and forgets the file (nothing is left behind); safe twice. */
void lod__writer_abort(lod_writer *w);
/* lod__scratch: an unnamed scratch file in the writer's directory (gone when closed or when the
 * process dies). Returns the fd or SD_EIO. */
int lod__scratch(lod_writer *w, sd_err *err);
