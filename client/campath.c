/* campath.c — camera-path files, output patterns, resume checks, atomic output files and the
 * progress line of `splat path` (see campath.h). */
#include "campath.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

int cp_parse_line(const char *line, cp_cam *cam, char *err, size_t errlen)
{
    static const char *what[10] = {"eye x", "eye y", "eye z", "target x", "target y",
                                   "target z", "up x", "up y", "up z", "fov"};
    double v[10];
    int k = 0;
    const char *s = line;
    for (;;) {
        while (*s == ' ' || *s == '\t' || *s == ',' || *s == '\r' || *s == '\n') s++;
        if (!*s || *s == '#') break;
        if (k == 10) {
            snprintf(err, errlen, "more than 10 numbers (eye x y z, target x y z, up x y z, "
                     "fov): '%.40s'", s);
            return -1;
        }
        char *end;
        errno = 0;
        v[k] = strtod(s, &end);
        if (end == s || errno || !isfinite(v[k]) ||
            (*end && !strchr(" \t,\r\n#", *end))) {
            snprintf(err, errlen, "%s is not a number: '%.*s'", what[k],
                     (int)strcspn(s, " \t,\r\n#"), s);
            return -1;
        }
        k++;
        s = end;
    }
    if (k == 0) return 0;
    if (k < 10) {
        snprintf(err, errlen, "%d numbers; a camera is 10: eye x y z, target x y z, up x y z, "
                 "fov (missing %s)", k, what[k]);
        return -1;
    }
    if (!(v[9] > 0 && v[9] < 180)) {
        snprintf(err, errlen, "fov %g is out of range (0, 180) degrees", v[9]);
        return -1;
    }
    for (int i = 0; i < 3; i++) {
        cam->eye[i] = v[i];
        cam->target[i] = v[3 + i];
        cam->up[i] = v[6 + i];
    }
    cam->fov = (float)v[9];
    return 1;
}

int cp_load(const char *path, cp_cam **cams, size_t *n, char *err, size_t errlen)
{
    *cams = NULL;
    *n = 0;
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errlen, "cannot open camera file %s: %s", path, strerror(errno));
        return -1;
    }
    size_t cap = 0;
    char *line = NULL;
    size_t lcap = 0;
    long lineno = 0;
    int rc = 0;
    while (getline(&line, &lcap, f) >= 0) {
        lineno++;
        cp_cam c;
        char e[200];
        int r = cp_parse_line(line, &c, e, sizeof e);
        if (r < 0) {
            snprintf(err, errlen, "%s:%ld: %s", path, lineno, e);
            rc = -1;
            break;
        }
        if (r == 0) continue;
        if (*n == cap) {
            size_t nc = cap ? cap * 2 : 64;
            cp_cam *nb = realloc(*cams, nc * sizeof *nb);
            if (!nb) {
                snprintf(err, errlen, "%s:%ld: out of memory", path, lineno);
                rc = -1;
                break;
            }
            *cams = nb;
            cap = nc;
        }
        (*cams)[(*n)++] = c;
    }
    if (rc == 0 && ferror(f)) {
        snprintf(err, errlen, "cannot read camera file %s: %s", path, strerror(errno));
        rc = -1;
    }
    if (rc == 0 && *n == 0) {
        snprintf(err, errlen, "%s: no cameras (one per line: eye x y z, target x y z, up x y z, "
                 "fov)", path);
        rc = -1;
    }
    free(line);
    fclose(f);
    if (rc < 0) {
        free(*cams);
        *cams = NULL;
        *n = 0;
    }
    return rc;
}

/* conv: parses the conversion at p (just after '%'): flags "0", width digits, 'd'. Returns
 * the characters used (> 0) with *zero and *width set, or 0 when it is not one. */
static int conv(const char *p, int *zero, int *width)
{
    int i = 0;
    *zero = 0;
    *width = 0;
    if (p[i] == '0') {
        *zero = 1;
        i++;
    }
    while (isdigit((unsigned char)p[i])) {
        *width = *width * 10 + (p[i] - '0');
        if (*width >= 20) return 0;
        i++;
    }
    if (p[i] != 'd') return 0;
    return i + 1;
}

