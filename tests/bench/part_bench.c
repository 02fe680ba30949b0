/* part_bench.c — the spatial partition of splatd --mpi (partition.h) on a real cloud, for
 * `make bench` (tests/bench/bench_farm.sh).
 *
 *   part_bench FILE --cache DIR [--parts LIST] [--render LIST]
 *     --parts   comma-separated part counts, default 2,3,4,7
 *     --render  part counts whose parts are also rendered (default none; e.g. 2,3,4)
 *
 * Opens FILE's prepared form through DIR (preparing it when absent), and for each N partitions
 * it with the earlier median cuts (pc_partition_median: points only) and with the octree-cell
 * kd tree (pc_partition: points and footprint). Prints one Markdown row per (N, partition):
 *   | N | partition | points share per part | footprint share per part | points max/mean |
 *   footprint max/mean | ms |
 * where footprint is the view-independent proxy sum of pi r^2 (r: the prep's splat radius) and
 * ms the partition's wall-clock time (one run; single thread).
 *
 * With --render, for each listed N and both partitions, every part is uploaded alone into one
 * renderer (the default back end, llvmpipe here) and drawn at 1280x720 with the points and
 * splat pipelines, timed from 4 views (the default framing of the whole cloud, turned 0, 90,
 * 180, 270 degrees about its up axis): the GPU time (render_us, up to glFinish) of each part is the
 * median of 5 frames, the parts drawn in turn. Under splatd --mpi a frame waits for its
 * slowest rank, so the row reports
 *   | N | partition | pipeline | covered pixels max/mean | slowest part ms | mean part ms |
 *   ms max/mean |
 * with the parts' actual screen footprint, max/mean of the pixels each covers alone (finite
 * depth; deterministic), median over 14 views from the 6 axis and 8 diagonal directions at
 * the framing distance; and medians over the 4 timed views of the slowest part's time, the
 * parts' mean time and their ratio (1 = every rank as fast as the others). Parts are drawn
 * one after another in one process (no contention between them, unlike ranks sharing this machine's
 * cores; llvmpipe's threads still share them with whatever else runs). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cache.h"
#include "common/testutil.h"
#include "partition.h"
#include "render.h"
#include "rndtest.h"

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* next_count: the next count of a comma-separated list at *s (advanced past it): 1 to
 * PC_PART_MAX, 0 at the end, -1 (said on stderr) when not a count. */
static long next_count(const char **s)
{
    if (!**s) return 0;
    char *end;
    long np = strtol(*s, &end, 10);
    if (end == *s || np < 1 || np > PC_PART_MAX || (*end && *end != ',')) {
        fprintf(stderr, "part_bench: bad part count at '%s'\n", *s);
        return -1;
    }
    *s = *end == ',' ? end + 1 : end;
    return np;
}

/* shares: "a / b / c" of v[0, n) in per cent. */
static void shares(const double *v, int n, char *out, size_t cap)
{
    size_t o = 0;
    out[0] = 0;
    for (int p = 0; p < n && o < cap; p++) {
        int l = snprintf(out + o, cap - o, "%s%.1f", p ? " / " : "", 100 * v[p]);
        if (l < 0) break;
        o += (size_t)l;
    }
}

/* quarter_turn: cam's eye turned 90 degrees about its up axis through the target. */
static void quarter_turn(rnd_camera *cam)
{
    double u[3], d[3], l = 0;
    for (int i = 0; i < 3; i++) l += cam->up[i] * cam->up[i];
    for (int i = 0; i < 3; i++) {
        u[i] = cam->up[i] / sqrt(l);
        d[i] = cam->eye[i] - cam->target[i];
    }
    double ud = u[0] * d[0] + u[1] * d[1] + u[2] * d[2];
    double x[3] = {u[1] * d[2] - u[2] * d[1], u[2] * d[0] - u[0] * d[2], u[0] * d[1] - u[1] * d[0]};
    for (int i = 0; i < 3; i++) cam->eye[i] = cam->target[i] + u[i] * ud + x[i];
}

enum { VIEWS = 4, REPS = 5, RENDER_MAX = 16, COVER_VIEWS = 14 };

/* view_from: c0 (a camera framing the cloud) moved to direction v of the 14 (the 6 axes, the 8
 * diagonals) at the same distance from its target; up kept unless nearly along the view. */
