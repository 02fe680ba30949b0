/* fuzz_cli.c — the bodies of the campath, shard and token fuzz targets (fuzz_targets.h): what
 * an operator hands `splat path` and the daemon (camera-path files, output patterns, the shard
 * of a farm worker from its options and environment, token files), each checked against an
 * independent reading of its documented grammar. */
#include "fuzz_targets.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "auth.h"
#include "campath.h"
#include "sd_err.h"
#include "shard.h"
#include "spc_internal.h"

/* ---- campath: output patterns and camera-path files --------------------------------------- */

/* ref_expand: pattern for index as campath.h describes it, read independently: "%%" is '%',
 * one conversion "%d", "%Nd" or "%0Nd" (N < 20: padded with spaces, or with zeros; as in
 * printf the '0' flag may repeat) is the index, anything else after a '%' or a count of
 * conversions other than one makes it invalid. out has room for strlen(pattern) + 40 bytes.
 * Returns the length written to out, or -1 when invalid. */
static long ref_expand(const char *pattern, long index, char *out)
{
    size_t o = 0;
    int convs = 0;
    for (size_t i = 0; pattern[i]; i++) {
        if (pattern[i] != '%') {
            out[o++] = pattern[i];
            continue;
        }
        i++;
        if (pattern[i] == '%') {
            out[o++] = '%';
            continue;
        }
        int zero = 0, width = 0;
        for (; pattern[i] == '0'; i++) zero = 1;
        for (; pattern[i] >= '0' && pattern[i] <= '9' && width < 20; i++)
            width = 10 * width + (pattern[i] - '0');
        if (pattern[i] != 'd' || width >= 20 || ++convs > 1) return -1;
        char num[32];
        int k = 0;
        unsigned long v = (unsigned long)index;
        do {
            num[k++] = (char)('0' + v % 10);
            v /= 10;
        } while (v);
        for (int pad = width - k; pad > 0; pad--) out[o++] = zero ? '0' : ' ';
        while (k > 0) out[o++] = num[--k];
    }
    out[o] = 0;
    return convs == 1 ? (long)o : -1;
}

static void check_pattern(const char *pattern)
{
    char err[300] = "";
    size_t room = strlen(pattern) + 40;
    char *want = malloc(room), *got = malloc(room + 1);
    if (!want || !got) abort();
    int ok = cp_pattern_check(pattern, err, sizeof err) == 0;
    if (!ok && !err[0]) fuzz_fail("campath", "pattern refused without a message");
    static const long idx[] = {0, 7, 99999, 123456789, LONG_MAX};
    for (size_t k = 0; k < sizeof idx / sizeof idx[0]; k++) {
        long n = ref_expand(pattern, idx[k], want);
        if ((n >= 0) != ok)
            fuzz_fail("campath", "pattern '%.80s': cp_pattern_check says %s, the grammar %s",
                      pattern, ok ? "valid" : "invalid", n >= 0 ? "valid" : "invalid");
        if (n < 0) {
            if (cp_expand(pattern, idx[k], got, room) == 0)
                fuzz_fail("campath", "invalid pattern '%.80s' expanded", pattern);
            continue;
        }
        /* exactly the room it needs, then one byte less */
        memset(got, 'x', room + 1);
        if (cp_expand(pattern, idx[k], got, (size_t)n + 1) != 0 || strcmp(got, want) != 0)
            fuzz_fail("campath", "'%.80s' with %ld in %ld + 1 bytes: '%.80s', not '%.80s'",
                      pattern, idx[k], n, got, want);
        if (got[n + 1] != 'x')
            fuzz_fail("campath", "'%.80s': cp_expand wrote past the %ld + 1 bytes given",
                      pattern, n);
        memset(got, 'x', room + 1);
        if (cp_expand(pattern, idx[k], got, (size_t)n) == 0)
            fuzz_fail("campath", "'%.80s' with %ld: %ld characters fitted in %ld bytes",
                      pattern, idx[k], n, n);
        if (got[n] != 'x')
            fuzz_fail("campath", "'%.80s': cp_expand wrote past the %ld bytes given", pattern, n);
        const char *f = cp_ext_format(want);
        const char *dot = strrchr(want, '.'), *slash = strrchr(want, '/');
        if (f && (!dot || (slash && slash > dot)))
            fuzz_fail("campath", "'%.80s' has no extension but gives format %s", want, f);
    }
    free(want);
    free(got);
}

