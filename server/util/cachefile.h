/* cachefile.h — one cache file: its name, its key, its header, its atomic write and its guarded
 * read-only mapping. Both cache kinds use it: the prepared cloud (prep/cache.c, .splc) and the
 * level-of-detail octree (prep/lod_file.c, .splod).
 *
 * A cache file is a header page followed by the kind's data:
 *
 *   [0, 4096)  cf_head, then the kind's meta (its summary values, meta_len bytes), then
 *              header_hash = sd_hash64 of every byte before it; zero padding
 *   [4096, )   the kind's data; [body_off, body_off + body_len) is checksummed (body_hash)
 *
 * in the host's byte order (byte_order rejects a file from another-endian host). The header
 * holds the key the cache is valid for: the kind (magic) and its format version, the source
 * file's size, mtime and content hash (the whole file, or its first and last MiB: hash_how),
 * and the build options (the kind folds them into one number: k, grid size, leaf size). A cache
 * whose key differs is out of date and rebuilt; one whose header, size or body checksum is wrong
 * is damaged, reported and rebuilt, never used.
 *
 * Writing: a new file in the cache directory (created 0700; refused when another user owns it
 * or others may write it) that nobody else can have made or linked: unnamed (O_TMPFILE) where
 * the file system has it, else a random name created with O_EXCL | O_NOFOLLOW; mode 0600;
 * filled, fsynced, given a random name (linkat) and renamed over the cache's name, the
 * directory fsynced. A writer killed at any moment leaves no file that loads; a named leftover
 * of a dead writer is removed by cf_sweep. A writer can also be opened in the temporary
 * directory (cf_writer_open_temp): an unnamed file never published, read back through its fd,
 * for a cache directory that cannot be written.
 *
 * Reading: cf_open checks the header (cheap: one page, no hashing), cf_check_source the source's
 * content hash, then the kind reads its data with cf_pread_all or through cf_map: a read-only
 * mapping guarded by sd_sigbus.h's zero fill, so that a cache file truncated under a reader
 * never kills the process: cf_map_changed says afterwards that the reads saw a shorter file. */
#pragma once
#include <limits.h>
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

enum { CF_PAGE = 4096 };
enum { CF_HASH_ALL = 0, CF_HASH_ENDS = 1 }; /* the source's content hash: whole, first+last MiB */

/* The key of a source file. */
typedef struct cf_key {
    uint64_t size;
    int64_t mtime_ns;
    uint64_t hash;            /* sd_hash64 of the content (hash_how) */
} cf_key;

/* The common part of a cache header, stored verbatim at offset 0. */
typedef struct cf_head {
    char magic[8];            /* the kind */
    uint32_t version;         /* the kind's format version */
    uint32_t byte_order;      /* 0x01020304 as written */
    cf_key src;               /* the source it was built from */
    uint64_t options;         /* the build options, folded by the kind */
    uint64_t file_len;        /* the whole file */
    uint64_t body_off, body_len, body_hash; /* the checksummed section */
    uint32_t meta_len;        /* bytes of the kind's meta after this struct */
    uint32_t hash_how;        /* CF_HASH_*: how src.hash was taken */
} cf_head;
_Static_assert(sizeof(cf_head) == 88, "cf_head is stored verbatim");

/* What a kind of cache is: its name in messages, magic, version, meta size, key hash, and how
 * to print its options (for "built with ..., asked ..."). */
typedef struct cf_kind {
    const char *what;         /* "cache", "LOD cache" */
    char magic[8];
    uint32_t version;
    uint32_t meta_len;        /* a multiple of 8, at most CF_META_MAX */
    uint32_t hash_how;
    void (*describe)(uint64_t options, char *buf, size_t len);
} cf_kind;
enum { CF_META_MAX = CF_PAGE - (int)sizeof(cf_head) - 8 };

/* ---- names ---- */

/* cf_dir_for: the cache directory for dir (NULL: the default: $SPLATD_CACHE, else
 * $XDG_CACHE_HOME/splatd, else ~/.cache/splatd) in buf. Returns 0, or -1 when the default
 * depends on each source file's directory (none of those set). */