int cp_pattern_check(const char *pattern, char *err, size_t errlen)
{
    int nconv = 0;
    for (const char *p = pattern; *p; p++) {
        if (*p != '%') continue;
        if (p[1] == '%') {
            p++;
            continue;
        }
        int z, w, used = conv(p + 1, &z, &w);
        if (!used) {
            snprintf(err, errlen, "output pattern '%s': '%%' at byte %zu must start %%d, %%05d "
                     "or %%%%", pattern, (size_t)(p - pattern));
            return -1;
        }
        nconv++;
        p += used;
    }
    if (nconv != 1) {
        snprintf(err, errlen, "output pattern '%s' needs exactly one frame number conversion "
                 "such as %%05d (it has %d)", pattern, nconv);
        return -1;
    }
    return 0;
}

int cp_expand(const char *pattern, long index, char *out, size_t len)
{
    char e[8];
    if (index < 0 || len == 0 || cp_pattern_check(pattern, e, sizeof e) < 0) return -1;
    size_t o = 0;
    for (const char *p = pattern; *p; p++) {
        char num[48];
        const char *piece = NULL;
        size_t plen = 1;
        if (*p == '%' && p[1] == '%') {
            piece = "%";
            p++;
        } else if (*p == '%') {
            int z, w, used = conv(p + 1, &z, &w);
            snprintf(num, sizeof num, z ? "%0*ld" : "%*ld", w, index);
            piece = num;
            plen = strlen(num);
            p += used;
        } else {
            piece = p;
        }
        if (o + plen >= len) return -1;
        memcpy(out + o, piece, plen);
        o += plen;
    }
    out[o] = 0;
    return 0;
}

const char *cp_ext_format(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(slash ? slash : path, '.');
    if (!dot) return NULL;
    if (!strcasecmp(dot, ".jpg") || !strcasecmp(dot, ".jpeg")) return "jpeg";
    if (!strcasecmp(dot, ".png")) return "png";
    if (!strcasecmp(dot, ".exr")) return "exr";
    if (!strcasecmp(dot, ".raw")) return "raw";
    return NULL;
}

int cp_frame_done(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0;
}

long cp_todo(const char *pattern, long n, int force, long *todo)
{
    long k = 0;
    char name[4096];
    for (long i = 0; i < n; i++) {
        if (cp_expand(pattern, i, name, sizeof name) < 0) return -1;
        if (force || !cp_frame_done(name)) todo[k++] = i;
    }
    return k;
}

int cp_mkdirs(const char *path, char *err, size_t errlen)
{
    char d[4096];
    if (snprintf(d, sizeof d, "%s", path) >= (int)sizeof d) {
        snprintf(err, errlen, "path too long: %.80s...", path);
        return -1;
    }
    char *slash = strrchr(d, '/');
    if (!slash) return 0;
    *slash = 0;
    for (char *p = d + 1; ; p++) {
        if (*p == '/' || !*p) {
            char keep = *p;
            *p = 0;
            if (d[0] && mkdir(d, 0777) < 0 && errno != EEXIST) {
                snprintf(err, errlen, "cannot create directory %s: %s", d, strerror(errno));
                return -1;
            }
            *p = keep;
            if (!keep) break;
        }
    }
    return 0;
}

int cp_write_file(const char *path, const void *data, size_t len, char *err, size_t errlen)
{
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        snprintf(err, errlen, "cannot create %s: %s", tmp, strerror(errno));
        return -1;
    }
    int ok = fwrite(data, 1, len, f) == len;
    ok = (fclose(f) == 0) && ok;
    if (!ok || rename(tmp, path) < 0) {
        snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    return 0;
}

char *cp_progress_line(char *buf, size_t len, long done, long total, double elapsed, int bar)
{
    char b[128] = "";
    if (bar > 0) {
        if (bar > 100) bar = 100;
        int fill = total > 0 ? (int)((double)done * bar / (double)total) : bar;
        b[0] = '[';
        for (int i = 0; i < bar; i++) b[1 + i] = i < fill ? '#' : '-';
        b[1 + bar] = ']';
        b[2 + bar] = ' ';
        b[3 + bar] = 0;
    }
    double fps = elapsed > 0 ? done / elapsed : 0;
    char eta[32] = "--:--";
    if (done > 0 && fps > 0) {
        long s = (long)ceil((double)(total - done) / fps);
        if (s >= 3600) snprintf(eta, sizeof eta, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
        else snprintf(eta, sizeof eta, "%ld:%02ld", s / 60, s % 60);
    }
    snprintf(buf, len, "%s%*ld/%ld  %.1f frames/s  ETA %s", b,
             (int)snprintf(NULL, 0, "%ld", total), done, total, fps, eta);
    return buf;
}
