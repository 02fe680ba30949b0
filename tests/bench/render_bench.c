/* render_bench.c — frame time per pipeline for one cloud, for `make bench`
 * (tests/bench/bench_render.sh, which prints the table README.md quotes).
 *
 *   render_bench FILE [--frames N] [--size WxH] [--backend auto|egl|osmesa]
 *                [--pipelines points,splat] [--label NAME] [--threads T] [--save DIR]
 *                (a pipeline may carry its own parameters: soft:model=base:lambda=0.3; it is
 *                 then reported under that whole name)
 *                [--set key=value ...]   (parameters for every pipeline, e.g. ewa=exact)
 *                [--shader-dir DIR]      (read the .glsl files from DIR: try a shader edit unbuilt)
 *                [--zoom Z]              (eye Z times closer to the target: a close-up, culled)
 *                [--edl-cost]            (also: each pipeline's frames with and without
 *                                         shading=edl, interleaved; see below)
 *                [--interleave]          (the pipelines' frames in turn, A B C A B C ..., at
 *                                         one camera a round; see below)
 *                [--host-ab]             (with --interleave: each pipeline on two renderers,
 *                                         without and with the host paths; see below)
 *
 * Loads FILE (pc_load) and preprocesses it (prep_run, default k, T threads: 0 = every core),
 * timing both; uploads the prepared cloud and renders, per pipeline, 1 + N frames of the
 * framing camera of the rendering tests (tu_camera_box) turned 0.5 degrees further about its up axis each
 * frame, so that no two frames are identical. The first frame of each pipeline is a warm-up
 * (shader compile, first-touch of buffers) and is not counted. Reported per pipeline, medians of
 * the N counted frames:
 *   ms/frame     wall-clock of rnd_render minus its read-back: view set-up, culling, clear,
 *                pipeline and glFinish (what a client waits for before the encoder starts);
 *   ratio        ms/frame divided by the `points` pipeline's ms/frame of this run (when
 *                `points` is among the pipelines);
 *   readback ms  rnd_frame.readback_us (glReadPixels RGBA8);
 *   jpeg ms      enc_encode of the frame as JPEG q85 4:2:0 (the daemon's default format);
 *   on stderr, "cpu: LABEL PIPELINE X ms/frame": the process CPU time of rnd_render (all
 *   threads), steadier than wall time on a shared machine for comparing shader versions.
 * Output on stdout, line by line so that the shell script can pick the pieces:
 *   "renderer: <rnd_renderer_string>"
 *   "splat_radius_median: R"   (prep's median splat radius, for the ParaView comparison)
 *   "prep: | cloud | points | load s | prep s | points/s |"   (a Markdown row)
 *   "| cloud | points | pipeline | ms/frame | ratio | readback ms | jpeg ms |" rows.
 * --save DIR writes DIR/<label>-<pipeline>.png of the last frame (to look at what was timed).
 * --edl-cost: per pipeline, N pairs of frames at the same camera, shading=lambert then
 *   shading=edl (the --set parameters otherwise), and on stdout
 *   "edl: | cloud | pipeline | lambert ms | edl ms | EDL ms | EDL CPU ms |", medians of the
 *   wall-clock (as ms/frame) and of the per-pair differences, wall and process CPU. Pairs of
 *   adjacent frames cancel most of a shared machine's drifting load, which the difference of
 *   two separate runs does not (a few ms against a 3 ms target).
 * --interleave: for A/B comparisons of two forms of one pipeline (soft:order=tile against
 *   soft:order=axis) on a shared machine: each round renders every pipeline once at the round's
 *   camera, so that a drifting load falls on all of them alike; after the table, per pipeline,
 *   "ab: | cloud | pipeline | ms/frame | CPU ms | ratio to the first |", the ratio being the
 *   median over the rounds of the first pipeline's wall time over this one's (> 1: faster than
 *   the first), and the load average at the end.
 * --host-ab (with --interleave): two renderers, without and with the host paths
 *   (rnd_desc.host_paths off and on, the same back end and tunings otherwise), each pipeline
 *   rendered by both in every round: rows "P [gl]" and "P [host]", the ratio of a [host] row
 *   being the median over the rounds of the [gl] frame's wall time over the [host] one's (> 1:
 *   the host paths are faster). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cloud.h"
#include "encode.h"
#include "params.h"
#include "prep.h"
#include "prepared.h"
#include "render.h"
#include "rndtest.h"
#include "sd_err.h"

enum { MAX_FRAMES = 1000, MAX_PIPES = 12 };

typedef struct bench_opts {
    const char *file;
    const char *label;
    const char *save_dir;
    const char *shader_dir;
    double zoom;
    int frames, width, height, threads;
    rnd_backend_kind backend;
    int pipes[MAX_PIPES];
    char pipe_names[MAX_PIPES][96]; /* as given: "soft:order=tile" */
    int npipes;
    const char *sets[MAX_PIPES]; /* --set key=value, applied to every pipeline's parameters */
    int nsets;
    int edl_cost;                /* --edl-cost */
    int interleave;              /* --interleave */
    int host_ab;                 /* --host-ab */
} bench_opts;

