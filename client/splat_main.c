/* splat_main.c — the `splat` command: list, info, render and camera-path jobs against a
 * splatd daemon, through libsplatclient. Exit status: 0 success, 1 a failure (any server
 * ERROR included, printed with its code), 2 a usage error. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "attrs.h"
#include "campath.h"
#include "cli.h"
#include "params.h"
#include "proto.h"
#include "shard.h"
#include "splat_client.h"

enum { EXIT_FAIL = 1, EXIT_USAGE = 2 };

#ifndef SPLAT_VERSION
#define SPLAT_VERSION "0.1.0"
#endif

static const char conn_opts[] =
    "connection options:\n"
    "  --host H          server host (default 127.0.0.1)\n"
    "  --port P          server port (default 7878)\n"
    "  --token-file F    shared token, mode 0600 (when the server requires one)\n"
    "  --tls             connect with TLS, trusting the system's certificates and checking that\n"
    "                    the server's certificate names H\n"
    "  --tls-ca F        trust the CA certificate(s) in PEM file F instead (implies --tls)\n"
    "  --tls-name N      the name the certificate must carry when it is not H (implies --tls)\n"
    "  --timeout S       seconds one request may take (default 60, 0 = none)\n"
    "  -q, --quiet       no progress output\n"
    "  -h, --help        this text\n";

static const char camera_opts[] =
    "camera (file coordinates; without --eye the view frames the cloud's bounding box):\n"
    "  --eye x,y,z --target x,y,z --up x,y,z --fov DEG (default 45)\n"
    "  --size WxH        frame size (default 1280x720)\n";

/* params_help: the --set parameters, their ranges and defaults, from the parameter table. */
static void params_help(FILE *f)
{
    fprintf(f, "parameters (--set key=value, repeatable; the output file's extension decides "
               "'format'):\n");
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        const sp_param_info *p = &sp_param_table[i];
        char range[160];
        if (p->type == SP_T_ENUM) snprintf(range, sizeof range, "%s", p->values);
        else snprintf(range, sizeof range, "%s in [%g, %g]",
                      p->type == SP_T_FLOAT ? "number" : p->type == SP_T_INT ? "integer"
                                                                               : "x,y,z each",
                      p->min, p->max);
        fprintf(f, "  %-14s %-40s default %s\n", p->name, range, p->def);
    }
}

