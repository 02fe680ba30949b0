/* cache.c — prepared-cloud cache files (see cache.h).
 *
 * File layout (host byte order; the byte_order field rejects a file from another-endian host):
 *   [0, 4096)            cache_header (below), zero padded
 *   [4096, 4096 + len)   the prepared array block of prepared.h, verbatim
 * header_hash covers the header bytes before it; block_hash covers the block, so a truncated or
 * bit-flipped cache is detected and rebuilt, never used. */
#include "cache.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <signal.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "cloud.h"
#include "prep.h"
#include "sd_hash.h"

/* Bump when the layout of prepared.h or the meaning of any prepared value changes, or the
 * hash of the keys and checksums (5: XXH3-64 from libxxhash instead of splatd's own). */
#define CACHE_VERSION 5u
#define CACHE_MAGIC "SPLATDC\0"
#define CACHE_BLOCK_OFFSET 4096u

typedef struct cache_header {
    char magic[8];
    uint32_t version;
    uint32_t byte_order;       /* 0x01020304 as written */
    uint64_t src_size;
    int64_t src_mtime_ns;
    uint64_t src_hash;         /* sd_hash64 of the whole source file */
    uint32_t k, attrs;
    uint64_t n, nbatches, block_len, block_hash;
    double offset[3], bmin[3], bmax[3];
    float sigma, F_raw_p99, F_pct[5], radius_median;
    uint64_t n_dropped;
    char format[64];
    char scalar_name[32];
    pc_prep_stats stats;
    uint64_t header_hash;      /* sd_hash64 of every byte above */
} cache_header;
_Static_assert(sizeof(cache_header) <= CACHE_BLOCK_OFFSET, "cache header must fit its page");

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* mkdir_p: creates dir and its missing parents, each 0700: the cache holds the data of the
 * clouds, and a directory only its owner can write is where nobody else can plant a link. */
static int mkdir_p(const char *dir)
{
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", dir);
    for (char *p = tmp + 1; *p; p++) {
        if (*p != '/') continue;
        *p = 0;
        if (mkdir(tmp, 0700) < 0 && errno != EEXIST) return -1;
        *p = '/';
    }
    if (mkdir(tmp, 0700) < 0 && errno != EEXIST) return -1;
    return 0;
}

/* open_cache_dir: creates dir when missing and opens it (never through a symlink) for the
 * *at() calls that write in it. Refuses a directory that another user owns or that group or
 * others may write: there, anyone could swap names under the writer. Returns the fd, or -1
 * with err filled. */
int cache__open_dir(const char *dir, sd_err *err)
{
    if (mkdir_p(dir) < 0) {
        sd_errf(err, SD_EIO, "cannot create cache directory %s: %s", dir, strerror(errno));
        return -1;
    }
    int dfd = open(dir, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (dfd < 0) {
        sd_errf(err, SD_EIO, "cannot open cache directory %s: %s", dir,
                errno == ELOOP ? "it is a symbolic link" : strerror(errno));
        return -1;
    }
    struct stat st;
    if (fstat(dfd, &st) < 0) {
        sd_errf(err, SD_EIO, "cache directory %s: %s", dir, strerror(errno));
        close(dfd);
        return -1;
    }
    if (st.st_uid != geteuid() || (st.st_mode & (S_IWGRP | S_IWOTH))) {
        sd_errf(err, SD_EIO, "cache directory %s is %s (mode %04o); caches are written only "
                "in a directory this user owns and nobody else can write (make it 0700)", dir,
                st.st_uid != geteuid() ? "owned by another user" : "writable by others",
                (unsigned)(st.st_mode & 07777));
        close(dfd);
        return -1;
    }
    return dfd;
}

/* Temporary names: "<cache file name>.tmp.<pid>.<12 hex digits>". The pid lets the sweep tell
 * a dead writer's leftover from a live writer's file; the random part makes the name
 * unpredictable. */
#define CACHE_TMP_TAG ".tmp."

static void tmp_name(const char *base, char *buf, size_t len)
{
    uint8_t r[6] = {0};
    if (getrandom(r, sizeof r, 0) != (ssize_t)sizeof r) {
        /* No entropy source: the names stay unique (O_EXCL below), only predictable. */
        uint64_t t = (uint64_t)(now_s() * 1e9);
        memcpy(r, &t, sizeof r);
    }
    snprintf(buf, len, "%s" CACHE_TMP_TAG "%ld.%02x%02x%02x%02x%02x%02x", base, (long)getpid(),
             r[0], r[1], r[2], r[3], r[4], r[5]);
}

int cache_sweep(const char *dir, int *removed)
{
    if (removed) *removed = 0;
    DIR *d = dir ? opendir(dir) : NULL;
    if (!d) return 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        const char *t = strstr(e->d_name, ".splc" CACHE_TMP_TAG);
        if (!t) continue;
        char *end;
        long pid = strtol(t + strlen(".splc" CACHE_TMP_TAG), &end, 10);
        if (pid <= 0 || (*end != '.' && *end != 0)) continue;
        /* A live writer's file (this process's or another's: a `splatd prep` beside the
         * daemon) is left alone; a dead one's is garbage. */
        if (pid == (long)getpid() || kill((pid_t)pid, 0) == 0 || errno != ESRCH) continue;
        if (unlinkat(dirfd(d), e->d_name, 0) == 0 && removed) (*removed)++;
    }
    closedir(d);
    return 0;
}