typedef struct pipe_result {
    double frame_ms, readback_ms, jpeg_ms;
    double cpu_ms;  /* process CPU time of rnd_render (all threads), median */
    uint64_t drawn;
    uint64_t splats;  /* kawata: splats drawn (last frame) */
    int buffer_w, buffer_h; /* kawata: its image buffer (last frame) */
    uint32_t flags;   /* rnd_frame.flags of any counted frame */
} pipe_result;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* CPU time of the whole process (every llvmpipe thread): steadier than wall time on a shared
 * machine, so better for comparing two versions of a shader. */
static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* median: the median of the n values v (reordered); the mean of the middle two for even n. */
static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof v[0], cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

static void usage(void)
{
    fprintf(stderr, "usage: render_bench FILE [--frames N (1-%d, default 10)] [--size WxH "
                    "(default 1280x720)]\n"
                    "       [--backend auto|egl|osmesa] [--pipelines points,splat] "
                    "[--label NAME] [--threads T] [--save DIR] [--set key=value ...]\n"
                    "       [--shader-dir DIR] [--zoom Z] [--edl-cost] [--interleave] "
                    "[--host-ab]\n",
            MAX_FRAMES);
}

/* pipe_params: applies "key=value:key=value" to p. Returns 0, or -1 with emsg. */
static int pipe_params(sp_params *p, const char *kvs, char *emsg, size_t len)
{
    char buf[96];
    snprintf(buf, sizeof buf, "%s", kvs);
    for (char *save = NULL, *kv = strtok_r(buf, ":", &save); kv; kv = strtok_r(NULL, ":", &save))
        if (sp_param_set_kv(p, kv, emsg, len) != 0) return -1;
    return 0;
}

/* parse_pipelines: fills o->pipes from a comma-separated list of pipeline names (the values of
 * the `pipeline` parameter). Returns 0, or -1 after printing which name is unknown. */
static int parse_pipelines(bench_opts *o, const char *list)
{
    char buf[256], emsg[256];
    snprintf(buf, sizeof buf, "%s", list);
    o->npipes = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok;
         tok = strtok_r(NULL, ",", &save)) {
        sp_params p;
        sp_params_defaults(&p);
        if (o->npipes == MAX_PIPES || strlen(tok) >= sizeof o->pipe_names[0]) {
            fprintf(stderr, "render_bench: --pipelines: more than %d names or '%s' too long\n",
                    MAX_PIPES, tok);
            return -1;
        }
        snprintf(o->pipe_names[o->npipes], sizeof o->pipe_names[0], "%s", tok);
        char *colon = strchr(tok, ':');
        if (colon) *colon = 0;
        if (sp_param_set_text(&p, "pipeline", tok, emsg, sizeof emsg) != 0 ||
            (colon && pipe_params(&p, colon + 1, emsg, sizeof emsg) != 0)) {
            fprintf(stderr, "render_bench: --pipelines: %s\n", emsg);
            return -1;
        }
        o->pipes[o->npipes++] = p.pipeline;
    }
    if (o->npipes == 0) {
        fprintf(stderr, "render_bench: --pipelines: empty list\n");
        return -1;
    }
    return 0;
}