int cf_dir_for(const char *dir, char *buf, size_t len);
/* cf_default_dir: the default cache directory for the source file src (a real path): as
 * cf_dir_for, else a .splatd-cache directory beside the source. */
void cf_default_dir(const char *src, char *buf, size_t len);
/* cf_path: the cache file of src under dir (NULL: the default) for k:
 * DIR/NAME.HASH.kK.EXT, HASH a hash of src's real path (two files of one name apart). Returns 0,
 * SD_EIO (src cannot be resolved) or SD_ELIMIT (too long), with err. */
int cf_path(const char *src, const char *dir, int k, const char *ext, char *buf, size_t len,
            sd_err *err);

/* ---- the source's key ---- */

/* cf_key_stat: the size and mtime of the regular file src in key (hash untouched). Opens it
 * with O_NONBLOCK: a FIFO in place of a file is refused at once. Returns 0 or SD_EIO. */
int cf_key_stat(const char *src, cf_key *key, sd_err *err);
/* cf_key_hash: key->hash of src by how (CF_HASH_*), read with pread (a mapped source truncated
 * under the hash would raise SIGBUS). The file must still have key's size and mtime (a stat
 * taken earlier): the hash must describe the bytes the caller parsed or is about to trust;
 * else SD_EIO saying it changed. Returns 0 or SD_EIO / SD_ENOMEM. */
int cf_key_hash(const char *src, uint32_t how, cf_key *key, sd_err *err);

/* ---- reading ---- */

typedef struct cf_file {
    int fd;                   /* -1 when closed */
    uint64_t size;            /* of the file when opened */
    cf_head head;
    uint8_t meta[CF_META_MAX];/* the kind's meta (head.meta_len bytes) */
    char path[PATH_MAX];
} cf_file;

/* cf_open: opens the cache file path (fd < 0; or, fd >= 0, a duplicate of fd, for a file
 * without a name: path then only names it in messages) of kind k and checks its header: intact
 * (magic, byte order, layout, checksum), this version and options, built from a source of
 * src's size and mtime (its content hash: cf_check_source), a file of the size the header
 * says with its body inside. Returns 1 when it matches (f open: close with cf_close), 0 when
 * there is none or it is out of date, -1 when it is damaged; why says which. Never follows a
 * symlink at path; a FIFO or other non-regular file there is damaged, at once. */
int cf_open(const cf_kind *k, const char *path, int fd, const cf_key *src, uint64_t options,
            cf_file *f, char *why, size_t whylen);
/* cf_check_source: 1 when the source file src has the content hash f's header was built
 * from (and still the size and mtime), else 0 with why. */
int cf_check_source(const cf_file *f, const char *src, char *why, size_t whylen);
/* cf_read_body: reads f's body into buf (head.body_len bytes) and checks its checksum.
 * Returns 1, or -1 with why (short read: the file changed; checksum mismatch: corrupt). */
int cf_read_body(const cf_file *f, void *buf, char *why, size_t whylen);
/* cf_loaded: the outcome of a cache's load attempt got (as cf_open: 1 loaded, 0 none or out of
 * date, -1 damaged; ignored when force): 1 when it loaded (why becomes "cache valid"); else 0,
 * why saying why it is built ("rebuild forced" when force), and a damaged one reported through
 * warn (may be NULL) as "WHAT PATH: WHY; rebuilding it". */
int cf_loaded(int force, int got, const char *what, const char *path, char *why, size_t whylen,
              void (*warn)(void *user, const char *msg), void *user);
/* cf_close: closes f; safe twice. */
void cf_close(cf_file *f);

/* The guarded read-only mapping of a whole cache file. */
typedef struct cf_map {
    const uint8_t *addr;
    size_t len;
    int guard;                /* sd_sigbus region */
    char path[PATH_MAX];
} cf_map;

/* cf_map_open: maps f's file read-only (length f->size), guarded. Returns the map (free with
 * cf_map_close) or NULL with why. */