int cache_dir_for(const char *dir, char *buf, size_t len)
{
    if (dir && *dir) {
        snprintf(buf, len, "%s", dir);
        return 0;
    }
    const char *e;
    if ((e = getenv("SPLATD_CACHE")) && *e) snprintf(buf, len, "%s", e);
    else if ((e = getenv("XDG_CACHE_HOME")) && *e) snprintf(buf, len, "%s/splatd", e);
    else if ((e = getenv("HOME")) && *e) snprintf(buf, len, "%s/.cache/splatd", e);
    else return -1; /* the default then depends on each source's directory */
    return 0;
}

/* Picks the default cache directory (see cache_desc.dir) for src. */
void cache__default_dir(const char *src, char *buf, size_t len)
{
    if (cache_dir_for(NULL, buf, len) == 0) return;
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", src);
    snprintf(buf, len, "%s/.splatd-cache", dirname(tmp));
}

int cache_path_for(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err)
{
    char real[PATH_MAX], d[PATH_MAX];
    if (!realpath(src, real))
        return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    if (dir && *dir) snprintf(d, sizeof d, "%s", dir);
    else cache__default_dir(real, d, sizeof d);
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", real);
    const char *base = basename(tmp);
    /* The absolute path's hash keeps two files of the same name in one cache apart. */
    uint64_t ph = sd_hash64(real, strlen(real), 0);
    int w = snprintf(buf, len, "%s/%s.%016llx.k%d.splc", d, base, (unsigned long long)ph, k);
    if (w < 0 || (size_t)w >= len) return sd_errf(err, SD_ELIMIT, "%s: cache path too long", src);
    return 0;
}

/* Hashes the whole file at fd (size bytes), read in 1 MiB pieces with pread rather than
 * mapped: a mapped source truncated under the hash would raise SIGBUS in the daemon. Returns 0,
 * -1 with errno on a read error, or -2 when the file ended before size bytes (it changed). */
static int hash_file(int fd, uint64_t size, uint64_t *out)
{
    enum { PIECE = 1 << 20 };
    uint8_t *buf = malloc(PIECE);
    if (!buf) return -1;
    sd_hash_state hs;
    sd_hash64_init(&hs, 0);
    uint64_t off = 0;
    int rc = 0;
    while (off < size) {
        size_t want = size - off < PIECE ? (size_t)(size - off) : PIECE;
        ssize_t r = pread(fd, buf, want, (off_t)off);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) {
            rc = r < 0 ? -1 : -2;
            break;
        }
        sd_hash64_update(&hs, buf, (size_t)r);
        off += (uint64_t)r;
    }
    free(buf);
    *out = sd_hash64_final(&hs);
    return rc;
}

typedef struct src_key {
    uint64_t size, hash;
    int64_t mtime_ns;
} src_key;