/* parse_int: strict decimal integer in [lo, hi]; returns 0 and *out, or -1. */
static int parse_int(const char *s, long lo, long hi, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end || v < lo || v > hi) return -1;
    *out = (int)v;
    return 0;
}

/* parse_size: "WxH" with both in 1-8192; returns 0 and *w, *h, or -1. */
static int parse_size(const char *s, int *w, int *h)
{
    char wbuf[32];
    const char *x = strchr(s, 'x');
    size_t wl = x ? (size_t)(x - s) : 0;
    if (!x || wl == 0 || wl >= sizeof wbuf) return -1;
    memcpy(wbuf, s, wl);
    wbuf[wl] = 0;
    return parse_int(wbuf, 1, 8192, w) || parse_int(x + 1, 1, 8192, h) ? -1 : 0;
}

/* parse_args: fills o from argv. Returns 0, or -1 after printing what was wrong. */
static int parse_args(int argc, char **argv, bench_opts *o)
{
    memset(o, 0, sizeof *o);
    o->frames = 10;
    o->width = 1280;
    o->height = 720;
    o->backend = RND_BACKEND_AUTO;
    if (parse_pipelines(o, "points,splat") != 0) return -1;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--edl-cost")) {
            o->edl_cost = 1;
            continue;
        }
        if (!strcmp(a, "--interleave")) {
            o->interleave = 1;
            continue;
        }
        if (!strcmp(a, "--host-ab")) {
            o->host_ab = 1;
            continue;
        }
        int takes = a[0] == '-' && a[1] == '-';
        if (takes && !v) {
            fprintf(stderr, "render_bench: %s needs a value\n", a);
            return -1;
        }
        if (!strcmp(a, "--frames")) {
            if (parse_int(v, 1, MAX_FRAMES, &o->frames)) {
                fprintf(stderr, "render_bench: --frames '%s' is not in 1-%d\n", v, MAX_FRAMES);
                return -1;
            }
        } else if (!strcmp(a, "--size")) {
            if (parse_size(v, &o->width, &o->height)) {
                fprintf(stderr, "render_bench: --size '%s' is not WxH with both in 1-8192\n", v);
                return -1;
            }
        } else if (!strcmp(a, "--backend")) {
            if (!strcmp(v, "auto")) o->backend = RND_BACKEND_AUTO;
            else if (!strcmp(v, "egl")) o->backend = RND_BACKEND_EGL;
            else if (!strcmp(v, "osmesa")) o->backend = RND_BACKEND_OSMESA;
            else {
                fprintf(stderr, "render_bench: --backend '%s' is not auto, egl or osmesa\n", v);
                return -1;
            }
        } else if (!strcmp(a, "--pipelines")) {
            if (parse_pipelines(o, v) != 0) return -1;
        } else if (!strcmp(a, "--set")) {
            sp_params t;
            char emsg[200];
            sp_params_defaults(&t);
            if (o->nsets == MAX_PIPES || sp_param_set_kv(&t, v, emsg, sizeof emsg) != 0) {
                fprintf(stderr, "render_bench: --set %s: %s\n", v,
                        o->nsets == MAX_PIPES ? "too many --set" : emsg);
                return -1;
            }
            o->sets[o->nsets++] = v;
        } else if (!strcmp(a, "--label")) {
            o->label = v;
        } else if (!strcmp(a, "--save")) {
            o->save_dir = v;
        } else if (!strcmp(a, "--shader-dir")) {
            o->shader_dir = v;
        } else if (!strcmp(a, "--zoom")) {
            char *end;
            o->zoom = strtod(v, &end);
            if (*end || !(o->zoom >= 1 && o->zoom <= 1e6)) {
                fprintf(stderr, "render_bench: --zoom '%s' is not a number in 1-1e6\n", v);
                return -1;
            }
        } else if (!strcmp(a, "--threads")) {
            if (parse_int(v, 0, 1024, &o->threads)) {
                fprintf(stderr, "render_bench: --threads '%s' is not in 0-1024\n", v);
                return -1;
            }
        } else if (!takes && !o->file) {
            o->file = a;
            continue;
        } else {
            fprintf(stderr, "render_bench: unexpected argument '%s'\n", a);
            return -1;
        }
        i++;
    }
    if (!o->file) {
        fprintf(stderr, "render_bench: no FILE given\n");
        return -1;
    }
    if (o->host_ab && !o->interleave) {
        fprintf(stderr, "render_bench: --host-ab needs --interleave\n");
        return -1;
    }
    if (!o->label) {
        const char *slash = strrchr(o->file, '/');
        o->label = slash ? slash + 1 : o->file;
    }
    return 0;
}

