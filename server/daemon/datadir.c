/* datadir.c — listing and safe name resolution in the data directory (see datadir.h). */
#include "datadir.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cloud.h"

int dd_check_dir(const char *dir, sd_err *err)
{
    struct stat st;
    if (!dir || !*dir) return sd_errf(err, SD_EINVAL, "no data directory given (--data DIR)");
    if (stat(dir, &st) < 0) return sd_errf(err, SD_EIO, "data directory %s: %s", dir, strerror(errno));
    if (!S_ISDIR(st.st_mode)) return sd_errf(err, SD_EINVAL, "data directory %s is not a directory", dir);
    if (access(dir, R_OK | X_OK) < 0)
        return sd_errf(err, SD_EIO, "data directory %s is not readable: %s", dir, strerror(errno));
    return 0;
}

/* valid_name: 1 when name is a plain file name (see datadir.h). */
static int valid_name(const char *name)
{
    size_t n = strlen(name);
    if (n == 0 || n > 255) return 0;
    if (!strcmp(name, ".") || !strcmp(name, "..")) return 0;
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)name[i];
        if (c == '/' || c == '\\' || c < 0x20 || c == 0x7f) return 0;
    }
    return 1;
}

/* inside: resolves dir/name with realpath and checks it lies under rdir (the real data dir) and
 * is a regular file. Returns 0 with path filled, or SD_E* with *why set. */
static int inside(const char *rdir, const char *name, char *path, size_t pathlen, dd_why *why,
                  sd_err *err)
{
    char joined[PATH_MAX + 256], real[PATH_MAX];
    snprintf(joined, sizeof joined, "%s/%s", rdir, name);
    struct stat lst;
    if (lstat(joined, &lst) < 0) {
        *why = DD_NOT_FOUND;
        return sd_errf(err, SD_ENOTFOUND, "no cloud named '%s' in the data directory", name);
    }
    if (!realpath(joined, real)) {
        *why = DD_NOT_FOUND;
        return sd_errf(err, SD_ENOTFOUND, "cloud '%s' cannot be resolved (dangling link?): %s", name,
                       strerror(errno));
    }
    size_t rl = strlen(rdir);
    int under = strncmp(real, rdir, rl) == 0 && (real[rl] == '/' || (rl == 1 && rdir[0] == '/'));
    if (!under) {
        *why = DD_OUTSIDE;
        return sd_errf(err, SD_EINVAL, "cloud '%s' resolves outside the data directory; refused", name);
    }
    struct stat st;
    if (stat(real, &st) < 0 || !S_ISREG(st.st_mode)) {
        *why = DD_NOT_CLOUD;
        return sd_errf(err, SD_EINVAL, "'%s' is not a regular file", name);
    }
    if (strlen(real) >= pathlen) {
        *why = DD_BAD_NAME;
        return sd_errf(err, SD_ELIMIT, "the path of cloud '%s' is too long", name);
    }
    strcpy(path, real);
    return 0;
}

int dd_resolve(const char *dir, const char *name, char *path, size_t pathlen, dd_why *why,
               sd_err *err)
{
    dd_why w_local;
    if (!why) why = &w_local;
    *why = DD_OK;
    if (!name || !valid_name(name)) {
        *why = DD_BAD_NAME;
        return sd_errf(err, SD_EINVAL,
                       "'%s' is not a cloud name: names are plain file names in the data directory "
                       "(no '/', no '..', no absolute paths)", name ? name : "");
    }
    char rdir[PATH_MAX];
    if (!realpath(dir, rdir)) {
        *why = DD_NOT_FOUND;
        return sd_errf(err, SD_EIO, "data directory %s: %s", dir, strerror(errno));
    }
    if (pc_supported_ext(name)) return inside(rdir, name, path, pathlen, why, err);

    /* No supported extension: the unique NAME.ext in the directory. */
    DIR *d = opendir(rdir);
    if (!d) {
        *why = DD_NOT_FOUND;
        return sd_errf(err, SD_EIO, "data directory %s: %s", dir, strerror(errno));
    }
    size_t nl = strlen(name), found = 0;
    char first[256] = "", second[256] = "";
    struct dirent *de;
    while ((de = readdir(d))) {
        if (strncmp(de->d_name, name, nl) != 0 || de->d_name[nl] != '.') continue;
        /* one extension after the name; ".copc.laz" counts as one */
        const char *ext = de->d_name + nl + 1;
        if ((strchr(ext, '.') && strcasecmp(ext, "copc.laz") != 0) ||
            !pc_supported_ext(de->d_name))
            continue;
        if (found == 0) snprintf(first, sizeof first, "%s", de->d_name);
        else if (found == 1) snprintf(second, sizeof second, "%s", de->d_name);
        found++;
    }
    closedir(d);
    if (found == 0) {
        *why = DD_NOT_FOUND;
        return sd_errf(err, SD_ENOTFOUND, "no cloud named '%s' in the data directory", name);
    }
    if (found > 1) {
        *why = DD_AMBIGUOUS;
        return sd_errf(err, SD_EINVAL, "cloud name '%s' is ambiguous: %s, %s%s; give the extension",
                       name, first, second, found > 2 ? ", ..." : "");
    }
    return inside(rdir, first, path, pathlen, why, err);
}

static int cmp_entry(const void *a, const void *b)
{
    return strcmp(((const dd_entry *)a)->name, ((const dd_entry *)b)->name);
}

int dd_list(const char *dir, dd_entry **out, size_t *n, sd_err *err)
{
    *out = NULL;
    *n = 0;
    DIR *d = opendir(dir);
    if (!d) return sd_errf(err, SD_EIO, "data directory %s: %s", dir, strerror(errno));
    dd_entry *v = NULL;
    size_t cnt = 0, cap = 0;
    int rc = 0;
    struct dirent *de;
    while ((de = readdir(d))) {
        if (de->d_name[0] == '.' || !pc_supported_ext(de->d_name)) continue;
        char path[PATH_MAX];
        if (dd_resolve(dir, de->d_name, path, sizeof path, NULL, NULL) != 0) continue;
        struct stat st;
        if (stat(path, &st) < 0) continue;
        if (cnt == cap) {
            size_t nc = cap ? cap * 2 : 16;
            dd_entry *nv = realloc(v, nc * sizeof *nv);
            if (!nv) { rc = sd_errf(err, SD_ENOMEM, "listing %s: out of memory", dir); break; }
            v = nv;
            cap = nc;
        }
        snprintf(v[cnt].name, sizeof v[cnt].name, "%s", de->d_name);
        v[cnt].size = (uint64_t)st.st_size;
        cnt++;
    }
    closedir(d);
    if (rc) { free(v); return rc; }
    if (cnt) qsort(v, cnt, sizeof *v, cmp_entry);
    *out = v;
    *n = cnt;
    return 0;
}