/* source_key: the size and modification time of the regular file src in key, and with
 * with_hash its content hash as well. With with_hash and key->size already set (a stat taken
 * earlier), a file whose size or time differs now fails as changed: the hash must describe the
 * bytes the caller parsed or is about to trust. Returns 0 or SD_EIO with err. */
static int source_key(const char *src, src_key *key, int with_hash, sd_err *err)
{
    /* O_NONBLOCK: a FIFO put in place of a cloud must not block the open until a writer comes;
     * it is refused by the regular-file check at once. */
    int fd = open(src, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) < 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        return sd_errf(err, SD_EIO, "%s: not a regular file", src);
    }
    uint64_t size = (uint64_t)st.st_size;
    int64_t mtime = (int64_t)st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec;
    if (!with_hash) {
        close(fd);
        key->size = size;
        key->mtime_ns = mtime;
        return 0;
    }
    int rc = size != key->size || mtime != key->mtime_ns ? -2 : hash_file(fd, size, &key->hash);
    int e = errno;
    close(fd);
    if (rc == -2)
        return sd_errf(err, SD_EIO, "%s: the file changed while it was being read (its size or "
                       "time changed); try again once it is complete", src);
    if (rc < 0) return sd_errf(err, SD_EIO, "%s: cannot read: %s", src, strerror(e));
    return 0;
}

/* Reads and checks the header of the cache file open at fd: intact (magic, byte order,
 * checksum), this version, built with k from a source of key's size and mtime (and content hash
 * when check_hash), and a file of the size the header says. Returns 1 when it matches, 0 when it
 * is out of date, -1 when it is damaged; why says which. */
static int check_header(int fd, const struct stat *st, const src_key *key, int check_hash, int k,
                        cache_header *h, char *why, size_t whylen)
{
    if ((uint64_t)st->st_size < CACHE_BLOCK_OFFSET ||
        pread(fd, h, sizeof *h, 0) != (ssize_t)sizeof *h) {
        snprintf(why, whylen, "it is truncated (%lld bytes)", (long long)st->st_size);
        return -1;
    }
    if (memcmp(h->magic, CACHE_MAGIC, 8) != 0 || h->byte_order != 0x01020304u) {
        snprintf(why, whylen, "it has a wrong magic or byte order");
        return -1;
    }
    if (h->header_hash != sd_hash64(h, offsetof(cache_header, header_hash), 0)) {
        snprintf(why, whylen, "its header is corrupt (checksum mismatch)");
        return -1;
    }
    if (h->version != CACHE_VERSION) {
        snprintf(why, whylen, "cache version %u, this splatd writes %u", h->version, CACHE_VERSION);
        return 0;
    }
    if (h->src_size != key->size || h->src_mtime_ns != key->mtime_ns ||
        (check_hash && h->src_hash != key->hash)) {
        snprintf(why, whylen, "source changed (size, mtime or content)");
        return 0;
    }
    if ((int)h->k != k) {
        snprintf(why, whylen, "cache built with k = %u, k = %d asked", h->k, k);
        return 0;
    }
    /* The counts are bounded by the file before the block length they imply is computed:
     * that length is a 64-bit sum that a huge count would wrap around to a plausible value. */
    uint64_t room = (uint64_t)st->st_size;
    if (h->n == 0 || h->n > room / 12 || h->nbatches == 0 || h->nbatches > h->n ||
        h->nbatches > room / sizeof(pc_batch)) {
        snprintf(why, whylen, "its counts (%llu points, %llu batches) cannot fit its %lld bytes",
                 (unsigned long long)h->n, (unsigned long long)h->nbatches,
                 (long long)st->st_size);
        return -1;
    }
    uint64_t want = pc_prepared_block_len(h->n, h->attrs, h->nbatches);
    if (want != h->block_len || (uint64_t)st->st_size != CACHE_BLOCK_OFFSET + h->block_len) {
        snprintf(why, whylen, "it is truncated or has a wrong size (%lld bytes, %llu expected)",
                 (long long)st->st_size, (unsigned long long)(CACHE_BLOCK_OFFSET + want));
        return -1;
    }
    return 1;
}