/* check_camera_line: one line through cp_parse_line; a camera it gives prints and parses back
 * to itself. Returns cp_parse_line's result. */
static int check_camera_line(const char *line, cp_cam *cam)
{
    char err[300] = "";
    int r = cp_parse_line(line, cam, err, sizeof err);
    if (r < 0 && !err[0]) fuzz_fail("campath", "line refused without a message");
    if (r < -1 || r > 1) fuzz_fail("campath", "cp_parse_line returned %d", r);
    if (r != 1) return r;
    if (!(cam->fov > 0 && cam->fov < 180))
        fuzz_fail("campath", "fov %g accepted", (double)cam->fov);
    char again[800];
    int l = snprintf(again, sizeof again, "%.17g %.17g %.17g, %.17g %.17g %.17g, %.17g %.17g "
                     "%.17g, %.9g", cam->eye[0], cam->eye[1], cam->eye[2], cam->target[0],
                     cam->target[1], cam->target[2], cam->up[0], cam->up[1], cam->up[2],
                     (double)cam->fov);
    if (l <= 0 || (size_t)l >= sizeof again) fuzz_fail("campath", "camera prints too long");
    for (int k = 0; k < 3; k++)
        if (!isfinite(cam->eye[k]) || !isfinite(cam->target[k]) || !isfinite(cam->up[k]))
            fuzz_fail("campath", "a non-finite camera was accepted: '%.80s'", line);
    cp_cam b;
    if (cp_parse_line(again, &b, err, sizeof err) != 1 || b.fov != cam->fov ||
        memcmp(b.eye, cam->eye, sizeof b.eye) || memcmp(b.target, cam->target, sizeof b.target) ||
        memcmp(b.up, cam->up, sizeof b.up))
        fuzz_fail("campath", "camera '%.80s' printed as '%s' reads back differently", line,
                  again);
    return 1;
}

int fuzz_one_campath(const uint8_t *data, size_t len)
{
    /* the first line (to '\n' or NUL) is an output pattern, the rest a camera-path file */
    size_t pl = 0;
    while (pl < len && data[pl] != '\n' && data[pl] != 0) pl++;
    char *pattern = malloc(pl + 1);
    if (!pattern) abort();
    memcpy(pattern, data, pl);
    pattern[pl] = 0;
    check_pattern(pattern);
    free(pattern);
    const uint8_t *file = data + (pl < len ? pl + 1 : len);
    size_t flen = len - (size_t)(file - data);
    /* the file's lines one by one, as cp_load must see them */
    size_t want_n = 0;
    long bad_line = 0, lineno = 0;
    char *line = malloc(flen + 1);
    if (!line) abort();
    for (size_t at = 0; at < flen && !bad_line;) {
        size_t e = at;
        while (e < flen && file[e] != '\n') e++;
        memcpy(line, file + at, e - at);
        line[e - at] = 0;
        lineno++;
        cp_cam cam;
        int r = check_camera_line(line, &cam);
        if (r < 0) bad_line = lineno;
        else want_n += (size_t)r;
        at = e + 1;
    }
    free(line);
    char path[64], err[600] = "";
    int fd = fuzz_memfd(file, flen, path, sizeof path);
    cp_cam *cams = NULL;
    size_t n = 0;
    int rc = cp_load(path, &cams, &n, err, sizeof err);
    close(fd);
    if (rc == 0 && (bad_line || n != want_n || n == 0 || !cams))
        fuzz_fail("campath", "cp_load read %zu cameras; line by line %zu, the first bad line %ld",
                  n, want_n, bad_line);
    if (rc != 0) {
        char where[128];
        snprintf(where, sizeof where, "%s:%ld:", path, bad_line);
        if (rc != -1 || n != 0 || cams || !strstr(err, path) ||
            (bad_line && !strstr(err, where)) || (!bad_line && want_n))
            fuzz_fail("campath", "cp_load returned %d (%zu cameras) with '%s'; the first bad "
                      "line is %ld, %zu cameras", rc, n, err, bad_line, want_n);
    }
    free(cams);
    return rc;
}

/* ---- shard: --shard, --shards and the farm's environment ---------------------------------- */

/* ref_num: s as a whole decimal number in [lo, hi]: one or more ASCII digits and nothing else
 * (no sign, no space). 0 or -1. */
