/* cmd_render.c — `splatd render FILE -o OUT.jpg|png|exr [options]`: renders one frame without
 * the network (scripted jobs, tests, benchmarks). Exit status: 0 done, 1 failed, 2 usage. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "cache.h"
#include "commands.h"
#include "encode.h"
#include "prep.h"
#include "progress.h"
#include "render.h"
#include "view.h"

enum { MAX_SIDE = 8192 };

static const char USAGE[] =
    "usage: splatd render FILE -o OUT.jpg|png|exr [options]\n"
    "  --pipeline NAME             the pipeline, one of %s (default splat)\n"
    "  --eye x,y,z --target x,y,z --up x,y,z\n"
    "                              camera in the file's coordinates (default: frames the cloud)\n"
    "  --fov DEG                   vertical field of view (default 45)\n"
    "  --size WxH                  frame size (default 1280x720, at most 8192x8192)\n"
    "  --near N --far F            clip distances (default: from the cloud's bounds)\n"
    "  --set key=value             any render parameter (repeatable; see PROTOCOL.md)\n"
    "  --backend auto|egl|osmesa   GL back end (default auto: EGL, then OSMesa)\n"
    "  --shader-dir DIR            load shaders from DIR before the built-in ones\n"
    "  --points-raster FORM        the points pipeline's form: auto, packed (depth quanta, ties\n"
    "                              by point index), exact (float depth: splatd --mpi's form, so\n"
    "                              its frames match these exactly) or gl (default auto)\n"
    "  --cache DIR --k N           prepared-cloud cache directory and neighbour count\n"
    "  --quiet                     no progress or timing on stderr\n";

typedef struct render_opts {
    const char *file, *out, *shader_dir;
    rnd_backend_kind backend;
    int points_raster;       /* RND_RASTER_* */
    cache_desc cache;
    int have_eye, have_target, have_up;
    double eye[3], target[3], up[3];
    double fov, znear, zfar;
    int width, height;
    int quiet;
} render_opts;

static void warn_stderr(void *user, const char *msg)
{
    (void)user;
    fprintf(stderr, "splatd render: warning: %s\n", msg);
}

/* Parses a finite number; prints the error and returns -1 when s is not one. */
static int parse_num(const char *opt, const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || errno || !isfinite(v)) {
        fprintf(stderr, "splatd render: %s needs a number, got '%s'\n", opt, s);
        return -1;
    }
    *out = v;
    return 0;
}

/* Parses "x,y,z". */
static int parse_vec3(const char *opt, const char *s, double v[3])
{
    char *end;
    const char *p = s;
    for (int k = 0; k < 3; k++) {
        errno = 0;
        v[k] = strtod(p, &end);
        if (end == p || errno || !isfinite(v[k]) || (k < 2 && *end != ',') || (k == 2 && *end)) {
            fprintf(stderr, "splatd render: %s needs three numbers x,y,z, got '%s'\n", opt, s);
            return -1;
        }
        p = end + 1;
    }
    return 0;
}

/* Parses "WxH" with 1 <= W, H <= MAX_SIDE. */
static int parse_size(const char *s, int *w, int *h)
{
    char *end;
    errno = 0;
    long a = strtol(s, &end, 10);
    if (end != s && (*end == 'x' || *end == 'X') && !errno) {
        const char *p = end + 1;
        long b = strtol(p, &end, 10);
        if (end != p && !*end && !errno && a >= 1 && b >= 1 && a <= MAX_SIDE && b <= MAX_SIDE) {
            *w = (int)a;
            *h = (int)b;
            return 0;
        }
    }
    fprintf(stderr, "splatd render: --size needs WxH with each side in [1, %d], got '%s'\n",
            MAX_SIDE, s);
    return -1;
}