cf_map *cf_map_open(const cf_file *f, char *why, size_t whylen);
/* cf_map_changed: 1 when a read of m found the file shorter than mapped (the reads from there
 * on gave zeros), else 0. Ask it after reading what must be trusted. */
int cf_map_changed(const cf_map *m);
/* cf_map_close: unmaps and frees m (NULL: nothing). */
void cf_map_close(cf_map *m);
/* cf_changed_error: fills err (SD_ESTALE) with the error of a cache file that changed under its
 * reader: what ("cache", "LOD cache"), the file's base name (what a client may be told; not
 * where the server keeps it), detail, and that it is rebuilt at the next open. Returns
 * SD_ESTALE. */
int cf_changed_error(sd_err *err, const char *what, const char *path, const char *detail);

/* ---- writing ---- */

typedef struct cf_writer {
    int dfd, fd;              /* the directory, the file; -1 when closed */
    int named;                /* the file has the temporary name tmp */
    int temp;                 /* an unnamed file in the temporary directory, never published */
    char dir[PATH_MAX], base[NAME_MAX + 1], path[PATH_MAX], tmp[PATH_MAX];
} cf_writer;

/* cf_open_dir: creates dir (and parents, 0700) when missing and opens it without following a
 * symlink; refuses one another user owns or others may write. Returns the fd or SD_EIO with
 * err naming the directory and why. */
int cf_open_dir(const char *dir, sd_err *err);
/* cf_writer_open: a new temporary file for the cache file cpath, in its directory. Returns 0,
 * or SD_EIO with err naming the directory or the file (errno kept from the failing call). */
int cf_writer_open(cf_writer *w, const char *cpath, sd_err *err);
/* cf_writer_open_temp: a new unnamed file in the temporary directory ($TMPDIR, else /tmp) for
 * the cache of cpath, never published: cf_writer_commit keeps it open for cf_open(fd). Returns
 * 0 or SD_EIO naming that directory. */
int cf_writer_open_temp(cf_writer *w, const char *cpath, sd_err *err);
/* cf_scratch: an unnamed scratch file (read and write) in w's directory, gone when closed or
 * when the process dies. Returns the fd or SD_EIO naming the directory. */
int cf_scratch(const cf_writer *w, sd_err *err);
/* cf_pwrite_all, cf_pread_all: all len bytes at off (EINTR retried). Return 0 or -1 (errno;
 * a read past the end is -1 with errno EIO). */
int cf_pwrite_all(int fd, const void *p, size_t len, uint64_t off);
int cf_pread_all(int fd, void *p, size_t len, uint64_t off);
/* cf_writer_commit: writes the header page of kind k (h: src, options, file_len and the body
 * fields set; the rest is filled here) with meta (k->meta_len bytes), then makes the file the
 * cache: fsync, a random name, rename over the cache's name, fsync of the directory. A temp
 * writer's file stays open and unnamed (w->fd). Returns 0 or SD_EIO with err; the file is
 * closed and removed on failure. */
int cf_writer_commit(cf_writer *w, const cf_kind *k, cf_head *h, const void *meta, sd_err *err);
/* cf_writer_abort: closes w and removes its file when it has a name; safe twice and after a
 * commit (a temp writer's kept fd is closed here). */
void cf_writer_abort(cf_writer *w);

/* cf_sweep: removes from directory dir the temporary files of cache writers (any kind) that
 * died before their rename; a live writer's are kept. *removed (may be NULL) gets their count.
 * Returns 0 (a missing directory is nothing to sweep). */
int cf_sweep(const char *dir, int *removed);

/* cf__set_version: rewrites the version of the cache file path (its checksum made valid), so
 * that tests can check that a cache of another version is rebuilt. Returns 0 or -1. */
int cf__set_version(const char *path, uint32_t version);
/* cf__seal: makes the cache file path describe the source src by how (its size, mtime and
 * content hash) and gives it valid checksums over what it holds (the body's over the part
 * inside the file), so that a fuzzer's bytes reach the checks behind them. options (when
 * set_options) replaces the header's. Internal (tests/fuzz); returns 0 or -1. */
int cf__seal(const char *path, const char *src, uint32_t how, int set_options,
             uint64_t options);
