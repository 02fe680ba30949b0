/* cmd_prep.c — `splatd prep FILE [--k N] [--cache DIR] [--threads N] [--force]`: loads (or
 * reloads from the cache) one cloud and prints its summary and the time of each phase. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "cache.h"
#include "commands.h"
#include "lod.h"
#include "srv.h"
#include "prep.h"

static void warn_stderr(void *user, const char *msg)
{
    (void)user;
    fprintf(stderr, "splatd prep: warning: %s\n", msg);
}

static int parse_int(const char *opt, const char *s, int lo, int hi, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(s ? s : "", &end, 10);
    if (!s || end == s || *end || errno || v < lo || v > hi) {
        fprintf(stderr, "splatd prep: %s needs an integer in [%d, %d], got '%s'\n", opt, lo, hi,
                s ? s : "(nothing)");
        return -1;
    }
    *out = (int)v;
    return 0;
}

int cmd_prep(int argc, char **argv)
{
    const char *file = NULL;
    cache_desc d = {.k = PREP_DEFAULT_K, .warn = warn_stderr, .progress = prep_progress_stderr};
    int lod_mode = LOD_AUTO;
    uint64_t memory = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--k")) {
            if (parse_int("--k", i + 1 < argc ? argv[++i] : NULL, 1, 256, &d.k) < 0) return 2;
        } else if (!strcmp(a, "--threads")) {
            if (parse_int("--threads", i + 1 < argc ? argv[++i] : NULL, 1, 1024, &d.threads) < 0)
                return 2;
        } else if (!strcmp(a, "--cache")) {
            if (i + 1 >= argc) {
                fprintf(stderr, "splatd prep: --cache needs a directory\n");
                return 2;
            }
            d.dir = argv[++i];
        } else if (!strcmp(a, "--lod")) {
            const char *v = i + 1 < argc ? argv[++i] : "";
            if (!strcmp(v, "auto")) lod_mode = LOD_AUTO;
            else if (!strcmp(v, "always")) lod_mode = LOD_ALWAYS;
            else if (!strcmp(v, "never")) lod_mode = LOD_NEVER;
            else {
                fprintf(stderr, "splatd prep: --lod needs auto, always or never, got '%s'\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--memory")) {
            const char *v = i + 1 < argc ? argv[++i] : "";
            if (srv_parse_size(v, &memory) != 0) {
                fprintf(stderr, "splatd prep: --memory needs a size such as 2G (at least 1M), "
                        "got '%s'\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--force")) {
            d.force = 1;
        } else if (!strcmp(a, "--quiet")) {
            d.progress = NULL;
        } else if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            printf("usage: splatd prep FILE [--k N] [--cache DIR] [--threads N] [--force] [--quiet]\n"
                   "                  [--lod auto|always|never] [--memory SIZE]\n"
                   "  Loads FILE (ply, pcd, las, laz, xyz, pts, txt), computes normals, splat radii,\n"
                   "  the uncertainty field F and point spacing with k nearest neighbours\n"
                   "  (default k = 24), caches the result and prints a summary.\n"
                   "  --lod: the level-of-detail form (an octree built out of core under\n"
                   "  --memory, default 2G), for files of 64 MiB or more (auto), always or never.\n");
            return 0;
        } else if (a[0] == '-') {
            fprintf(stderr, "splatd prep: unknown option '%s' (see splatd prep --help)\n", a);
            return 2;
        } else if (!file) {
            file = a;
        } else {
            fprintf(stderr, "splatd prep: one FILE only ('%s' is extra)\n", a);
            return 2;
        }
    }
    if (!file) {
        fprintf(stderr, "usage: splatd prep FILE [--k N] [--cache DIR] [--threads N] [--force] [--quiet]\n");
        return 2;
    }

    struct stat st;
    if (stat(file, &st) == 0 && lod_want(lod_mode, (uint64_t)st.st_size)) {
        lod_desc ld = {.dir = d.dir, .k = d.k, .threads = d.threads, .memory = memory,
                       .force = d.force, .progress = d.progress, .warn = warn_stderr,
                       .status = d.progress ? cmd_lod_status : NULL};
        return cmd_prep_lod(file, &ld);
    }
    pc_prepared p;
    cache_result r;
    sd_err err = {0};
    char cdir[4096];
    int swept = 0;
    if (cache_dir_for(d.dir, cdir, sizeof cdir) == 0) cache_sweep(cdir, &swept);
    if (swept) fprintf(stderr, "splatd prep: removed %d temporary file(s) of interrupted cache "
                       "writes from %s\n", swept, cdir);
    if (cache_open_cloud(file, &d, &p, &r, &err) < 0) {
        /* A parse error may quote the file's bytes: never raw to a terminal (escape codes). */
        char clean[sizeof err.msg * 4];
        srv_clean_text(err.msg, clean, sizeof clean);
        fprintf(stderr, "splatd prep: %s\n", clean);
        return 1;
    }
    char attrs[128];
    sp_attr_names(p.attrs, attrs, sizeof attrs);
    printf("file        %s (%llu bytes)\n", file, (unsigned long long)r.file_size);
    printf("format      %s\n", p.format);
    printf("points      %llu kept, %llu dropped (non-finite)\n", (unsigned long long)p.n,
           (unsigned long long)p.n_dropped);
    printf("bounds      x [%.6f, %.6f]  y [%.6f, %.6f]  z [%.6f, %.6f]\n", p.bmin[0], p.bmax[0],
           p.bmin[1], p.bmax[1], p.bmin[2], p.bmax[2]);
    printf("offset      %.6f %.6f %.6f (subtracted; float32 coordinates are relative to it)\n",
           p.offset[0], p.offset[1], p.offset[2]);
    printf("attributes  %s%s%s\n", attrs, p.scalar_name[0] ? "  scalar=" : "", p.scalar_name);
    printf("k           %u\n", p.k);
    printf("batches     %llu (up to %d points each, Morton order)\n",
           (unsigned long long)p.nbatches, PC_BATCH_POINTS);
    printf("sigma       %.6g (median nearest-neighbour distance)\n", p.sigma);
    printf("radius      %.6g (median splat radius)\n", p.radius_median);
    printf("F           p1 %.3f  p25 %.3f  p50 %.3f  p75 %.3f  p99 %.3f  (raw p99 %.4g)\n",
           p.F_pct[0], p.F_pct[1], p.F_pct[2], p.F_pct[3], p.F_pct[4], p.F_raw_p99);
    printf("cache       %s (%s)\n", r.path, r.hit ? "hit" : r.why);
    if (r.hit) {
        printf("time        cached load %.1f ms\n", r.t_read * 1e3);
        printf("            (first prep: knn build %.3f s, knn query %.3f s, normals %.3f s, "
               "radius %.3f s, field %.3f s, reorder %.3f s)\n",
               p.stats.t_knn_build, p.stats.t_knn_query, p.stats.t_normals, p.stats.t_radius,
               p.stats.t_field, p.stats.t_reorder);
    } else {
        printf("time        read %.3f s, prep %.3f s (reorder %.3f, knn build %.3f, knn query %.3f, "
               "normals %.3f, radius %.3f, field %.3f), cache write %.3f s\n",
               r.t_read, r.t_prep, p.stats.t_reorder, p.stats.t_knn_build, p.stats.t_knn_query,
               p.stats.t_normals, p.stats.t_radius, p.stats.t_field, r.t_write);
    }
    pc_prepared_free(&p);
    if (r.write_failed) {
        /* The point of `prep` is the cache: without it the command failed. */
        fprintf(stderr, "splatd prep: %s\n", r.write_error);
        return 1;
    }
    return 0;
}
