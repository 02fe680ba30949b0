/* lod_bench.c — a LOD cloud's frame time under a fixed point budget, for `make bench`
 * (tests/bench/bench_lod.sh).
 *
 *   lod_bench FILE --cache DIR [--budget N] [--frames N] [--size WxH] [--pipeline NAME]
 *             [--label NAME] [--backend auto|egl|osmesa]
 *
 * Opens FILE's LOD form from DIR (building it when absent: run `splatd prep --lod always`
 * first to time the build apart), adopts it into a renderer, and for each of N cameras (the
 * default framing turned 0.5 degrees further about its up axis each time) renders until the
 * frame is complete (waiting for the loader thread between frames; not timed), then times one
 * more frame of that camera: wall-clock of rnd_render minus its read-back. Reported, medians
 * of the N timed frames, as a Markdown row:
 *   | cloud | points | pipeline | budget | points drawn | ms/frame | frames to complete |
 * and "first: | cloud | map ms | first frame ms | first complete ms |": the time to map the
 * cache, and from the start of the mapping to the first frame after adoption (what lod_first=1
 * answers) and to the first complete one (what a RENDER answers), of the first camera; the
 * renderer's own start-up is not counted (a daemon has done it before any OPEN). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "lod.h"
#include "render.h"
#include "rndtest.h"

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return n ? v[n / 2] : 0;
}

/* Turns cam's eye about its up axis through the target by deg degrees. */
static void turn(rnd_camera *cam, double deg)
{
    double a = deg * M_PI / 180, u[3], l = 0;
    for (int i = 0; i < 3; i++) l += cam->up[i] * cam->up[i];
    l = sqrt(l);
    for (int i = 0; i < 3; i++) u[i] = cam->up[i] / l;
    double v[3];
    for (int i = 0; i < 3; i++) v[i] = cam->eye[i] - cam->target[i];
    double c = cos(a), s = sin(a), d = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    double x[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    for (int i = 0; i < 3; i++)
        cam->eye[i] = cam->target[i] + v[i] * c + x[i] * s + u[i] * d * (1 - c);
}

int main(int argc, char **argv)
{
    const char *file = NULL, *cache = NULL, *label = NULL, *pipe = "points";
    long long budget = 1000000;
    int frames = 10, w = 1280, h = 720;
    rnd_backend_kind be = RND_BACKEND_AUTO;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--cache") && v) cache = v, i++;
        else if (!strcmp(a, "--budget") && v) budget = atoll(v), i++;
        else if (!strcmp(a, "--frames") && v) frames = atoi(v), i++;
        else if (!strcmp(a, "--size") && v && sscanf(v, "%dx%d", &w, &h) == 2) i++;
        else if (!strcmp(a, "--pipeline") && v) pipe = v, i++;
        else if (!strcmp(a, "--label") && v) label = v, i++;
        else if (!strcmp(a, "--backend") && v) {
            be = !strcmp(v, "egl") ? RND_BACKEND_EGL : !strcmp(v, "osmesa") ? RND_BACKEND_OSMESA
                                                                             : RND_BACKEND_AUTO;
            i++;
        } else if (a[0] != '-' && !file) file = a;
        else {
            fprintf(stderr, "usage: lod_bench FILE --cache DIR [--budget N] [--frames N] "
                            "[--size WxH] [--pipeline NAME] [--label NAME] [--backend B]\n");
            return 2;
        }
    }
    if (!file || !cache || frames < 1 || w < 1 || h < 1) {
        fprintf(stderr, "lod_bench: FILE and --cache DIR are needed\n");
        return 2;
    }
    if (!label) label = file;
    sd_err err = {0};
    lod_cloud *c = calloc(1, sizeof *c);
    lod_desc d = {.dir = cache};
    lod_result res;
    double t0 = now_ms();
    if (!c || lod_open_cloud(file, &d, c, &res, &err) != 0) {
        fprintf(stderr, "lod_bench: %s\n", err.msg);
        return 1;
    }
    double t_map = now_ms() - t0;
    uint64_t n = c->n;
    double lo[3], hi[3];
    memcpy(lo, c->bmin, sizeof lo);
    memcpy(hi, c->bmax, sizeof hi);
    rnd_desc rd = {.backend = be};
    rnd_ctx *r = rnd_create(&rd, &err);
    if (!r) {
        fprintf(stderr, "lod_bench: %s\n", err.msg);
        return 1;
    }
    printf("renderer: %s\n", rnd_renderer_string(r));
    t0 = now_ms() - t_map; /* the renderer's start-up (a daemon's is done before any OPEN) */
    int64_t id = rnd_adopt_lod(r, c, &err);
    if (id <= 0) {
        fprintf(stderr, "lod_bench: %s\n", err.msg);
        return 1;
    }
    sp_params p;
    sp_params_defaults(&p);
    p.point_budget = budget;
    if (sp_param_set_text(&p, "pipeline", pipe, NULL, 0) != 0) {
        fprintf(stderr, "lod_bench: unknown pipeline '%s'\n", pipe);
        return 2;
    }
    rnd_camera cam;
    tu_camera_box(lo, hi, w, h, &cam);
    rnd_frame f = {0};
    double *ms = calloc((size_t)frames, sizeof *ms), *pts = calloc((size_t)frames, sizeof *pts);
    double *nfr = calloc((size_t)frames, sizeof *nfr);
    double t_first = 0, t_complete = 0;
    for (int k = 0; k < frames; k++) {
        int count = 0;
        double s0 = now_ms();
        do {
            if (count) rnd_lod_wait(r, (uint32_t)id, 2000);
            if (rnd_render(r, (uint32_t)id, &cam, &p, 0, &f, &err) != 0) {
                fprintf(stderr, "lod_bench: %s\n", err.msg);
                return 1;
            }
            if (k == 0 && count == 0) t_first = now_ms() - t0;
            count++;
        } while (!f.complete && count < 10000);
        if (k == 0) t_complete = now_ms() - s0 + t_first;
        double a = now_ms();
        if (rnd_render(r, (uint32_t)id, &cam, &p, 0, &f, &err) != 0) {
            fprintf(stderr, "lod_bench: %s\n", err.msg);
            return 1;
        }
        ms[k] = now_ms() - a - f.readback_us / 1e3;
        pts[k] = (double)f.points_drawn;
        nfr[k] = count;
        turn(&cam, 0.5);
    }
    printf("| %s | %llu | %s | %lld | %.0f | %.1f | %.0f |\n", label, (unsigned long long)n, pipe,
           budget, median(pts, frames), median(ms, frames), median(nfr, frames));
    printf("first: | %s | %.1f | %.1f | %.1f |\n", label, t_map, t_first, t_complete);
    rnd_frame_free(&f);
    rnd_destroy(r);
    free(ms);
    free(pts);
    free(nfr);
    return 0;
}
