/* cache.h — the prepared-cloud cache: one versioned binary file per source file.
 *
 * The cache file (cachefile.h: header, key, atomic write, guarded mapping) is a header page
 * (the source's size, mtime and content hash, k, counts, summary) followed by the prepared
 * array block of prepared.h, verbatim. It is loaded with a guarded mmap: a cached load copies
 * nothing and redoes no kNN, and a cache file cut under the daemon reads as zeros and is
 * reported (pc_prepared_check), never a SIGBUS. A cache whose source, version or k changed is
 * rebuilt; a truncated or corrupt one gives a warning (through the warn callback) and is
 * rebuilt, never loaded. */
#pragma once
#include <stdint.h>

#include "prepared.h"
#include "progress.h"
#include "sd_err.h"

#define CACHE_EXT ".splc"

typedef struct cache_desc {
    const char *dir;   /* default NULL: $SPLATD_CACHE, else $XDG_CACHE_HOME/splatd, else
                          ~/.cache/splatd, else a .splatd-cache directory beside the source */
    int k;             /* default PREP_DEFAULT_K (24): neighbours for prep (part of the key) */
    int threads;       /* default 0: every core */
    int force;         /* rebuild even when a valid cache exists */
    prep_progress_fn progress; /* default: none (progress.h) */
    void (*warn)(void *user, const char *msg);                        /* default: none */
    void *user;
} cache_desc;

typedef struct cache_result {
    int hit;               /* 1: loaded from the cache, 0: prepared now */
    char path[4096];       /* the cache file */
    char why[256];         /* why it was (re)built: "no cache", "source changed", ... */
    double t_read;         /* seconds: file parse (miss) or mmap + checks (hit) */
    double t_prep;         /* seconds: preprocessing (miss) */
    double t_write;        /* seconds: cache write (miss) */
    uint64_t file_size;
    int write_failed;      /* 1: prepared, but the cache could not be written (write_error) */
    char write_error[600];
} cache_result;

/* cache_open_cloud: returns in out the prepared cloud of the file src: from a valid cache
 * (mmapped) or by loading, preparing and caching it. Returns 0 or a negative SD_E* code. A cache
 * that cannot be written (read-only directory, one others may write) is reported through warn
 * and res->write_failed, not as an error: the prepared cloud is still returned. Caches are
 * written to an unnamed (O_TMPFILE) or random O_EXCL|O_NOFOLLOW file in the cache directory,
 * mode 0600, and renamed into place. */
int cache_open_cloud(const char *src, const cache_desc *d, pc_prepared *out, cache_result *res,
                     sd_err *err);

/* cache_probe: 1 when src has a cache under dir (NULL: the default) that cache_open_cloud
 * would load for k (<= 0: the default): this version and k, the source's size and mtime, an
 * intact header and the right file size. Cheap (one header read, no hashing), for listings;
 * the load still checks the content hashes. 0 otherwise. */
int cache_probe(const char *src, const char *dir, int k);
/* cache_probe_points: cache_probe that also gives the prepared cloud's point count (from the
 * header) in *points when it returns 1 (points may be NULL). */
int cache_probe_points(const char *src, const char *dir, int k, uint64_t *points);

/* cache_sweep: removes from directory dir the temporary files of cache writers (flat and LOD)
 * that died (killed while writing, before their rename); a live writer's are kept. *removed
 * (may be NULL) gets their count. Returns 0 (a missing directory is nothing to sweep). */
int cache_sweep(const char *dir, int *removed);
/* cache_dir_for: the cache directory for dir (NULL: the default) in buf. Returns 0, or -1 when
 * the default depends on each source file's directory (no $SPLATD_CACHE, $XDG_CACHE_HOME,
 * $HOME). */
int cache_dir_for(const char *dir, char *buf, size_t len);

/* cache_path_for: the cache file path for src under directory dir (NULL: the default). */
int cache_path_for(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err);

/* cache__set_version: rewrites the version field of a cache file (with a valid checksum), so
 * tests can check that a cache of another version is rebuilt. Internal; returns 0 or -1. */
int cache__set_version(const char *cache_path, uint32_t version);

/* cache__seal: makes the cache file at cache_path describe the source src (its size, time and
 * content hash) and gives it valid checksums over what it holds (the block's over at most the
 * length its header claims), so that a fuzzer's bytes reach the checks behind the checksums.
 * Internal (tests/fuzz); returns 0 or -1. */
int cache__seal(const char *cache_path, const char *src);
/* cache__load: the loader of cache_open_cloud alone: maps and checks the cache file at
 * cache_path for source src and k. Returns 1 with *out (free with pc_prepared_free), 0 when
 * out of date, -1 when damaged; why says which. Internal (tests/fuzz). */
int cache__load(const char *cache_path, const char *src, int k, pc_prepared *out, char *why,
                size_t whylen);