/* usage: the help of one command (cmd NULL: the overview). */
static void usage(FILE *f, const char *cmd)
{
    if (!cmd) {
        fprintf(f,
            "splat " SPLAT_VERSION " — client of the splatd point-cloud rendering daemon\n"
            "\n"
            "usage: splat [--host H] [--port P] [--token-file F] [--tls] [-q] COMMAND ...\n"
            "\n"
            "commands (splat COMMAND --help for each one's options):\n"
            "  list                       the clouds in the server's data directory\n"
            "  info NAME                  open a cloud (extension optional) and print its summary\n"
            "  render NAME -o FILE        render one frame (.jpg .png .exr .raw)\n"
            "  path NAME (--path FILE | --orbit N) -o 'dir/%%05d.jpg'\n"
            "                             render a camera path; frames already written are skipped\n"
            "  view NAME [--size WxH]     an interactive window (the program splat-view, SDL2)\n"
            "  --version                  print the version and exit\n"
            "\n");
        fputs(conn_opts, f);
    } else if (!strcmp(cmd, "list")) {
        fprintf(f,
            "usage: splat list [connection options]\n"
            "\n"
            "Lists the clouds in the server's data directory: NAME, file BYTES, POINTS (once\n"
            "prepared) and STATE: 'loaded' (in the server's memory), 'prepared' (cached, loads\n"
            "quickly) or '-' (the first OPEN prepares it).\n\n");
        fputs(conn_opts, f);
    } else if (!strcmp(cmd, "info")) {
        fprintf(f,
            "usage: splat info NAME [--set key=value ...] [connection options]\n"
            "\n"
            "Opens cloud NAME (preparing it on first use, with progress) and prints its summary:\n"
            "points, bounds, offset, attributes, point spacing sigma, k, and the server's back end.\n\n");
        fputs(conn_opts, f);
    } else if (!strcmp(cmd, "render")) {
        fprintf(f,
            "usage: splat render NAME -o FILE [camera] [--set key=value ...] [connection options]\n"
            "\n"
            "Renders one frame of cloud NAME into FILE; the format follows FILE's extension: .jpg,\n"
            ".png, .exr (half RGBA + float Z), .raw (the server's bytes as sent).\n\n");
        fputs(camera_opts, f);
        fputc('\n', f);
        fputs(conn_opts, f);
        fputc('\n', f);
        params_help(f);
    } else { /* path */
        fprintf(f,
            "usage: splat path NAME (--path FILE | --orbit N) -o PATTERN [options]\n"
            "\n"
            "Renders a camera path of cloud NAME into numbered files, several frames in flight.\n"
            "Frames that exist already are skipped, so an interrupted job resumes.\n"
            "\n"
            "  -o PATTERN        output files with one %%d or %%05d, e.g. 'out/%%05d.jpg'\n"
            "  --path FILE       one camera per line: eye x y z, target x y z, up x y z, fov;\n"
            "                    '#' comments; spaces and/or commas between numbers\n"
            "  --orbit N         N cameras around the bounding-box centre, about --up (default:\n"
            "                    the up axis the default camera guesses from the bounds)\n"
            "  --inflight K      frames in flight (default 2, 1..64)\n"
            "  --prefetch K      announce the next K cameras to the server (default 4, 0..16;\n"
            "                    0 = off): a level-of-detail cloud's nodes load ahead\n"
            "  --force           re-render frames that already exist\n"
            "  --shard I/N       render only frames i with i %% N == I (a farm's worker I of N);\n"
            "                    without it: $JOB_COMPLETION_INDEX (Kubernetes Indexed Job) of\n"
            "                    --shards N or $SPLAT_SHARD_COUNT, else $SLURM_ARRAY_TASK_ID\n"
            "                    (minus $SLURM_ARRAY_TASK_MIN) of $SLURM_ARRAY_TASK_COUNT\n"
            "  --shards N        the shard count when the index comes from the environment\n"
            "  --size WxH, --fov DEG, --up x,y,z  as for render\n"
            "\n");
        fputs(conn_opts, f);
        fputc('\n', f);
        params_help(f);
    }
}

/* fail: prints the client's last error and returns EXIT_FAIL. */
static int fail(spc_client *c, const char *what)
{
    fprintf(stderr, "splat: %s: %s\n", what, spc_errmsg(c));
    return EXIT_FAIL;
}