static int ref_num(const char *s, long lo, long hi, long *out)
{
    if (!s || !*s) return -1;
    long v = 0;
    for (const char *p = s; *p; p++) {
        if (*p < '0' || *p > '9') return -1;
        if (v > (LONG_MAX - 9) / 10) return -1;
        v = 10 * v + (*p - '0');
    }
    if (v < lo || v > hi) return -1;
    *out = v;
    return 0;
}

/* ref_resolve: shard.h's rules, read independently: 0 with *index, *count and *src, or -1
 * with *src the option or variable the error must name. */
static int ref_resolve(const shard_env *e, long *index, long *count, const char **src)
{
    enum { MAX = 1000000 };
    long i, n = 0, lo = 0;
    *index = 0, *count = 1, *src = "";
    if (e->shard_flag) {
        *src = "--shard";
        const char *sl = strchr(e->shard_flag, '/');
        if (!sl || sl - e->shard_flag > 16) return -1;
        char a[32];
        memcpy(a, e->shard_flag, (size_t)(sl - e->shard_flag));
        a[sl - e->shard_flag] = 0;
        if (ref_num(a, 0, MAX - 1, &i) || ref_num(sl + 1, 1, MAX, &n) || i >= n) return -1;
        *index = i, *count = n;
        return 0;
    }
    if (e->shards_flag && ref_num(e->shards_flag, 1, MAX, &n)) return *src = "--shards", -1;
    if (e->job_index && *e->job_index) {
        *src = "JOB_COMPLETION_INDEX";
        if (ref_num(e->job_index, 0, MAX - 1, &i)) return -1;
        if (!e->shards_flag) {
            if (!e->shard_count || !*e->shard_count) return -1;
            if (ref_num(e->shard_count, 1, MAX, &n)) return *src = "SPLAT_SHARD_COUNT", -1;
        }
        if (i >= n) return -1;
        *index = i, *count = n;
        return 0;
    }
    if (e->slurm_id && *e->slurm_id) {
        *src = "SLURM_ARRAY_TASK_ID";
        if (ref_num(e->slurm_id, 0, 100000000, &i)) return -1;
        if (e->slurm_min && *e->slurm_min && ref_num(e->slurm_min, 0, i, &lo))
            return *src = "SLURM_ARRAY_TASK_MIN", -1;
        if (!e->shards_flag) {
            if (!e->slurm_count || !*e->slurm_count) return *src = "SLURM_ARRAY_TASK_COUNT", -1;
            if (ref_num(e->slurm_count, 1, MAX, &n)) return *src = "SLURM_ARRAY_TASK_COUNT", -1;
        }
        if (i - lo >= n) return -1;
        *index = i - lo, *count = n;
        return 0;
    }
    if (e->shards_flag) return *src = "--shards", -1;
    return 0;
}

int fuzz_one_shard(const uint8_t *data, size_t len)
{
    if (len < 1) return -1;
    /* byte 0: which of the seven are set (bit k: field k); then the fields, '\n'-separated */
    char *copy = malloc(len);
    if (!copy) abort();
    memcpy(copy, data + 1, len - 1);
    copy[len - 1] = 0;
    const char *f[7];
    char *p = copy;
    for (int k = 0; k < 7; k++) {
        f[k] = p;
        char *nl = p ? strchr(p, '\n') : NULL;
        if (nl) *nl = 0;
        p = nl ? nl + 1 : NULL;
        if (!f[k]) f[k] = "";
        if (!(data[0] >> k & 1)) f[k] = NULL;
    }
    shard_env e = {f[0], f[1], f[2], f[3], f[4], f[5], f[6]};
    shard s;
    char err[300] = "";
    int rc = shard_resolve(&e, &s, err, sizeof err);
    long wi, wn;
    const char *src;
    int want = ref_resolve(&e, &wi, &wn, &src);
    if (rc != want)
        fuzz_fail("shard", "shard_resolve returned %d (%s), the rules say %d (%s)", rc,
                  rc ? err : s.source, want, src);
    if (rc == 0) {
        if (s.index != wi || s.count != wn || strcmp(s.source, src) != 0)
            fuzz_fail("shard", "shard %ld of %ld from '%s'; the rules say %ld of %ld from '%s'",
                      s.index, s.count, s.source, wi, wn, src);
        /* shard_filter keeps exactly the frames i with i % count == index, in order */
        long todo[300], m = 1 + (long)(len % 299), k = 0;
        for (long i = 0; i < m; i++) todo[i] = 3 * i + (long)(data[0] & 3);
        long got = shard_filter(&s, todo, m);
        for (long i = 0; i < m; i++) {
            long v = 3 * i + (long)(data[0] & 3);
            if (s.count > 1 && v % s.count != s.index) continue;
            if (k >= got || todo[k] != v)
                fuzz_fail("shard", "shard_filter of shard %ld/%ld: entry %ld is %ld, not %ld",
                          s.index, s.count, k, k < got ? todo[k] : -1, v);
            k++;
        }
        if (k != got) fuzz_fail("shard", "shard_filter kept %ld, the rule %ld", got, k);
    } else if (!err[0] || !strstr(err, src)) {
        fuzz_fail("shard", "the error '%s' does not name %s", err, src);
    }
    free(copy);
    return rc;
}