/* orbit: cam0 turned by angle_rad about the axis through its target along its up vector
 * (Rodrigues' rotation of the eye offset), written to cam. */
static void orbit(const rnd_camera *cam0, double angle_rad, rnd_camera *cam)
{
    *cam = *cam0;
    double k[3] = { cam0->up[0], cam0->up[1], cam0->up[2] };
    double kl = sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2]);
    if (!(kl > 0)) return;
    for (int i = 0; i < 3; i++) k[i] /= kl;
    double v[3], c = cos(angle_rad), s = sin(angle_rad);
    for (int i = 0; i < 3; i++) v[i] = cam0->eye[i] - cam0->target[i];
    double kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2];
    double kxv[3] = { k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2],
                      k[0] * v[1] - k[1] * v[0] };
    for (int i = 0; i < 3; i++)
        cam->eye[i] = cam0->target[i] + v[i] * c + kxv[i] * s + k[i] * kv * (1 - c);
}

/* params_of: the parameters of the k-th pipeline of o: the defaults, the --set ones, the
 * pipeline and its own (all checked by parse_args). */
static void params_of(const bench_opts *o, int k, sp_params *p)
{
    char emsg[200];
    sp_params_defaults(p);
    for (int i = 0; i < o->nsets; i++) sp_param_set_kv(p, o->sets[i], emsg, sizeof emsg);
    p->pipeline = o->pipes[k];
    const char *colon = strchr(o->pipe_names[k], ':');
    if (colon) pipe_params(p, colon + 1, emsg, sizeof emsg);
}

/* bench_pipeline: renders 1 + o->frames frames of cloud id through pipeline pipe and fills res
 * with the medians. Returns 0, or a negative SD_E* code with err filled. */
static int bench_pipeline(rnd_ctx *r, uint32_t id, const rnd_camera *cam0, int k,
                          const bench_opts *o, enc_ctx *enc, pipe_result *res, sd_err *err)
{
    sp_params p, jp;
    params_of(o, k, &p);
    jp = p;
    jp.format = SP_FMT_JPEG;
    jp.quality = 85;
    jp.subsampling = SP_SUB_420;
    double *t_frame = calloc((size_t)o->frames * 4, sizeof(double));
    if (!t_frame) return sd_errf(err, SD_ENOMEM, "render_bench: out of memory");
    double *t_read = t_frame + o->frames, *t_jpeg = t_read + o->frames;
    double *t_cpu = t_jpeg + o->frames;
    rnd_frame f;
    memset(&f, 0, sizeof f);
    int rc = 0;
    for (int i = -1; i < o->frames && rc == 0; i++) {
        rnd_camera cam;
        orbit(cam0, (i + 1) * 0.5 * M_PI / 180.0, &cam);
        double c0 = cpu_s(), t0 = now_s();
        rc = rnd_render(r, id, &cam, &p, 0, &f, err);
        double t1 = now_s(), c1 = cpu_s();
        if (rc < 0) break;
        const uint8_t *out;
        size_t len;
        rc = enc_encode(enc, &f, &jp, &out, &len, err);
        double t2 = now_s();
        if (rc < 0 || i < 0) continue;
        t_read[i] = (double)f.readback_us * 1e-3;
        t_frame[i] = (t1 - t0) * 1e3 - t_read[i];
        t_jpeg[i] = (t2 - t1) * 1e3;
        t_cpu[i] = (c1 - c0) * 1e3;
        res->drawn = f.points_drawn;
        res->splats = f.splats_drawn;
        res->buffer_w = f.buffer_w, res->buffer_h = f.buffer_h;
        res->flags |= f.flags;
    }
    if (rc == 0) {
        res->frame_ms = median(t_frame, o->frames);
        res->readback_ms = median(t_read, o->frames);
        res->jpeg_ms = median(t_jpeg, o->frames);
        res->cpu_ms = median(t_cpu, o->frames);
        if (o->save_dir) {
            char path[4096];
            snprintf(path, sizeof path, "%s/%s-%s.png", o->save_dir, o->label, o->pipe_names[k]);
            rc = enc_write_file(path, &f, &jp, err);
        }
    }
    rnd_frame_free(&f);
    free(t_frame);
    return rc;
}