/* Parses argv into o and p. Returns 0, or 2 (usage error, already printed), or -1 for --help. */
static int parse_args(int argc, char **argv, render_opts *o, sp_params *p)
{
    char perr[256];
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) return -1;
        if (!strcmp(a, "--quiet")) {
            o->quiet = 1;
            continue;
        }
        if (a[0] != '-') {
            if (o->file) {
                fprintf(stderr, "splatd render: one FILE only ('%s' is extra)\n", a);
                return 2;
            }
            o->file = a;
            continue;
        }
        static const char *const with_value[] = {
            "-o", "--pipeline", "--eye", "--target", "--up", "--fov", "--size", "--near",
            "--far", "--set", "--backend", "--shader-dir", "--cache", "--k",
            "--points-raster", NULL};
        int known = 0;
        for (int k = 0; with_value[k]; k++) known |= !strcmp(a, with_value[k]);
        if (!known) {
            fprintf(stderr, "splatd render: unknown option '%s' (see splatd render --help)\n", a);
            return 2;
        }
        if (i + 1 >= argc) {
            fprintf(stderr, "splatd render: %s needs a value\n", a);
            return 2;
        }
        const char *v = argv[++i];
        double num;
        if (!strcmp(a, "-o")) {
            o->out = v;
        } else if (!strcmp(a, "--pipeline")) {
            if (sp_param_set_text(p, "pipeline", v, perr, sizeof perr) < 0) {
                fprintf(stderr, "splatd render: --pipeline: %s\n", perr);
                return 2;
            }
        } else if (!strcmp(a, "--set")) {
            if (sp_param_set_kv(p, v, perr, sizeof perr) < 0) {
                fprintf(stderr, "splatd render: --set: %s\n", perr);
                return 2;
            }
        } else if (!strcmp(a, "--eye")) {
            if (parse_vec3(a, v, o->eye) < 0) return 2;
            o->have_eye = 1;
        } else if (!strcmp(a, "--target")) {
            if (parse_vec3(a, v, o->target) < 0) return 2;
            o->have_target = 1;
        } else if (!strcmp(a, "--up")) {
            if (parse_vec3(a, v, o->up) < 0) return 2;
            o->have_up = 1;
        } else if (!strcmp(a, "--fov")) {
            if (parse_num(a, v, &o->fov) < 0) return 2;
            if (!(o->fov > 0 && o->fov < 180)) {
                fprintf(stderr, "splatd render: --fov %s is outside (0, 180) degrees\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--size")) {
            if (parse_size(v, &o->width, &o->height) < 0) return 2;
        } else if (!strcmp(a, "--near") || !strcmp(a, "--far")) {
            if (parse_num(a, v, &num) < 0) return 2;
            if (!(num > 0)) {
                fprintf(stderr, "splatd render: %s must be positive, got %s\n", a, v);
                return 2;
            }
            *(a[2] == 'n' ? &o->znear : &o->zfar) = num;
        } else if (!strcmp(a, "--backend")) {
            if (!strcmp(v, "auto")) o->backend = RND_BACKEND_AUTO;
            else if (!strcmp(v, "egl")) o->backend = RND_BACKEND_EGL;
            else if (!strcmp(v, "osmesa")) o->backend = RND_BACKEND_OSMESA;
            else {
                fprintf(stderr, "splatd render: --backend '%s' is not auto, egl or osmesa\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--shader-dir")) {
            o->shader_dir = v;
        } else if (!strcmp(a, "--points-raster")) {
            static const struct { const char *name; int form; } forms[] = {
                {"auto", RND_RASTER_AUTO}, {"packed", RND_RASTER_PACKED},
                {"exact", RND_RASTER_EXACT}, {"gl", RND_RASTER_GL}};
            o->points_raster = -1;
            for (int k = 0; k < 4; k++)
                if (!strcmp(v, forms[k].name)) o->points_raster = forms[k].form;
            if (o->points_raster < 0) {
                fprintf(stderr, "splatd render: --points-raster '%s' is not auto, packed, exact "
                        "or gl\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--cache")) {
            o->cache.dir = v;
        } else if (!strcmp(a, "--k")) {
            if (parse_num(a, v, &num) < 0) return 2;
            if (num != floor(num) || num < 1 || num > 256) {
                fprintf(stderr, "splatd render: --k needs an integer in [1, 256], got '%s'\n", v);
                return 2;
            }
            o->cache.k = (int)num;
        }
    }
    if (!o->file || !o->out) {
        fprintf(stderr, "splatd render: %s\n", !o->file ? "no FILE given" : "no -o OUT given");
        fprintf(stderr, USAGE, SP_PIPELINE_VALUES);
        return 2;
    }
    if (o->znear > 0 && o->zfar > 0 && o->zfar <= o->znear) {
        fprintf(stderr, "splatd render: --far %g is not beyond --near %g\n", o->zfar, o->znear);
        return 2;
    }
    sd_err err = {0};
    int fmt = enc_format_from_path(o->out, &err);
    if (fmt < 0 || (fmt != SP_FMT_JPEG && fmt != SP_FMT_PNG && fmt != SP_FMT_EXR)) {
        fprintf(stderr, "splatd render: -o %s: the name must end in .jpg, .jpeg, .png or .exr\n",
                o->out);
        return 2;
    }
    p->format = fmt;
    return 0;
}

/* The camera: framing the cloud, then whatever the options set. */
static void make_camera(const render_opts *o, const pc_prepared *pc, rnd_camera *cam)
{
    sp_view v;
    view_of_prepared(pc, &v);
    rnd_camera_frame(&v, o->width, o->height, o->fov, cam);
    for (int k = 0; k < 3; k++) {
        if (o->have_eye) cam->eye[k] = o->eye[k];
        if (o->have_target) cam->target[k] = o->target[k];
        if (o->have_up) cam->up[k] = o->up[k];
    }
    if (o->fov > 0) cam->fov_deg = (float)o->fov;
    cam->znear = (float)o->znear;
    cam->zfar = (float)o->zfar;
}

int cmd_render(int argc, char **argv)
{
    render_opts o = {.width = RND_DEFAULT_WIDTH, .height = RND_DEFAULT_HEIGHT,
                     .cache = {.k = PREP_DEFAULT_K}};
    sp_params p;
    sp_params_defaults(&p);
    int rc = parse_args(argc, argv, &o, &p);
    if (rc == -1) {
        printf(USAGE, SP_PIPELINE_VALUES);
        return 0;
    }
    if (rc) return rc;
    struct stat st;
    if (stat(o.file, &st) != 0) {
        fprintf(stderr, "splatd render: cannot open %s: %s\n", o.file, strerror(errno));
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        fprintf(stderr, "splatd render: %s is not a regular file\n", o.file);
        return 1;
    }
    o.cache.warn = warn_stderr;
    o.cache.progress = o.quiet ? NULL : prep_progress_stderr; /* whole lines off a terminal */

    sd_err err = {0};
    pc_prepared pc;
    cache_result cr;
    if (cache_open_cloud(o.file, &o.cache, &pc, &cr, &err) < 0) {
        fprintf(stderr, "splatd render: %s\n", err.msg);
        return 1;
    }
    rnd_desc d = {.backend = o.backend, .shader_dir = o.shader_dir,
                  .pipe = {.points_raster = o.points_raster}};
    rnd_ctx *r = rnd_create(&d, &err);
    if (!r) {
        fprintf(stderr, "splatd render: %s\n", err.msg);
        pc_prepared_free(&pc);
        return 1;
    }
    if (!o.quiet)
        fprintf(stderr, "splatd render: %s; %llu points (%s)\n", rnd_renderer_string(r),
                (unsigned long long)pc.n, cr.hit ? "cached" : "prepared now");
    rnd_camera cam;
    make_camera(&o, &pc, &cam);
    rnd_frame f = {0};
    int64_t id = rnd_upload(r, &pc, &err);
    pc_prepared_free(&pc);
    rc = 1;
    if (id < 0) {
        fprintf(stderr, "splatd render: %s\n", err.msg);
        goto done;
    }
    if (rnd_render(r, (uint32_t)id, &cam, &p, p.format == SP_FMT_EXR, &f, &err) < 0) {
        fprintf(stderr, "splatd render: %s\n", err.msg);
        goto done;
    }
    if (enc_write_file(o.out, &f, &p, &err) < 0) {
        fprintf(stderr, "splatd render: %s\n", err.msg);
        goto done;
    }
    if (!o.quiet)
        fprintf(stderr, "splatd render: %llu points drawn, render %.1f ms, read-back %.1f ms, "
                "wrote %s (%dx%d)\n", (unsigned long long)f.points_drawn, f.render_us / 1e3,
                f.readback_us / 1e3, o.out, f.width, f.height);
    rc = 0;
done:
    rnd_frame_free(&f);
    rnd_destroy(r);
    return rc;
}