/* Tries to map a valid cache. Returns 1 on success, 0 when there is none or it is out of date
 * (why says which), -1 when it is damaged (why says how: the caller warns). */
static int try_load(const char *cpath, const char *src, src_key *key, int k, pc_prepared *out,
                    char *why, size_t whylen)
{
    /* O_NOFOLLOW: a symlink at the cache's name is nobody's cache (it is replaced on write). */
    int fd = open(cpath, O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (fd < 0) {
        snprintf(why, whylen, "no cache");
        return 0;
    }
    struct stat st;
    cache_header h;
    int rc = -1;
    if (fstat(fd, &st) < 0) {
        snprintf(why, whylen, "it cannot be read: %s", strerror(errno));
        goto out;
    }
    /* The cheap checks first (header, version, k, the source's size and time): the source's
     * content is hashed only for a cache that could be used, never for one that is stale
     * anyway, nor before the source's own header has been looked at (cache_open_cloud). */
    rc = check_header(fd, &st, key, 0, k, &h, why, whylen);
    if (rc != 1) goto out;
    sd_err herr = {0};
    if (source_key(src, key, 1, &herr) < 0 || key->hash != h.src_hash) {
        snprintf(why, whylen, "source changed (content)");
        rc = 0;
        goto out;
    }
    rc = -1;
    size_t maplen = (size_t)st.st_size;
    uint8_t *m = mmap(NULL, maplen, PROT_READ, MAP_PRIVATE, fd, 0);
    if (m == MAP_FAILED) {
        snprintf(why, whylen, "it cannot be mapped: %s", strerror(errno));
        goto out;
    }
    if (sd_hash64(m + CACHE_BLOCK_OFFSET, h.block_len, 0) != h.block_hash) {
        munmap(m, maplen);
        snprintf(why, whylen, "its data is corrupt (checksum mismatch)");
        goto out;
    }
    /* The batches must tile [0, n) in order, as prep writes them: the count in the header and
     * the batches then agree (a count off by one within a section's alignment padding would
     * otherwise be taken as it is, and the renderer trusts the batches). */
    pc_prepared where = {.n = h.n, .attrs = h.attrs, .nbatches = h.nbatches};
    pc_prepared_bind(&where, m + CACHE_BLOCK_OFFSET);
    const pc_batch *bt = where.batches;
    uint64_t next = 0;
    for (uint64_t i = 0; i < h.nbatches; i++) {
        if (bt[i].first != next || bt[i].count == 0 || bt[i].count > h.n - next) {
            /* The message quotes the batch: written before the mapping goes. */
            snprintf(why, whylen, "batch %llu [%u, +%u) does not follow the previous one in its "
                     "%llu points", (unsigned long long)i, bt[i].first, bt[i].count,
                     (unsigned long long)h.n);
            munmap(m, maplen);
            goto out;
        }
        next += bt[i].count;
    }
    if (next != h.n) {
        munmap(m, maplen);
        snprintf(why, whylen, "its batches hold %llu points, its header says %llu",
                 (unsigned long long)next, (unsigned long long)h.n);
        goto out;
    }
    memset(out, 0, sizeof *out);
    out->n = h.n;
    out->attrs = h.attrs;
    out->k = h.k;
    out->nbatches = h.nbatches;
    memcpy(out->offset, h.offset, sizeof h.offset);
    memcpy(out->bmin, h.bmin, sizeof h.bmin);
    memcpy(out->bmax, h.bmax, sizeof h.bmax);
    out->sigma = h.sigma;
    out->F_raw_p99 = h.F_raw_p99;
    memcpy(out->F_pct, h.F_pct, sizeof h.F_pct);
    out->radius_median = h.radius_median;
    out->n_dropped = h.n_dropped;
    memcpy(out->format, h.format, sizeof out->format);
    memcpy(out->scalar_name, h.scalar_name, sizeof out->scalar_name);
    out->format[sizeof out->format - 1] = 0;
    out->scalar_name[sizeof out->scalar_name - 1] = 0;
    out->stats = h.stats;
    out->map = m;
    out->map_len = maplen;
    pc_prepared_bind(out, m + CACHE_BLOCK_OFFSET);
    rc = 1;
out:
    close(fd);
    return rc;
}

int cache_probe(const char *src, const char *dir, int k)
{
    return cache_probe_points(src, dir, k, NULL);
}

int cache_probe_points(const char *src, const char *dir, int k, uint64_t *points)
{
    if (k <= 0) k = PREP_DEFAULT_K;
    char cpath[4096], why[256];
    struct stat ss, cs;
    if (cache_path_for(src, dir, k, cpath, sizeof cpath, NULL) != 0 || stat(src, &ss) != 0)
        return 0;
    src_key key = {.size = (uint64_t)ss.st_size,
                   .mtime_ns = (int64_t)ss.st_mtim.tv_sec * 1000000000LL + ss.st_mtim.tv_nsec};
    int fd = open(cpath, O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (fd < 0) return 0;
    cache_header h;
    int ok = fstat(fd, &cs) == 0 && check_header(fd, &cs, &key, 0, k, &h, why, sizeof why) == 1;
    close(fd);
    if (ok && points) *points = h.n;
    return ok;
}

static int write_all(int fd, const void *p, size_t len)
{
    const uint8_t *b = p;
    while (len) {
        ssize_t w = write(fd, b, len);
        if (w < 0) {
            if (errno == EINTR) continue;
            return -1;
        }
        b += w;
        len -= (size_t)w;
    }
    return 0;
}

/* create_tmp: a new file for writing in directory dfd that no one else can have made or
 * linked: an unnamed O_TMPFILE file when the file system has them (nothing is left behind if
 * the process dies while writing), else a random name created with O_EXCL | O_NOFOLLOW (a
 * symlink planted there makes the create fail, never followed). *named is set to 1 and name
 * filled in the second case. Returns the fd or -1 with errno. */
int cache__create_tmp(int dfd, const char *base, char *name, size_t len, int *named)
{
    *named = 0;
    int fd = openat(dfd, ".", O_TMPFILE | O_WRONLY | O_CLOEXEC, 0600);
    if (fd >= 0) return fd;
    if (errno != EOPNOTSUPP && errno != EISDIR && errno != EINVAL && errno != ENOENT) return -1;
    for (int tries = 0; tries < 16; tries++) {
        tmp_name(base, name, len);
        fd = openat(dfd, name, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
        if (fd >= 0 || errno != EEXIST) break;
    }
    if (fd >= 0) *named = 1;
    return fd;
}

/* link_tmp: gives the unnamed file fd the new random name name in dfd (linkat fails, never
 * follows, when the name exists). Returns 0 or -1 with errno. */
int cache__link_tmp(int fd, int dfd, const char *base, char *name, size_t len)
{
    char proc[64];
    snprintf(proc, sizeof proc, "/proc/self/fd/%d", fd);
    for (int tries = 0; tries < 16; tries++) {
        tmp_name(base, name, len);
        int rc = linkat(AT_FDCWD, proc, dfd, name, AT_SYMLINK_FOLLOW);
        if (rc < 0 && errno == ENOENT) /* no /proc: the same through AT_EMPTY_PATH */
            rc = linkat(fd, "", dfd, name, AT_EMPTY_PATH);
        if (rc == 0 || errno != EEXIST) return rc;
    }
    return -1;
}

int cache__publish(int fd, int dfd, const char *base, char *tmp, size_t tmplen, int named,
                   int failed)
{
    int bad = failed || fsync(fd);
    int saved = errno;
    if (!bad && !named) {
        bad = cache__link_tmp(fd, dfd, base, tmp, tmplen) != 0;
        saved = errno;
        named = !bad;
    }
    if (close(fd) < 0 && !bad) {
        bad = 1;
        saved = errno;
    }
    if (!bad && renameat(dfd, tmp, dfd, base) < 0) {
        bad = 1;
        saved = errno;
    }
    if (bad) {
        if (named) unlinkat(dfd, tmp, 0);
        errno = saved;
        return -1;
    }
    fsync(dfd); /* make the rename durable */
    return 0;
}

/* Writes p to cpath: into a new temporary file in the cache directory (create_tmp), fsynced,
 * then renamed over cpath (rename replaces a symlink at cpath rather than following it) and
 * the directory fsynced. Returns 0 or SD_EIO with err. */
static int write_cache(const char *cpath, const src_key *key, const pc_prepared *p, sd_err *err)
{
    char dir[PATH_MAX], tmp[PATH_MAX];
    snprintf(dir, sizeof dir, "%s", cpath);
    char *slash = strrchr(dir, '/');
    const char *base = cpath;
    if (slash) {
        *slash = 0;
        base = slash + 1;
    } else {
        snprintf(dir, sizeof dir, ".");
    }

    static const uint8_t zero[CACHE_BLOCK_OFFSET];
    cache_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, CACHE_MAGIC, 8);
    h.version = CACHE_VERSION;
    h.byte_order = 0x01020304u;
    h.src_size = key->size;
    h.src_mtime_ns = key->mtime_ns;
    h.src_hash = key->hash;
    h.k = p->k;
    h.attrs = p->attrs;
    h.n = p->n;
    h.nbatches = p->nbatches;
    h.block_len = p->block_len;
    h.block_hash = sd_hash64(p->block, p->block_len, 0);
    memcpy(h.offset, p->offset, sizeof h.offset);
    memcpy(h.bmin, p->bmin, sizeof h.bmin);
    memcpy(h.bmax, p->bmax, sizeof h.bmax);
    h.sigma = p->sigma;
    h.F_raw_p99 = p->F_raw_p99;
    memcpy(h.F_pct, p->F_pct, sizeof h.F_pct);
    h.radius_median = p->radius_median;
    h.n_dropped = p->n_dropped;
    memcpy(h.format, p->format, sizeof h.format);
    memcpy(h.scalar_name, p->scalar_name, sizeof h.scalar_name);
    h.stats = p->stats;
    h.header_hash = sd_hash64(&h, offsetof(cache_header, header_hash), 0);

    int dfd = cache__open_dir(dir, err);
    if (dfd < 0) return SD_EIO;
    int named = 0;
    int fd = cache__create_tmp(dfd, base, tmp, sizeof tmp, &named);
    if (fd < 0) {
        int e = errno;
        close(dfd);
        return sd_errf(err, SD_EIO, "cannot write cache %s: %s", cpath, strerror(e));
    }
    int bad = write_all(fd, &h, sizeof h) || write_all(fd, zero, CACHE_BLOCK_OFFSET - sizeof h) ||
              write_all(fd, p->block, p->block_len);
    bad = cache__publish(fd, dfd, base, tmp, sizeof tmp, named, bad) < 0;
    int saved = errno;
    close(dfd);
    if (bad) return sd_errf(err, SD_EIO, "cannot write cache %s: %s", cpath, strerror(saved));
    return 0;
}

int cache_open_cloud(const char *src, const cache_desc *d, pc_prepared *out, cache_result *res,
                     sd_err *err)
{
    cache_desc dd = d ? *d : (cache_desc){0};
    if (dd.k <= 0) dd.k = PREP_DEFAULT_K;
    cache_result rr;
    memset(&rr, 0, sizeof rr);
    memset(out, 0, sizeof *out);
    int rc;

    double t0 = now_s();
    src_key key = {0};
    if ((rc = source_key(src, &key, 0, err)) < 0) return rc;
    rr.file_size = key.size;
    if ((rc = cache_path_for(src, dd.dir, dd.k, rr.path, sizeof rr.path, err)) < 0) return rc;

    if (!dd.force) {
        int got = try_load(rr.path, src, &key, dd.k, out, rr.why, sizeof rr.why);
        if (got == 1) {
            rr.hit = 1;
            rr.t_read = now_s() - t0;
            snprintf(rr.why, sizeof rr.why, "cache valid");
            if (res) *res = rr;
            return 0;
        }
        if (got < 0 && dd.warn) {
            char msg[4600];
            snprintf(msg, sizeof msg, "cache %s: %s; rebuilding it", rr.path, rr.why);
            dd.warn(dd.user, msg);
        }
    } else {
        snprintf(rr.why, sizeof rr.why, "rebuild forced");
    }

    /* The reader checks the file's header before it reads the rest, so a file that is no cloud
     * fails at once; the content hash for the new cache's key is taken after a successful
     * parse (the bytes are then in the page cache), from a file of the same size and time. */
    pc_cloud cloud;
    if ((rc = pc_load_threads(src, dd.threads, &cloud, err)) < 0) return rc;
    if ((rc = source_key(src, &key, 1, err)) < 0) {
        pc_cloud_free(&cloud);
        return rc;
    }
    rr.t_read = now_s() - t0;

    double t1 = now_s();
    prep_desc pd = {.k = dd.k, .threads = dd.threads, .progress = dd.progress, .user = dd.user};
    rc = prep_run(&cloud, &pd, out, err);
    pc_cloud_free(&cloud);
    if (rc < 0) return rc;
    rr.t_prep = now_s() - t1;

    double t2 = now_s();
    sd_err werr = {0};
    if (write_cache(rr.path, &key, out, &werr) < 0) {
        rr.write_failed = 1;
        snprintf(rr.write_error, sizeof rr.write_error, "%s", werr.msg);
        if (dd.warn) {
            char msg[700];
            snprintf(msg, sizeof msg, "%s (continuing without a cache)", werr.msg);
            dd.warn(dd.user, msg);
        }
    }
    rr.t_write = now_s() - t2;
    if (res) *res = rr;
    return 0;
}

int cache__set_version(const char *cache_path, uint32_t version)
{
    int fd = open(cache_path, O_RDWR | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) return -1;
    cache_header h;
    int rc = -1;
    if (pread(fd, &h, sizeof h, 0) == (ssize_t)sizeof h) {
        h.version = version;
        h.header_hash = sd_hash64(&h, offsetof(cache_header, header_hash), 0);
        if (pwrite(fd, &h, sizeof h, 0) == (ssize_t)sizeof h) rc = 0;
    }
    close(fd);
    return rc;
}

int cache__seal(const char *cache_path, const char *src)
{
    src_key key = {0};
    sd_err err = {0};
    if (source_key(src, &key, 0, &err) < 0 || source_key(src, &key, 1, &err) < 0) return -1;
    int fd = open(cache_path, O_RDWR | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) return -1;
    struct stat st;
    cache_header h;
    int rc = -1;
    if (fstat(fd, &st) == 0 && (uint64_t)st.st_size >= CACHE_BLOCK_OFFSET &&
        pread(fd, &h, sizeof h, 0) == (ssize_t)sizeof h) {
        h.src_size = key.size;
        h.src_mtime_ns = key.mtime_ns;
        h.src_hash = key.hash;
        uint64_t left = (uint64_t)st.st_size - CACHE_BLOCK_OFFSET;
        uint8_t *m = left ? mmap(NULL, (size_t)left + CACHE_BLOCK_OFFSET, PROT_READ, MAP_PRIVATE,
                                 fd, 0) : NULL;
        if (m != MAP_FAILED) {
            h.block_hash = sd_hash64(m ? m + CACHE_BLOCK_OFFSET : (const uint8_t *)"",
                                     left < h.block_len ? (size_t)left : (size_t)h.block_len, 0);
            if (m) munmap(m, (size_t)left + CACHE_BLOCK_OFFSET);
            h.header_hash = sd_hash64(&h, offsetof(cache_header, header_hash), 0);
            if (pwrite(fd, &h, sizeof h, 0) == (ssize_t)sizeof h) rc = 0;
        }
    }
    close(fd);
    return rc;
}

int cache__load(const char *cache_path, const char *src, int k, pc_prepared *out, char *why,
                size_t whylen)
{
    src_key key = {0};
    sd_err err = {0};
    if (source_key(src, &key, 0, &err) < 0) {
        snprintf(why, whylen, "%s", err.msg);
        return -1;
    }
    return try_load(cache_path, src, &key, k, out, why, whylen);
}