/* bench_edl: o->frames pairs of frames of pipeline pipe at one camera each, shading=lambert
 * then shading=edl, printing the "edl:" row (see the top). Returns 0 or SD_E*. */
static int bench_edl(rnd_ctx *r, uint32_t id, const rnd_camera *cam0, int pipe,
                     const bench_opts *o, sd_err *err)
{
    sp_params p[2];
    char emsg[200];
    for (int k = 0; k < 2; k++) {
        sp_params_defaults(&p[k]);
        for (int i = 0; i < o->nsets; i++) sp_param_set_kv(&p[k], o->sets[i], emsg, sizeof emsg);
        p[k].pipeline = pipe;
        p[k].shading = k ? SP_SHADING_EDL : SP_SHADING_LAMBERT;
    }
    double *t = calloc((size_t)o->frames * 4, sizeof(double));
    if (!t) return sd_errf(err, SD_ENOMEM, "render_bench: out of memory");
    double *ta = t, *tb = t + o->frames, *dw = tb + o->frames, *dc = dw + o->frames;
    rnd_frame f;
    memset(&f, 0, sizeof f);
    int rc = 0;
    for (int i = -1; i < o->frames && rc == 0; i++) {
        rnd_camera cam;
        orbit(cam0, (i + 1) * 0.5 * M_PI / 180.0, &cam);
        double w[2], c[2];
        for (int k = 0; k < 2 && rc == 0; k++) {
            double c0 = cpu_s(), t0 = now_s();
            rc = rnd_render(r, id, &cam, &p[k], 0, &f, err);
            w[k] = (now_s() - t0) * 1e3 - (double)f.readback_us * 1e-3;
            c[k] = (cpu_s() - c0) * 1e3;
        }
        if (rc < 0 || i < 0) continue;
        ta[i] = w[0], tb[i] = w[1], dw[i] = w[1] - w[0], dc[i] = c[1] - c[0];
    }
    if (rc == 0) {
        char name[32];
        sp_enum_name(SP_PIPELINE, pipe, name, sizeof name);
        printf("edl: | %s | %s | %.1f | %.1f | %.2f | %.2f |\n", o->label, name,
               median(ta, o->frames), median(tb, o->frames), median(dw, o->frames),
               median(dc, o->frames));
    }
    rnd_frame_free(&f);
    free(t);
    return rc;
}

/* bench_interleaved: 1 + o->frames rounds, each rendering every pipeline once at the round's
 * camera (the first round is the warm-up) on each of the nr renderers r[] (cloud ids id[]),
 * entry k being pipeline k / nr on renderer k % nr; fills res[k].frame_ms and cpu_ms with
 * medians and prints the "ab:" rows (see the top). Returns 0 or SD_E*. */