/* ---- token: the daemon's and the client's token file readers ------------------------------ */

int fuzz_one_token(const uint8_t *data, size_t len)
{
    if (len < 1) return SD_EINVAL;
    /* byte 0: bits 0-1 the file's mode, bit 2 read through a symbolic link, bit 3 a
     * directory in its place, bit 4 a FIFO (no writer: a reader that blocks hangs here); the
     * rest is the file */
    static const mode_t modes[4] = {0600, 0400, 0640, 0604};
    mode_t mode = modes[data[0] & 3];
    int link = data[0] >> 2 & 1, isdir = data[0] >> 3 & 1, fifo = !isdir && (data[0] >> 4 & 1);
    const uint8_t *body = data + 1;
    size_t n = len - 1;
    char dir[512], file[600], path[600];
    fuzz_mkdtemp(dir, sizeof dir, "token");
    snprintf(file, sizeof file, "%s/token", dir);
    snprintf(path, sizeof path, "%s/%s", dir, link ? "link" : "token");
    if (isdir) {
        if (mkdir(file, 0700) != 0) abort();
    } else if (fifo) {
        if (mkfifo(file, 0600) != 0) abort();
    } else {
        fuzz_write_file(file, body, n);
        if (chmod(file, mode) != 0) abort();
    }
    if (link && symlink(file, path) != 0) abort();
    /* what the rules say (auth.h): a regular file that group and others cannot use, of at
     * most AUTH_TOKEN_MAX + 2 bytes, its trailing '\n' and '\r' removed, 1 to AUTH_TOKEN_MAX
     * bytes left */
    size_t t = n;
    while (t > 0 && (body[t - 1] == '\n' || body[t - 1] == '\r')) t--;
    int ok = !isdir && !fifo && !(mode & 077) && n <= AUTH_TOKEN_MAX + 2 && t > 0 &&
             t <= AUTH_TOKEN_MAX;
    auth_token tok;
    sd_err err = {0};
    int rc = auth_token_load(path, &tok, &err);
    fuzz_check_sd_err(rc, &err, path, "token (daemon)");
    if ((rc == 0) != ok || (ok && (tok.len != t || memcmp(tok.bytes, body, t) != 0)))
        fuzz_fail("token", "%zu bytes (%zu without the line end), mode %04o%s: the daemon's "
                  "reader gives %d (%s), %zu bytes", n, t, (unsigned)mode,
                  isdir ? ", a directory" : fifo ? ", a FIFO" : "", rc, err.msg,
                  rc == 0 ? tok.len : 0);
    uint8_t buf[AUTH_TOKEN_MAX];
    char cerr[700] = "";
    int crc = spc__read_token(path, buf, sizeof buf, cerr, sizeof cerr);
    if ((crc > 0) != ok || (ok && ((size_t)crc != t || memcmp(buf, body, t) != 0)) ||
        (crc <= 0 && (crc != SPC_E_TOKEN || !strstr(cerr, path))))
        fuzz_fail("token", "%zu bytes (%zu without the line end), mode %04o%s: the client's "
                  "reader gives %d (%s); the daemon's %d", n, t, (unsigned)mode,
                  isdir ? ", a directory" : fifo ? ", a FIFO" : "", crc, cerr, rc);
    if (link) unlink(path);
    if (isdir) rmdir(file);
    else if (fifo) unlink(file);
    else unlink(file);
    rmdir(dir);
    return rc;
}