static void on_progress(void *user, const char *phase, float fraction, const char *text)
{
    const cli_args *a = user;
    if (a->quiet) return;
    char what[300];
    if (text && text[0]) snprintf(what, sizeof what, "%s", text);
    else snprintf(what, sizeof what, "%s %.0f%%", phase, 100.0 * fraction);
    if (isatty(2)) fprintf(stderr, "\rpreparing %s: %s\033[K", a->name, what);
    else fprintf(stderr, "preparing %s: %s\n", a->name, what);
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* open_cloud: OPEN with progress, then the --set parameters plus format (when not NULL). */
static int open_cloud(spc_client *c, const cli_args *a, const char *format, spc_info *info)
{
    /* provisional=1 must precede the OPEN it changes; the other parameters follow it */
    for (int i = 0; i < a->nsets; i++)
        if (!strncmp(a->sets[i], "provisional=", 12) && spc_set_param(c, a->sets[i]) < 0)
            return fail(c, "parameters");
    int rc = spc_open(c, a->name, info, on_progress, (void *)a);
    if (!a->quiet && isatty(2)) fprintf(stderr, "\r\033[K");
    if (rc < 0) return fail(c, a->name);
    const char *kv[CLI_MAX_SETS + 1];
    int n = 0;
    for (int i = 0; i < a->nsets; i++) kv[n++] = a->sets[i];
    char fkv[32];
    if (format) {
        snprintf(fkv, sizeof fkv, "format=%s", format);
        kv[n++] = fkv;
    }
    if (n && spc_set_params(c, kv, n) < 0) return fail(c, "parameters");
    return 0;
}

/* make_camera: the camera of `render` from the options and the cloud's bounds. */
static void make_camera(const cli_args *a, const spc_info *info, spc_camera *cam)
{
    spc_camera_frame(info, a->width, a->height, cam);
    if (a->have_eye) {
        memcpy(cam->eye, a->eye, sizeof cam->eye);
        for (int i = 0; i < 3; i++) cam->target[i] = 0.5 * (info->bmin[i] + info->bmax[i]);
        cam->up[0] = 0, cam->up[1] = 0, cam->up[2] = 1;
    }
    if (a->have_target) memcpy(cam->target, a->target, sizeof cam->target);
    if (a->have_up) memcpy(cam->up, a->up, sizeof cam->up);
    if (a->have_fov) cam->fov_deg = a->fov;
}

static int cmd_list(spc_client *c)
{
    spc_cloud *l;
    int n = spc_list(c, &l);
    if (n < 0) return fail(c, "list");
    printf("%-40s %14s %12s  %s\n", "NAME", "BYTES", "POINTS", "STATE");
    for (int i = 0; i < n; i++)
        printf("%-40s %14llu %12llu  %s\n", l[i].name, (unsigned long long)l[i].bytes,
               (unsigned long long)l[i].points,
               l[i].flags & 2 ? "loaded" : l[i].flags & 1 ? "prepared" : "-");
    spc_free_list(l);
    return 0;
}

static int cmd_info(spc_client *c, const cli_args *a)
{
    spc_info in;
    int rc = open_cloud(c, a, NULL, &in);
    if (rc) return rc;
    char attrs[160];
    sp_attr_names(in.attrs, attrs, sizeof attrs);
    printf("name        %s\n", in.name);
    printf("format      %s\n", in.format);
    printf("points      %llu (%llu dropped)\n", (unsigned long long)in.points,
           (unsigned long long)in.dropped);
    printf("bounds min  %.17g %.17g %.17g\n", in.bmin[0], in.bmin[1], in.bmin[2]);
    printf("bounds max  %.17g %.17g %.17g\n", in.bmax[0], in.bmax[1], in.bmax[2]);
    printf("offset      %.17g %.17g %.17g\n", in.offset[0], in.offset[1], in.offset[2]);
    printf("attributes  %s\n", attrs);
    printf("sigma       %.9g\n", (double)in.sigma);
    printf("k           %u\n", in.k);
    const spc_server_info *s = spc_server(c);
    printf("server      %s, %s, %s\n", s->server, s->backend, s->renderer);
    return 0;
}

static int cmd_render(spc_client *c, const cli_args *a)
{
    const char *fmt = cp_ext_format(a->output);
    if (!fmt) {
        fprintf(stderr, "splat: cannot tell the format of %s: use .jpg, .png, .exr or .raw\n",
                a->output);
        return EXIT_USAGE;
    }
    spc_info in;
    int rc = open_cloud(c, a, fmt, &in);
    if (rc) return rc;
    spc_camera cam;
    make_camera(a, &in, &cam);
    if (spc_set_camera(c, &cam, NULL) < 0) return fail(c, "camera");
    spc_frame f;
    if (spc_render(c, &f, 0) < 0) return fail(c, "render");
    char err[600];
    if (cp_mkdirs(a->output, err, sizeof err) < 0 ||
        cp_write_file(a->output, f.data, f.data_len, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        return EXIT_FAIL;
    }
    if (!a->quiet)
        fprintf(stderr, "wrote %s: %ux%u %s %s, %zu bytes; render %.1f ms, readback %.1f ms, "
                "encode %.1f ms, %llu points%s\n", a->output, f.width, f.height, f.pipeline,
                f.format, f.data_len, f.render_us / 1e3, f.readback_us / 1e3, f.encode_us / 1e3,
                (unsigned long long)f.points_drawn,
                f.provisional ? " (provisional: the first image, the full cloud still preparing)" : "");
    return 0;
}

/* progress output of a path job: a bar redrawn in place on a terminal, else a plain line at
 * most every 2 seconds (and at the end). */
typedef struct prog {
    int tty, quiet;
    double t0, last;
} prog;

static void prog_show(prog *p, long done, long total, int final)
{
    if (p->quiet) return;
    double t = now_s();
    char line[200];
    if (p->tty) {
        if (!final && t - p->last < 0.1) return;
        fprintf(stderr, "\r%s\033[K%s", cp_progress_line(line, sizeof line, done, total,
                                                          t - p->t0, 30), final ? "\n" : "");
    } else {
        if (!final && t - p->last < 2.0) return;
        fprintf(stderr, "%s\n", cp_progress_line(line, sizeof line, done, total, t - p->t0, 0));
    }
    p->last = t;
}

typedef struct inflight {
    uint32_t seq;
    long index;
} inflight;

/* path_cam: the camera of frame idx of n: from the path file's cameras, else the orbit. */
static void path_cam(const cli_args *a, const cp_cam *cams, const spc_info *in, long n, long idx,
                     spc_camera *cam)
{
    if (cams) {
        memset(cam, 0, sizeof *cam);
        memcpy(cam->eye, cams[idx].eye, sizeof cam->eye);
        memcpy(cam->target, cams[idx].target, sizeof cam->target);
        memcpy(cam->up, cams[idx].up, sizeof cam->up);
        cam->fov_deg = cams[idx].fov;
        cam->width = a->width;
        cam->height = a->height;
    } else {
        spc_camera_orbit(in, a->have_up ? a->up : NULL, (int)idx, (int)n,
                         a->have_fov ? a->fov : 45.0f, a->width, a->height, cam);
    }
}

static int cmd_path(spc_client *c, const cli_args *a)
{
    char err[600];
    const char *fmt = cp_ext_format(a->output);
    if (cp_pattern_check(a->output, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        return EXIT_USAGE;
    }
    if (!fmt) {
        fprintf(stderr, "splat: cannot tell the format of %s: use .jpg, .png, .exr or .raw\n",
                a->output);
        return EXIT_USAGE;
    }
    cp_cam *cams = NULL;
    size_t ncams = 0;
    if (a->path_file && cp_load(a->path_file, &cams, &ncams, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        return EXIT_USAGE;
    }
    shard_env se = {a->shard, a->shards, getenv("JOB_COMPLETION_INDEX"),
                    getenv("SPLAT_SHARD_COUNT"), getenv("SLURM_ARRAY_TASK_ID"),
                    getenv("SLURM_ARRAY_TASK_COUNT"), getenv("SLURM_ARRAY_TASK_MIN")};
    shard sh;
    if (shard_resolve(&se, &sh, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        free(cams);
        return EXIT_USAGE;
    }
    long n = a->path_file ? (long)ncams : a->orbit;
    long *todo = malloc((size_t)n * sizeof *todo);
    long ntodo = todo ? cp_todo(a->output, n, a->force, todo) : -1;
    int rc = 0;
    if (ntodo < 0) {
        fprintf(stderr, "splat: cannot plan %ld frames for %s\n", n, a->output);
        rc = EXIT_FAIL;
        goto out;
    }
    ntodo = shard_filter(&sh, todo, ntodo);
    /* the frames of this shard: a resumed shard counts only its own as existing */
    long nmine = sh.count > 1 ? (n - sh.index + sh.count - 1) / sh.count : n;
    if (sh.count > 1 && !a->quiet)
        fprintf(stderr, "shard %ld of %ld (from %s): frames i with i %% %ld == %ld, %ld of %ld\n",
                sh.index, sh.count, sh.source, sh.count, sh.index, nmine, n);
    if (ntodo == 0) {
        if (!a->quiet)
            fprintf(stderr, "all %ld frames of %s exist already (--force renders them again)\n",
                    nmine, a->output);
        goto out;
    }
    char first[4096];
    cp_expand(a->output, todo[0], first, sizeof first);
    if (cp_mkdirs(first, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        rc = EXIT_FAIL;
        goto out;
    }
    spc_info in;
    if ((rc = open_cloud(c, a, fmt, &in)) != 0) goto out;
    if (!a->quiet && ntodo < nmine)
        fprintf(stderr, "resuming: %ld of %ld frames exist, %ld to render\n", nmine - ntodo,
                nmine, ntodo);

    inflight fl[64];
    int nfl = 0;
    long sent = 0, got = 0;
    prog pg = {isatty(2), a->quiet, now_s(), 0};
    uint64_t sum_render = 0, sum_encode = 0, bytes = 0;
    while (got < ntodo) {
        while (sent < ntodo && nfl < a->inflight) {
            long idx = todo[sent];
            spc_camera cam;
            path_cam(a, cams, &in, n, idx, &cam);
            uint32_t seq;
            if (spc_send_render(c, &cam, &seq) < 0) {
                snprintf(err, sizeof err, "frame %ld", idx);
                rc = fail(c, err);
                goto out;
            }
            /* the cameras after the ones in flight: the server loads their nodes meanwhile */
            spc_camera next[16];
            int np = 0;
            for (long j = sent + 1; j < ntodo && np < a->prefetch; j++)
                path_cam(a, cams, &in, n, todo[j], &next[np++]);
            if (np && spc_prefetch(c, next, np) < 0) {
                rc = fail(c, "prefetch");
                goto out;
            }
            fl[nfl].seq = seq;
            fl[nfl].index = idx;
            nfl++;
            sent++;
        }
        spc_frame f;
        if (spc_recv_frame(c, &f, 0) < 0) {
            if (!a->quiet && pg.tty) fprintf(stderr, "\n");
            /* name the frame: the error's request is its CAMERA or its RENDER */
            uint32_t es = spc_errseq(c);
            snprintf(err, sizeof err, "path");
            for (int j = 0; j < nfl; j++)
                if (es && (fl[j].seq == es || fl[j].seq == es + 1))
                    snprintf(err, sizeof err, "frame %ld", fl[j].index);
            rc = fail(c, err);
            goto out;
        }
        int k = 0;
        while (k < nfl && fl[k].seq != f.seq) k++;
        if (k == nfl) {
            if (f.seq == 0) continue; /* a streamed frame: not ours */
            fprintf(stderr, "splat: the server sent a frame for request %u, which is not in "
                    "flight\n", f.seq);
            rc = EXIT_FAIL;
            goto out;
        }
        char name[4096];
        cp_expand(a->output, fl[k].index, name, sizeof name);
        if (cp_write_file(name, f.data, f.data_len, err, sizeof err) < 0) {
            fprintf(stderr, "\nsplat: %s\n", err);
            rc = EXIT_FAIL;
            goto out;
        }
        memmove(&fl[k], &fl[k + 1], (size_t)(nfl - k - 1) * sizeof fl[0]);
        nfl--;
        got++;
        sum_render += f.render_us;
        sum_encode += f.encode_us;
        bytes += f.data_len;
        prog_show(&pg, got, ntodo, got == ntodo);
    }
    if (!a->quiet) {
        double el = now_s() - pg.t0;
        fprintf(stderr, "%ld frames in %.2f s (%.2f frames/s, %d in flight); server render %.1f "
                "ms, encode %.1f ms per frame on average; %.1f KiB per frame\n", got, el,
                got / (el > 0 ? el : 1), a->inflight, sum_render / 1e3 / got,
                sum_encode / 1e3 / got, bytes / 1024.0 / got);
    }
out:
    free(todo);
    free(cams);
    return rc;
}

/* exec_view: `splat view ...` runs the viewer, splat-view, a binary of its own so that `splat`
 * needs no SDL2 or X11: $SPLAT_VIEW_BIN, else splat-view next to this program, else the one
 * on PATH. argv without the word "view" goes to it. Returns only when no viewer could run. */
static int exec_view(int argc, char **argv, int view_at)
{
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av) return EXIT_FAIL;
    int n = 0;
    av[n++] = "splat-view";
    for (int i = 1; i < argc; i++)
        if (i != view_at) av[n++] = argv[i];
    av[n] = NULL;
    const char *env = getenv("SPLAT_VIEW_BIN");
    if (env && env[0]) {
        execv(env, av);
        fprintf(stderr, "splat: cannot run the viewer %s: %s\n", env, strerror(errno));
        free(av);
        return EXIT_FAIL;
    }
    char self[4096];
    ssize_t len = readlink("/proc/self/exe", self, sizeof self - 16);
    if (len > 0) {
        self[len] = 0;
        char *slash = strrchr(self, '/');
        if (slash) {
            strcpy(slash + 1, "splat-view");
            execv(self, av);
        }
    }
    execvp("splat-view", av);
    fprintf(stderr, "splat: cannot run the viewer splat-view (build it with make, or set "
            "SPLAT_VIEW_BIN): %s\n", strerror(errno));
    free(av);
    return EXIT_FAIL;
}

/* view_command: the index of the word "view" when it is the command (the first operand,
 * after any options and their values), else 0. */
static int view_command(int argc, char **argv)
{
    static const char *const with_value[] = {
        "--host", "--port", "--token-file", "--tls-ca", "--tls-name", "--timeout", "--set", "-o", "--path", "--orbit",
        "--inflight", "--prefetch", "--eye", "--target", "--up", "--fov", "--size", "--script",
        "--drag-budget", "--shard", "--shards"};
    for (int i = 1; i < argc; i++) {
        const char *s = argv[i];
        if (!strcmp(s, "--")) return i + 1 < argc && !strcmp(argv[i + 1], "view") ? i + 1 : 0;
        int takes = 0;
        for (size_t k = 0; k < sizeof with_value / sizeof with_value[0]; k++)
            takes |= !strcmp(s, with_value[k]);
        if (takes) {
            i++;
            continue;
        }
        if (s[0] == '-') continue;
        return strcmp(s, "view") ? 0 : i;
    }
    return 0;
}

int main(int argc, char **argv)
{
    cli_args a;
    char err[600];
    int view_at = view_command(argc, argv);
    if (view_at) return exec_view(argc, argv, view_at);
    if (cli_parse(argc, argv, &a, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        return EXIT_USAGE;
    }
    if (a.version) {
        printf("splat %s (protocol version %u)\n", SPLAT_VERSION, (unsigned)PROTO_VERSION);
        return 0;
    }
    if (a.help) {
        usage(stdout, a.command);
        return 0;
    }
    /* check --set locally before connecting: a typo fails fast with the range */
    sp_params chk;
    sp_params_defaults(&chk);
    for (int i = 0; i < a.nsets; i++)
        if (sp_param_set_kv(&chk, a.sets[i], err, sizeof err) < 0) {
            fprintf(stderr, "splat: --set %s: %s\n", a.sets[i], err);
            return EXIT_USAGE;
        }
    spc_options o = {.host = a.host, .port = a.port, .token_file = a.token_file,
                     .tls = a.tls, .tls_ca = a.tls_ca, .tls_name = a.tls_name,
                     .timeout_ms = a.timeout_s ? a.timeout_s * 1000 : -1,
                     .client_name = "splat"};
    spc_client *c;
    if (spc_connect(&o, &c, err, sizeof err) < 0) {
        fprintf(stderr, "splat: %s\n", err);
        return EXIT_FAIL;
    }
    int rc;
    if (!strcmp(a.command, "list")) rc = cmd_list(c);
    else if (!strcmp(a.command, "info")) rc = cmd_info(c, &a);
    else if (!strcmp(a.command, "render")) rc = cmd_render(c, &a);
    else rc = cmd_path(c, &a);
    spc_close(c);
    return rc;
}
