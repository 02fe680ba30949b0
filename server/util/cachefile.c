/* cachefile.c — cache files: names, keys, header, atomic write, guarded mapping (cachefile.h). */
#include "cachefile.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "sd_hash.h"
#include "sd_sigbus.h"

#define BYTE_ORDER_MARK 0x01020304u

/* ---- names ---- */

int cf_dir_for(const char *dir, char *buf, size_t len)
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

void cf_default_dir(const char *src, char *buf, size_t len)
{
    if (cf_dir_for(NULL, buf, len) == 0) return;
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", src);
    snprintf(buf, len, "%s/.splatd-cache", dirname(tmp));
}

int cf_path(const char *src, const char *dir, int k, const char *ext, char *buf, size_t len,
            sd_err *err)
{
    char real[PATH_MAX], d[PATH_MAX];
    if (!realpath(src, real)) return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    if (dir && *dir) snprintf(d, sizeof d, "%s", dir);
    else cf_default_dir(real, d, sizeof d);
    char tmp[PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", real);
    uint64_t ph = sd_hash64(real, strlen(real), 0);
    int w = snprintf(buf, len, "%s/%s.%016llx.k%d%s", d, basename(tmp), (unsigned long long)ph,
                     k, ext);
    if (w < 0 || (size_t)w >= len) return sd_errf(err, SD_ELIMIT, "%s: cache path too long", src);
    return 0;
}

/* ---- the source's key ---- */

/* open_source: src opened for reading (O_NONBLOCK: a FIFO put in place of a cloud must not
 * block the open until a writer comes), checked to be a regular file, *st filled. Returns the
 * fd or SD_EIO. */
static int open_source(const char *src, struct stat *st, sd_err *err)
{
    int fd = open(src, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return sd_errf(err, SD_EIO, "%s: %s", src, strerror(errno));
    if (fstat(fd, st) < 0 || !S_ISREG(st->st_mode)) {
        close(fd);
        return sd_errf(err, SD_EIO, "%s: not a regular file", src);
    }
    return fd;
}

static int64_t mtime_ns(const struct stat *st)
{
    return (int64_t)st->st_mtim.tv_sec * 1000000000LL + st->st_mtim.tv_nsec;
}

int cf_key_stat(const char *src, cf_key *key, sd_err *err)
{
    struct stat st;
    int fd = open_source(src, &st, err);
    if (fd < 0) return fd;
    close(fd);
    key->size = (uint64_t)st.st_size;
    key->mtime_ns = mtime_ns(&st);
    return 0;
}

/* hash_range: feeds [off, off + len) of fd to hs, read in 1 MiB pieces. Returns 0, -1 with
 * errno on a read error, or -2 when the file ended first (it changed). */
static int hash_range(int fd, uint64_t off, uint64_t len, uint8_t *buf, size_t piece,
                      sd_hash_state *hs)
{
    uint64_t end = off + len;
    while (off < end) {
        size_t want = end - off < piece ? (size_t)(end - off) : piece;
        ssize_t r = pread(fd, buf, want, (off_t)off);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return r < 0 ? -1 : -2;
        sd_hash64_update(hs, buf, (size_t)r);
        off += (uint64_t)r;
    }
    return 0;
}

int cf_key_hash(const char *src, uint32_t how, cf_key *key, sd_err *err)
{
    enum { PIECE = 1 << 20 };
    struct stat st;
    int fd = open_source(src, &st, err);
    if (fd < 0) return fd;
    if ((uint64_t)st.st_size != key->size || mtime_ns(&st) != key->mtime_ns) {
        close(fd);
        return sd_errf(err, SD_EIO, "%s: the file changed while it was being read (its size or "
                       "time changed); try again once it is complete", src);
    }
    uint8_t *buf = malloc(PIECE);
    if (!buf) {
        close(fd);
        return sd_errf(err, SD_ENOMEM, "out of memory hashing %s", src);
    }
    sd_hash_state hs;
    sd_hash64_init(&hs, 0);
    uint64_t n = key->size;
    int rc;
    if (how == CF_HASH_ENDS) { /* the first and the last MiB (the same bytes twice when short) */
        uint64_t head = n < PIECE ? n : PIECE;
        rc = hash_range(fd, 0, head, buf, PIECE, &hs);
        if (rc == 0) rc = hash_range(fd, n - head, head, buf, PIECE, &hs);
    } else {
        rc = hash_range(fd, 0, n, buf, PIECE, &hs);
    }
    int e = errno;
    free(buf);
    close(fd);
    key->hash = sd_hash64_final(&hs);
    if (rc == -2)
        return sd_errf(err, SD_EIO, "%s: the file changed while it was being read (it became "
                       "shorter); try again once it is complete", src);
    if (rc < 0) return sd_errf(err, SD_EIO, "%s: cannot read: %s", src, strerror(e));
    return 0;
}

/* ---- reading ---- */

static uint64_t header_hash(const uint8_t *page, uint32_t meta_len)
{
    return sd_hash64(page, sizeof(cf_head) + meta_len, 0);
}

/* check: the header checks of cf_open on f (fd open, page read into page). */
static int check(const cf_kind *k, cf_file *f, const uint8_t *page, const cf_key *src,
                 uint64_t options, char *why, size_t whylen)
{
    const cf_head *h = &f->head;
    if (memcmp(h->magic, k->magic, 8) != 0 || h->byte_order != BYTE_ORDER_MARK) {
        snprintf(why, whylen, "it has a wrong magic or byte order");
        return -1;
    }
    /* The checksum's place follows from the layout: another layout is another version's
     * (out of date) or damage (this version's). */
    if (h->meta_len != k->meta_len) {
        if (h->version != k->version) goto version;
        snprintf(why, whylen, "its header is corrupt (a layout of %u bytes, %u expected)",
                 h->meta_len, k->meta_len);
        return -1;
    }
    uint64_t hh;
    memcpy(&hh, page + sizeof(cf_head) + k->meta_len, 8);
    if (hh != header_hash(page, k->meta_len)) {
        snprintf(why, whylen, "its header is corrupt (checksum mismatch)");
        return -1;
    }
    if (h->version != k->version) goto version;
    if (h->hash_how != k->hash_how) {
        snprintf(why, whylen, "it is keyed by another hash of the source (%u, %u expected)",
                 h->hash_how, k->hash_how);
        return 0;
    }
    if (h->options != options) {
        char a[96] = "", b[96] = "";
        k->describe(h->options, a, sizeof a);
        k->describe(options, b, sizeof b);
        snprintf(why, whylen, "%s built with %s; %s asked", k->what, a, b);
        return 0;
    }
    if (h->src.size != src->size || h->src.mtime_ns != src->mtime_ns) {
        snprintf(why, whylen, "source changed (size or mtime)");
        return 0;
    }
    if (h->file_len != f->size) {
        snprintf(why, whylen, "it is truncated or has a wrong size (%llu bytes, %llu expected)",
                 (unsigned long long)f->size, (unsigned long long)h->file_len);
        return -1;
    }
    if (h->body_off < CF_PAGE || h->body_off > f->size || h->body_len > f->size - h->body_off) {
        snprintf(why, whylen, "its checksummed section [%llu, +%llu) is not inside its %llu "
                 "bytes", (unsigned long long)h->body_off, (unsigned long long)h->body_len,
                 (unsigned long long)f->size);
        return -1;
    }
    memcpy(f->meta, page + sizeof(cf_head), k->meta_len);
    return 1;
version:
    snprintf(why, whylen, "%s version %u, this splatd writes %u", k->what, h->version,
             k->version);
    return 0;
}

int cf_open(const cf_kind *k, const char *path, int fd, const cf_key *src, uint64_t options,
            cf_file *f, char *why, size_t whylen)
{
    memset(f, 0, sizeof *f);
    snprintf(f->path, sizeof f->path, "%s", path);
    /* O_NOFOLLOW: a symlink at the cache's name is nobody's cache (it is replaced on write). */
    f->fd = fd >= 0 ? fcntl(fd, F_DUPFD_CLOEXEC, 0)
                    : open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (f->fd < 0 && fd >= 0) {
        snprintf(why, whylen, "it cannot be read: %s", strerror(errno));
        return -1;
    }
    if (f->fd < 0) {
        snprintf(why, whylen, "no cache");
        return 0;
    }
    struct stat st;
    uint8_t *page = malloc(CF_PAGE);
    int rc = -1;
    if (!page) {
        snprintf(why, whylen, "out of memory");
    } else if (fstat(f->fd, &st) < 0) {
        snprintf(why, whylen, "it cannot be read: %s", strerror(errno));
    } else if (!S_ISREG(st.st_mode)) {
        snprintf(why, whylen, "it is not a regular file");
    } else if ((f->size = (uint64_t)st.st_size) < CF_PAGE ||
               cf_pread_all(f->fd, page, CF_PAGE, 0) < 0) {
        snprintf(why, whylen, "it is truncated (%lld bytes)", (long long)st.st_size);
    } else {
        memcpy(&f->head, page, sizeof f->head);
        rc = check(k, f, page, src, options, why, whylen);
    }
    free(page);
    if (rc != 1) cf_close(f);
    return rc;
}

int cf_check_source(const cf_file *f, const char *src, char *why, size_t whylen)
{
    cf_key key = {.size = f->head.src.size, .mtime_ns = f->head.src.mtime_ns};
    sd_err e = {0};
    if (cf_key_hash(src, f->head.hash_how, &key, &e) < 0 || key.hash != f->head.src.hash) {
        snprintf(why, whylen, "source changed (content)");
        return 0;
    }
    return 1;
}

int cf_read_body(const cf_file *f, void *buf, char *why, size_t whylen)
{
    const cf_head *h = &f->head;
    if (cf_pread_all(f->fd, buf, (size_t)h->body_len, h->body_off) < 0) {
        snprintf(why, whylen, "it cannot be read: %s", strerror(errno));
        return -1;
    }
    if (sd_hash64(buf, (size_t)h->body_len, 0) != h->body_hash) {
        snprintf(why, whylen, "its data is corrupt (checksum mismatch)");
        return -1;
    }
    return 1;
}

int cf_loaded(int force, int got, const char *what, const char *path, char *why, size_t whylen,
              void (*warn)(void *user, const char *msg), void *user)
{
    if (force) {
        snprintf(why, whylen, "rebuild forced");
        return 0;
    }
    if (got == 1) {
        snprintf(why, whylen, "cache valid");
        return 1;
    }
    if (got < 0 && warn) {
        char msg[PATH_MAX + 512];
        snprintf(msg, sizeof msg, "%s %s: %s; rebuilding it", what, path, why);
        warn(user, msg);
    }
    return 0;
}

void cf_close(cf_file *f)
{
    if (f->fd >= 0) close(f->fd);
    f->fd = -1;
}

cf_map *cf_map_open(const cf_file *f, char *why, size_t whylen)
{
    cf_map *m = calloc(1, sizeof *m);
    if (!m || f->size > SIZE_MAX) {
        free(m);
        snprintf(why, whylen, "it cannot be mapped: %s", m ? "too large" : "out of memory");
        return NULL;
    }
    m->len = (size_t)f->size;
    void *a = mmap(NULL, m->len, PROT_READ, MAP_SHARED, f->fd, 0);
    if (a == MAP_FAILED) {
        snprintf(why, whylen, "it cannot be mapped: %s", strerror(errno));
        free(m);
        return NULL;
    }
    m->addr = a;
    m->guard = sd_sigbus_region_add(a, m->len);
    if (m->guard < 0) {
        snprintf(why, whylen, "it cannot be mapped: %d cache files are mapped already",
                 SD_SIGBUS_REGIONS);
        munmap(a, m->len);
        free(m);
        return NULL;
    }
    snprintf(m->path, sizeof m->path, "%s", f->path);
    return m;
}

int cf_map_changed(const cf_map *m)
{
    return m && sd_sigbus_region_faulted(m->guard);
}

void cf_map_close(cf_map *m)
{
    if (!m) return;
    sd_sigbus_region_remove(m->guard);
    munmap((void *)m->addr, m->len);
    free(m);
}

int cf_changed_error(sd_err *err, const char *what, const char *path, const char *detail)
{
    const char *slash = strrchr(path, '/');
    return sd_errf(err, SD_ESTALE, "the %s file %s changed while splatd was reading it (%s); "
                   "open the cloud again to rebuild it", what, slash ? slash + 1 : path, detail);
}

/* ---- writing ---- */

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

int cf_open_dir(const char *dir, sd_err *err)
{
    if (mkdir_p(dir) < 0)
        return sd_errf(err, SD_EIO, "cannot create cache directory %s: %s", dir, strerror(errno));
    int dfd = open(dir, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (dfd < 0)
        return sd_errf(err, SD_EIO, "cannot open cache directory %s: %s", dir,
                       errno == ELOOP ? "it is a symbolic link" : strerror(errno));
    struct stat st;
    if (fstat(dfd, &st) < 0) {
        int e = errno;
        close(dfd);
        return sd_errf(err, SD_EIO, "cache directory %s: %s", dir, strerror(e));
    }
    /* Another user's directory, or one others may write: there, anyone could swap names
     * under the writer. */
    if (st.st_uid != geteuid() || (st.st_mode & (S_IWGRP | S_IWOTH))) {
        close(dfd);
        errno = EPERM;
        return sd_errf(err, SD_EIO, "cache directory %s is %s (mode %04o); caches are written "
                       "only in a directory this user owns and nobody else can write (make it "
                       "0700)", dir, st.st_uid != geteuid() ? "owned by another user"
                                                           : "writable by others",
                       (unsigned)(st.st_mode & 07777));
    }
    return dfd;
}

/* Temporary names: "<cache file name>.tmp.<pid>.<12 hex digits>". The pid lets the sweep tell
 * a dead writer's leftover from a live writer's file; the random part makes the name
 * unpredictable. */
#define TMP_TAG ".tmp."

static void tmp_name(const char *base, char *buf, size_t len)
{
    uint8_t r[6] = {0};
    if (getrandom(r, sizeof r, 0) != (ssize_t)sizeof r) {
        /* No entropy source: the names stay unique (O_EXCL, linkat), only predictable. */
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        uint64_t t = (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
        memcpy(r, &t, sizeof r);
    }
    snprintf(buf, len, "%s" TMP_TAG "%ld.%02x%02x%02x%02x%02x%02x", base, (long)getpid(), r[0],
             r[1], r[2], r[3], r[4], r[5]);
}

/* create_tmp: a new file (read and write) in dfd that no one else can have made or linked: an
 * unnamed O_TMPFILE file when the file system has them (nothing is left behind if the process
 * dies), else a random name created with O_EXCL | O_NOFOLLOW (a symlink planted there makes
 * the create fail, never followed); with unlink_now that name is removed at once (a scratch
 * or temp file that is never published). *named is 1 when the file keeps the name in name.
 * Returns the fd or -1 with errno. */
static int create_tmp(int dfd, const char *base, char *name, size_t len, int unlink_now,
                      int *named)
{
    *named = 0;
    int fd = openat(dfd, ".", O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (fd >= 0) return fd;
    if (errno != EOPNOTSUPP && errno != EISDIR && errno != EINVAL && errno != ENOENT) return -1;
    for (int tries = 0; tries < 16; tries++) {
        tmp_name(base, name, len);
        fd = openat(dfd, name, O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
        if (fd >= 0 || errno != EEXIST) break;
    }
    if (fd >= 0 && unlink_now) unlinkat(dfd, name, 0);
    else if (fd >= 0) *named = 1;
    return fd;
}

/* link_tmp: gives the unnamed file fd a new random name in dfd (linkat fails, never follows,
 * when the name exists). Returns 0 or -1 with errno. */
static int link_tmp(int fd, int dfd, const char *base, char *name, size_t len)
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

static void writer_init(cf_writer *w, const char *cpath)
{
    memset(w, 0, sizeof *w);
    w->fd = w->dfd = -1;
    snprintf(w->path, sizeof w->path, "%s", cpath);
    snprintf(w->dir, sizeof w->dir, "%s", cpath);
    char *slash = strrchr(w->dir, '/');
    if (slash) {
        *slash = 0;
        snprintf(w->base, sizeof w->base, "%s", slash + 1);
    } else {
        snprintf(w->dir, sizeof w->dir, ".");
        snprintf(w->base, sizeof w->base, "%s", cpath);
    }
}

int cf_writer_open(cf_writer *w, const char *cpath, sd_err *err)
{
    writer_init(w, cpath);
    w->dfd = cf_open_dir(w->dir, err);
    if (w->dfd < 0) return SD_EIO;
    w->fd = create_tmp(w->dfd, w->base, w->tmp, sizeof w->tmp, 0, &w->named);
    if (w->fd < 0) {
        int e = errno;
        close(w->dfd);
        w->dfd = -1;
        errno = e;
        return sd_errf(err, SD_EIO, "cannot write cache %s: %s", cpath, strerror(e));
    }
    return 0;
}

int cf_writer_open_temp(cf_writer *w, const char *cpath, sd_err *err)
{
    writer_init(w, cpath);
    const char *t = getenv("TMPDIR");
    snprintf(w->dir, sizeof w->dir, "%s", t && *t ? t : "/tmp");
    w->temp = 1;
    /* No ownership check here: the file never has a name anyone could swap (unnamed, or a
     * random O_EXCL name removed at once), so a shared sticky /tmp is fine. */
    w->dfd = open(w->dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (w->dfd >= 0)
        w->fd = create_tmp(w->dfd, w->base, w->tmp, sizeof w->tmp, 1, &w->named);
    if (w->fd < 0) {
        int e = errno;
        if (w->dfd >= 0) close(w->dfd);
        w->dfd = -1;
        errno = e;
        return sd_errf(err, SD_EIO, "cannot create a temporary file in %s: %s", w->dir,
                       strerror(e));
    }
    return 0;
}

int cf_scratch(const cf_writer *w, sd_err *err)
{
    char name[PATH_MAX];
    int named;
    int fd = create_tmp(w->dfd, ".scratch", name, sizeof name, 1, &named);
    if (fd < 0) return sd_errf(err, SD_EIO, "cannot create a scratch file in %s: %s", w->dir,
                               strerror(errno));
    return fd;
}

int cf_pwrite_all(int fd, const void *p, size_t len, uint64_t off)
{
    const uint8_t *b = p;
    while (len) {
        ssize_t g = pwrite(fd, b, len, (off_t)off);
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0) return -1;
        b += g;
        len -= (size_t)g;
        off += (uint64_t)g;
    }
    return 0;
}

int cf_pread_all(int fd, void *p, size_t len, uint64_t off)
{
    uint8_t *q = p;
    while (len) {
        ssize_t g = pread(fd, q, len, (off_t)off);
        if (g < 0 && errno == EINTR) continue;
        if (g == 0) errno = EIO; /* the file ended first */
        if (g <= 0) return -1;
        q += g;
        len -= (size_t)g;
        off += (uint64_t)g;
    }
    return 0;
}

/* publish: fsync, a name when the file has none, rename over base, fsync of the directory.
 * Returns 0, or -1 with errno (the file removed, base untouched); fd is closed either way. */
static int publish(cf_writer *w)
{
    int bad = fsync(w->fd);
    int saved = errno;
    if (!bad && !w->named) {
        bad = link_tmp(w->fd, w->dfd, w->base, w->tmp, sizeof w->tmp) != 0;
        saved = errno;
        w->named = !bad;
    }
    if (close(w->fd) < 0 && !bad) {
        bad = 1;
        saved = errno;
    }
    w->fd = -1;
    if (!bad && renameat(w->dfd, w->tmp, w->dfd, w->base) < 0) {
        bad = 1;
        saved = errno;
    }
    if (bad) {
        errno = saved;
        return -1; /* the abort removes the named file */
    }
    w->named = 0; /* renamed: it is the cache now */
    fsync(w->dfd); /* make the rename durable */
    return 0;
}

int cf_writer_commit(cf_writer *w, const cf_kind *k, cf_head *h, const void *meta, sd_err *err)
{
    uint8_t *page = calloc(1, CF_PAGE);
    if (!page) {
        cf_writer_abort(w);
        return sd_errf(err, SD_ENOMEM, "out of memory writing %s", w->path);
    }
    memcpy(h->magic, k->magic, 8);
    h->version = k->version;
    h->byte_order = BYTE_ORDER_MARK;
    h->meta_len = k->meta_len;
    h->hash_how = k->hash_how;
    memcpy(page, h, sizeof *h);
    memcpy(page + sizeof *h, meta, k->meta_len);
    uint64_t hh = header_hash(page, k->meta_len);
    memcpy(page + sizeof *h + k->meta_len, &hh, 8);
    int bad = cf_pwrite_all(w->fd, page, CF_PAGE, 0) < 0;
    int saved = errno;
    free(page);
    if (!bad && !w->temp) {
        bad = publish(w) < 0;
        saved = errno;
    }
    if (!bad) return 0;
    cf_writer_abort(w);
    return sd_errf(err, SD_EIO, "cannot write cache %s: %s", w->path, strerror(saved));
}

void cf_writer_abort(cf_writer *w)
{
    if (w->fd >= 0) close(w->fd);
    if (w->named && w->dfd >= 0) unlinkat(w->dfd, w->tmp, 0);
    if (w->dfd >= 0) close(w->dfd);
    w->fd = w->dfd = -1;
    w->named = 0;
}

int cf_sweep(const char *dir, int *removed)
{
    if (removed) *removed = 0;
    DIR *d = dir ? opendir(dir) : NULL;
    if (!d) return 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        /* "<name>.spl<kind>.tmp.<pid>[.<hex>]": a cache writer's temporary file */
        const char *t = strstr(e->d_name, TMP_TAG);
        if (!t || t == e->d_name || !memmem(e->d_name, (size_t)(t - e->d_name), ".spl", 4))
            continue;
        char *end;
        long pid = strtol(t + strlen(TMP_TAG), &end, 10);
        if (pid <= 0 || (*end != '.' && *end != 0)) continue;
        /* A live writer's file (this process's or another's: a `splatd prep` beside the
         * daemon) is left alone; a dead one's is garbage. */
        if (pid == (long)getpid() || kill((pid_t)pid, 0) == 0 || errno != ESRCH) continue;
        if (unlinkat(dirfd(d), e->d_name, 0) == 0 && removed) (*removed)++;
    }
    closedir(d);
    return 0;
}

/* ---- for tests ---- */

/* rewrite_header: reads path's header page, lets fn change it (with the file's fd and size),
 * puts a valid header checksum on it and writes it back. Returns 0 or -1. */
static int rewrite_header(const char *path, int (*fn)(int fd, uint64_t size, cf_head *h,
                                                      void *user), void *user)
{
    int fd = open(path, O_RDWR | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) return -1;
    struct stat st;
    uint8_t page[CF_PAGE];
    int rc = -1;
    if (fstat(fd, &st) == 0 && (uint64_t)st.st_size >= CF_PAGE &&
        cf_pread_all(fd, page, CF_PAGE, 0) == 0) {
        cf_head h;
        memcpy(&h, page, sizeof h);
        if (fn(fd, (uint64_t)st.st_size, &h, user) == 0) {
            memcpy(page, &h, sizeof h);
            /* a layout with no room for the checksum has none (no loader gets that far) */
            if (h.meta_len <= CF_META_MAX) {
                uint64_t hh = header_hash(page, h.meta_len);
                memcpy(page + sizeof h + h.meta_len, &hh, 8);
            }
            rc = cf_pwrite_all(fd, page, CF_PAGE, 0);
        }
    }
    close(fd);
    return rc;
}

static int set_version(int fd, uint64_t size, cf_head *h, void *user)
{
    (void)fd;
    (void)size;
    h->version = *(const uint32_t *)user;
    return 0;
}

int cf__set_version(const char *path, uint32_t version)
{
    return rewrite_header(path, set_version, &version);
}

typedef struct seal_job {
    cf_key key;
    int set_options;
    uint64_t options;
} seal_job;

static int seal(int fd, uint64_t size, cf_head *h, void *user)
{
    const seal_job *j = user;
    h->src = j->key;
    if (j->set_options) h->options = j->options;
    uint64_t off = h->body_off, len = 0;
    if (off < size) len = size - off < h->body_len ? size - off : h->body_len;
    if (len > SIZE_MAX) return -1;
    uint8_t *b = malloc(len ? (size_t)len : 1);
    if (!b) return -1;
    int rc = len && cf_pread_all(fd, b, (size_t)len, off) < 0 ? -1 : 0;
    h->body_hash = sd_hash64(b, (size_t)len, 0);
    free(b);
    return rc;
}

int cf__seal(const char *path, const char *src, uint32_t how, int set_options,
             uint64_t options)
{
    seal_job j = {.set_options = set_options, .options = options};
    sd_err err = {0};
    if (cf_key_stat(src, &j.key, &err) < 0 || cf_key_hash(src, how, &j.key, &err) < 0)
        return -1;
    return rewrite_header(path, seal, &j);
}