static int bench_interleaved(rnd_ctx *const *r, const uint32_t *id, int nr,
                             const rnd_camera *cam0, const bench_opts *o, pipe_result *res,
                             sd_err *err)
{
    int np = o->npipes * nr, nf = o->frames;
    double *t = calloc((size_t)np * (size_t)nf * 3, sizeof(double));
    if (!t) return sd_errf(err, SD_ENOMEM, "render_bench: out of memory");
    double *tw = t, *tc = t + (size_t)np * nf, *ratio = tc + (size_t)np * nf;
    sp_params p[2 * MAX_PIPES];
    for (int k = 0; k < np; k++) params_of(o, k / nr, &p[k]);
    rnd_frame f;
    memset(&f, 0, sizeof f);
    int rc = 0;
    for (int i = -1; i < nf && rc == 0; i++) {
        rnd_camera cam;
        orbit(cam0, (i + 1) * 0.5 * M_PI / 180.0, &cam);
        for (int k = 0; k < np && rc == 0; k++) {
            double c0 = cpu_s(), t0 = now_s();
            rc = rnd_render(r[k % nr], id[k % nr], &cam, &p[k], 0, &f, err);
            double w = (now_s() - t0) * 1e3 - (double)f.readback_us * 1e-3;
            if (rc < 0 || i < 0) continue;
            tw[(size_t)k * nf + i] = w;
            tc[(size_t)k * nf + i] = (cpu_s() - c0) * 1e3;
            res[k].drawn = f.points_drawn;
            res[k].flags |= f.flags;
        }
        /* the ratio to the first entry, or with two renderers to the pipeline's [gl] entry */
        for (int k = 0; k < np && rc == 0 && i >= 0; k++) {
            int ref = nr == 2 ? k - k % 2 : 0;
            ratio[(size_t)k * nf + i] = tw[(size_t)ref * nf + i] / tw[(size_t)k * nf + i];
        }
    }
    for (int k = 0; k < np && rc == 0; k++) {
        res[k].frame_ms = median(tw + (size_t)k * nf, nf);
        res[k].cpu_ms = median(tc + (size_t)k * nf, nf);
        printf("ab: | %s | %s%s | %.1f | %.1f | %.2f |\n", o->label, o->pipe_names[k / nr],
               nr == 2 ? (k % 2 ? " [host]" : " [gl]") : "", res[k].frame_ms, res[k].cpu_ms,
               median(ratio + (size_t)k * nf, nf));
    }
    if (rc == 0) {
        FILE *la = fopen("/proc/loadavg", "r");
        char line[64] = "?";
        if (la && fgets(line, sizeof line, la)) line[strcspn(line, "\n")] = 0;
        if (la) fclose(la);
        printf("ab-load: %s\n", line);
    }
    rnd_frame_free(&f);
    free(t);
    return rc;
}

/* load_and_prep: pc_load + prep_run of o->file into pc, printing the "prep:" row.
 * Returns 0 or a negative SD_E* code with err filled. */
static int load_and_prep(const bench_opts *o, pc_prepared *pc, sd_err *err)
{
    pc_cloud c;
    memset(&c, 0, sizeof c);
    double t0 = now_s();
    int rc = pc_load(o->file, &c, err);
    if (rc < 0) return rc;
    double t1 = now_s();
    prep_desc d;
    memset(&d, 0, sizeof d);
    d.threads = o->threads;
    rc = prep_run(&c, &d, pc, err);
    double t2 = now_s();
    pc_cloud_free(&c);
    if (rc < 0) return rc;
    printf("splat_radius_median: %g\n", (double)pc->radius_median);
    printf("prep: | %s | %llu | %.2f | %.2f | %.0f |\n", o->label, (unsigned long long)pc->n,
           t1 - t0, t2 - t1, (double)pc->n / (t2 - t1));
    fflush(stdout);
    return 0;
}