static void view_from(const rnd_camera *c0, int v, rnd_camera *c)
{
    static const signed char dir[COVER_VIEWS][3] = {
        {1, 0, 0},  {-1, 0, 0}, {0, 1, 0},   {0, -1, 0},  {0, 0, 1},   {0, 0, -1},  {1, 1, 1},
        {1, 1, -1}, {1, -1, 1}, {1, -1, -1}, {-1, 1, 1},  {-1, 1, -1}, {-1, -1, 1}, {-1, -1, -1}};
    *c = *c0;
    double l = 0, dist = 0, ul = 0, dot = 0;
    for (int a = 0; a < 3; a++) {
        l += dir[v][a] * dir[v][a];
        dist += (c0->eye[a] - c0->target[a]) * (c0->eye[a] - c0->target[a]);
        ul += c0->up[a] * c0->up[a];
    }
    l = sqrt(l);
    dist = sqrt(dist);
    for (int a = 0; a < 3; a++) {
        c->eye[a] = c0->target[a] + dist * dir[v][a] / l;
        dot += c0->up[a] * dir[v][a] / l / sqrt(ul);
    }
    if (fabs(dot) > 0.9) /* looking along up: the first camera's view direction is up */
        for (int a = 0; a < 3; a++) c->up[a] = c0->target[a] - c0->eye[a];
}

/* render_parts: the rows of --render for np parts of pc as part gives them. */
static int render_parts(rnd_ctx *r, const pc_prepared *pc, const uint16_t *part, int np,
                        const char *kind, sd_err *err)
{
    if (np > RENDER_MAX) return sd_errf(err, SD_EINVAL, "--render: at most %d parts", RENDER_MAX);
    uint32_t ids[RENDER_MAX] = {0};
    int rc = 0;
    for (int p = 0; p < np && rc == 0; p++) {
        pc_prepared sub;
        rc = pc_prepared_subset(pc, part, p, &sub, err);
        if (rc == 0 && sub.n > 0) {
            int64_t id = rnd_upload(r, &sub, err);
            if (id < 0) rc = (int)id;
            else ids[p] = (uint32_t)id;
        }
        if (rc == 0) pc_prepared_free(&sub);
    }
    static const char *const pipes[] = {"points", "splat"};
    for (int q = 0; q < 2 && rc == 0; q++) {
        sp_params prm;
        sp_params_defaults(&prm);
        sp_param_set_text(&prm, "pipeline", pipes[q], NULL, 0);
        rnd_camera cam;
        tu_camera_box(pc->bmin, pc->bmax, 1280, 720, &cam);
        double slow[VIEWS], mean[VIEWS], ratio[VIEWS];
        rnd_frame f = {0};
        for (int v = 0; v < VIEWS && rc == 0; v++, quarter_turn(&cam)) {
            /* the parts take turns frame by frame, so a burst of load elsewhere hits them all */
            double t[RENDER_MAX][REPS], mx = 0, sum = 0;
            for (int k = -1; k < REPS && rc == 0; k++) /* k = -1: warm-up */
                for (int p = 0; p < np && rc == 0; p++) {
                    if (!ids[p]) {
                        if (k >= 0) t[p][k] = 0;
                        continue;
                    }
                    rc = rnd_render(r, ids[p], &cam, &prm, 0, &f, err);
                    if (k >= 0) t[p][k] = f.render_us / 1e3;
                }
            for (int p = 0; p < np && rc == 0; p++) {
                double ms = tu_median(t[p], REPS);
                mx = ms > mx ? ms : mx;
                sum += ms;
            }
            slow[v] = mx;
            mean[v] = sum / np;
            ratio[v] = mean[v] > 0 ? mx / mean[v] : 1;
        }
        /* the parts' screen footprint from the 14 directions: pixels with a finite depth */
        double cratio[COVER_VIEWS];
        for (int v = 0; v < COVER_VIEWS && rc == 0; v++) {
            rnd_camera cv;
            view_from(&cam, v, &cv);
            double cmx = 0, csum = 0;
            for (int p = 0; p < np && rc == 0; p++) {
                double cov = 0;
                if (ids[p]) rc = rnd_render(r, ids[p], &cv, &prm, 1, &f, err);
                for (size_t i = 0; ids[p] && rc == 0 && i < (size_t)f.width * f.height; i++)
                    cov += isfinite(f.depth[i]);
                cmx = cov > cmx ? cov : cmx;
                csum += cov;
            }
            cratio[v] = csum > 0 ? cmx * np / csum : 1;
        }
        rnd_frame_free(&f);
        if (rc == 0)
            printf("| %d | %s | %s | %.3f | %.1f | %.1f | %.3f |\n", np, kind, pipes[q],
                   tu_median(cratio, COVER_VIEWS), tu_median(slow, VIEWS), tu_median(mean, VIEWS),
                   tu_median(ratio, VIEWS));
    }
    for (int p = 0; p < np; p++)
        if (ids[p]) rnd_release(r, ids[p]);
    return rc;
}