int main(int argc, char **argv)
{
    bench_opts o;
    if (parse_args(argc, argv, &o) != 0) {
        usage();
        return 2;
    }
    sd_err err;
    memset(&err, 0, sizeof err);
    pc_prepared pc;
    memset(&pc, 0, sizeof pc);
    rnd_ctx *r = NULL, *rgl = NULL; /* rgl: --host-ab's renderer without the host paths */
    enc_ctx *enc = NULL;
    int rc = 1;

    if (load_and_prep(&o, &pc, &err) < 0) goto fail;
    rnd_desc rd;
    memset(&rd, 0, sizeof rd);
    rd.backend = o.backend;
    rd.shader_dir = o.shader_dir;
    if (o.host_ab) rd.host_paths = RND_CAP_ON;
    if (!(r = rnd_create(&rd, &err))) goto fail;
    if (o.host_ab) {
        rd.host_paths = RND_CAP_OFF;
        if (!(rgl = rnd_create(&rd, &err))) goto fail;
    }
    printf("renderer: %s\n", rnd_renderer_string(r));
    fflush(stdout);
    if (!(enc = enc_create(&err))) goto fail;
    uint64_t npts = pc.n;
    rnd_camera cam0;
    tu_camera_box(pc.bmin, pc.bmax, o.width, o.height, &cam0);
    if (o.zoom > 1)
        for (int i = 0; i < 3; i++)
            cam0.eye[i] = cam0.target[i] + (cam0.eye[i] - cam0.target[i]) / o.zoom;
    int64_t id = rnd_upload(r, &pc, &err), idgl = 0;
    if (id < 0) goto fail;
    if (rgl && (idgl = rnd_upload(rgl, &pc, &err)) < 0) goto fail;
    pc_prepared_free(&pc); /* the renderer keeps what it needs */

    pipe_result res[2 * MAX_PIPES];
    memset(res, 0, sizeof res);
    double points_ms = 0;
    rnd_ctx *const rs[2] = {rgl ? rgl : r, r};
    const uint32_t ids[2] = {rgl ? (uint32_t)idgl : (uint32_t)id, (uint32_t)id};
    if (o.interleave && bench_interleaved(rgl ? rs : rs + 1, rgl ? ids : ids + 1, rgl ? 2 : 1,
                                          &cam0, &o, res, &err) < 0)
        goto fail;
    for (int k = 0; k < o.npipes && !o.interleave; k++) {
        if (bench_pipeline(r, (uint32_t)id, &cam0, k, &o, enc, &res[k], &err) < 0)
            goto fail;
        if (o.pipes[k] == SP_PIPE_POINTS) points_ms = res[k].frame_ms;
    }
    for (int k = 0; k < o.npipes && !o.host_ab; k++) {
        char ratio[32] = "-";
        const char *name = o.pipe_names[k];
        if (points_ms > 0) snprintf(ratio, sizeof ratio, "%.2f", res[k].frame_ms / points_ms);
        printf("| %s | %llu | %s | %.1f | %s | %.2f | %.2f |\n", o.label,
               (unsigned long long)npts, name, res[k].frame_ms, ratio, res[k].readback_ms,
               res[k].jpeg_ms);
        fprintf(stderr, "cpu: %s %s %.1f ms/frame\n", o.label, name, res[k].cpu_ms);
        if (res[k].flags)
            fprintf(stderr, "flags: %s %s 0x%x (soft samples dropped)\n", o.label, name,
                    res[k].flags);
    }
    for (int k = 0; k < o.npipes && o.edl_cost; k++)
        if (bench_edl(r, (uint32_t)id, &cam0, o.pipes[k], &o, &err) < 0) goto fail;
    /* Pipelines with an image buffer (kawata): its size and the splats drawn, one line each
     * ("buffer: | label | pipeline | WxH | splats |"), for bench_render.sh's table. */
    for (int k = 0; k < o.npipes; k++) {
        if (!res[k].buffer_w) continue;
        char name[32];
        sp_enum_name(SP_PIPELINE, o.pipes[k], name, sizeof name);
        printf("buffer: | %s | %s | %dx%d | %llu |\n", o.label, name, res[k].buffer_w,
               res[k].buffer_h, (unsigned long long)res[k].splats);
    }
    rc = 0;
fail:
    if (rc) fprintf(stderr, "render_bench: %s\n", err.msg[0] ? err.msg : "failed");
    enc_destroy(enc);
    if (r) rnd_destroy(r);
    if (rgl) rnd_destroy(rgl);
    pc_prepared_free(&pc);
    return rc;
}