int main(int argc, char **argv)
{
    const char *file = NULL, *cache = NULL, *list = "2,3,4,7", *rlist = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--cache") && i + 1 < argc) cache = argv[++i];
        else if (!strcmp(argv[i], "--parts") && i + 1 < argc) list = argv[++i];
        else if (!strcmp(argv[i], "--render") && i + 1 < argc) rlist = argv[++i];
        else if (argv[i][0] != '-' && !file) file = argv[i];
        else {
            fprintf(stderr, "usage: part_bench FILE --cache DIR [--parts 2,3,4,7] "
                            "[--render 2,3,4]\n");
            return 2;
        }
    }
    if (!file || !cache) {
        fprintf(stderr, "part_bench: FILE and --cache DIR are needed\n");
        return 2;
    }
    sd_err err = {0};
    pc_prepared pc;
    cache_result res;
    cache_desc cd = {.dir = cache};
    if (cache_open_cloud(file, &cd, &pc, &res, &err) < 0) {
        fprintf(stderr, "part_bench: %s: %s\n", file, err.msg);
        return 1;
    }
    uint16_t *part = malloc((size_t)(pc.n ? pc.n : 1) * sizeof *part);
    if (!part) {
        fprintf(stderr, "part_bench: out of memory\n");
        pc_prepared_free(&pc);
        return 1;
    }
    rnd_ctx *r = NULL;
    if (rlist) {
        rnd_desc rd = {0};
        r = rnd_create(&rd, &err);
        if (!r) {
            fprintf(stderr, "part_bench: %s\n", err.msg);
            free(part);
            pc_prepared_free(&pc);
            return 1;
        }
    }
    printf("| N | partition | points %% per part | footprint %% per part | points max/mean | "
           "footprint max/mean | ms |\n|---:|---|---|---|---:|---:|---:|\n");
    int rc = 0;
    long np;
    for (const char *s = list; rc == 0 && (np = next_count(&s)) != 0;) {
        if (np < 0) {
            rc = 2;
            break;
        }
        for (int kind = 0; kind < 2 && rc == 0; kind++) {
            double t0 = now_ms();
            rc = kind ? pc_partition(pc.pos, pc.radius, pc.n, (int)np, part, NULL, &err)
                      : pc_partition_median(pc.pos, pc.n, (int)np, part, &err);
            double ms = now_ms() - t0;
            if (rc < 0) {
                fprintf(stderr, "part_bench: %s\n", err.msg);
                rc = 1;
                break;
            }
            double pts[PC_PART_MAX], fp[PC_PART_MAX], ip, ifp;
            pc_partition_balance(pc.radius, pc.n, part, (int)np, pts, fp, &ip, &ifp);
            char sp[512], sf[512];
            shares(pts, (int)np, sp, sizeof sp);
            shares(fp, (int)np, sf, sizeof sf);
            printf("| %ld | %s | %s | %s | %.3f | %.3f | %.1f |\n", np,
                   kind ? "octree cells, points + footprint" : "median cuts (before)", sp, sf,
                   ip, ifp, ms);
        }
    }
    if (r && rc == 0) {
        printf("\nparts rendered alone (%s; 1280x720; coverage: median over %d views; time: "
               "GPU time, median of %d frames, medians over %d views):\n\n| N | partition | "
               "pipeline | covered pixels max/mean | slowest part ms | mean part ms | ms "
               "max/mean |\n|---:|---|---|---:|---:|---:|---:|\n", rnd_renderer_string(r),
               COVER_VIEWS, REPS, VIEWS);
        for (const char *s = rlist; rc == 0 && (np = next_count(&s)) != 0;) {
            if (np < 0) {
                rc = 2;
                break;
            }
            for (int kind = 0; kind < 2 && rc == 0; kind++) {
                rc = kind ? pc_partition(pc.pos, pc.radius, pc.n, (int)np, part, NULL, &err)
                          : pc_partition_median(pc.pos, pc.n, (int)np, part, &err);
                if (rc == 0)
                    rc = render_parts(r, &pc, part, (int)np, kind ? "octree cells" : "median cuts",
                                      &err);
                if (rc < 0) fprintf(stderr, "part_bench: %s\n", err.msg);
            }
        }
    }
    if (r) rnd_destroy(r);
    free(part);
    pc_prepared_free(&pc);
    return rc ? 1 : 0;
}
