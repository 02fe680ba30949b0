/* test_viewer.c — `splat view` end to end: a daemon, a virtual X server (Xvfb) and the viewer
 * driven by --script. The saved view must equal `splat render` of the camera the viewer prints
 * at quit, a pipeline key must reach the server (the frames' pipeline), keys the server lacks
 * must not be errors, a continuous drag must give reduced-resolution frames and the rest a full
 * one, and a bad script must be refused naming its line. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "daemonproc.h"
#include "imgtest.h"
#include "testutil.h"

/* The saved view and `splat render` of the same camera come from the same renderer and the
 * same PNG encoder: they are expected to be equal; 40 dB leaves room for a renderer whose
 * output varies slightly between two runs, and still fails for a camera off by a degree or a
 * missing E key (the bunny with and without EDL: 17.9 dB). */
#define MIN_PSNR_DB 40.0

static pid_t xvfb_pid;
static char display[32];

/* start_xvfb: a virtual X server on a free display number; 0, or -1 when there is none. */
static int start_xvfb(void)
{
    if (access("/usr/bin/Xvfb", X_OK) != 0) return -1;
    for (int n = 90 + (int)(getpid() % 50); n < 190; n++) {
        char lock[64], sock[64];
        snprintf(lock, sizeof lock, "/tmp/.X%d-lock", n);
        snprintf(sock, sizeof sock, "/tmp/.X11-unix/X%d", n);
        if (access(lock, F_OK) == 0 || access(sock, F_OK) == 0) continue;
        char dn[16];
        snprintf(dn, sizeof dn, ":%d", n);
        pid_t pid = fork();
        if (pid < 0) return -1;
        if (pid == 0) {
            freopen("/dev/null", "w", stderr);
            freopen("/dev/null", "w", stdout);
            /* -br: a black root window, so that every lit pixel on the screen is the
             * viewer's. */
            execl("/usr/bin/Xvfb", "Xvfb", dn, "-screen", "0", "1280x1024x24", "-br",
                  "-nolisten", "tcp", (char *)NULL);
            _exit(127);
        }
        for (int i = 0; i < 500; i++) {
            int st;
            if (waitpid(pid, &st, WNOHANG) == pid) break; /* taken meanwhile: try the next */
            if (access(sock, F_OK) == 0) {
                xvfb_pid = pid;
                snprintf(display, sizeof display, "%s", dn);
                setenv("DISPLAY", display, 1);
                return 0;
            }
            usleep(10000);
        }
        if (xvfb_pid == 0) {
            kill(pid, SIGKILL);
            waitpid(pid, NULL, 0);
        }
    }
    return -1;
}

static int group_setup(void **state)
{
    (void)state;
    if (start_xvfb() < 0) xvfb_pid = 0;
    return 0;
}

static int group_teardown(void **state)
{
    (void)state;
    if (xvfb_pid > 0) {
        kill(xvfb_pid, SIGTERM);
        waitpid(xvfb_pid, NULL, 0);
    }
    return 0;
}

typedef struct fx {
    char *root;
    char data[700], cache[700];
    tu_daemon d;
} fx;

static int setup(void **state)
{
    fx *f = calloc(1, sizeof *f);
    if (!f || tu_tmpdir_setup((void **)&f->root) != 0) return -1;
    snprintf(f->data, sizeof f->data, "%s/data", f->root);
    snprintf(f->cache, sizeof f->cache, "%s/cache", f->root);
    mkdir(f->data, 0755);
    mkdir(f->cache, 0700);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fx *f = *state;
    if (f->d.pid) tu_daemon_stop(&f->d);
    tu_tmpdir_teardown((void **)&f->root);
    free(f);
    return 0;
}

/* start_daemon_with: splatd on the bunny (tests/data/bun000.ply) as "bun.ply", with the
 * options in extra (NULL-terminated; may be NULL) besides. */
static void start_daemon_with(fx *f, const char *const *extra)
{
    char src[700], dst[800];
    tu_data("bun000.ply", src, sizeof src);
    snprintf(dst, sizeof dst, "%s/bun.ply", f->data);
    assert_int_equal(tu_copy_file(src, dst), 0);
    const char *args[16] = {"--listen", "127.0.0.1:0", "--data", f->data, "--cache", f->cache};
    int n = 6;
    for (; extra && *extra && n < 15; extra++) args[n++] = *extra;
    args[n] = NULL;
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
}

static void start_daemon(fx *f)
{
    start_daemon_with(f, NULL);
}

/* run_cmd: runs argv (NULL-terminated) with stdout to out_path and stderr to err_path, killed
 * after limit_s seconds; returns the exit status (-1: died of a signal or was killed). */
static int run_cmd(const char *const *argv, const char *out_path, const char *err_path,
                   int limit_s)
{
    fflush(stdout); /* the child's freopen would write what is buffered a second time */
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        if (!freopen(out_path, "w", stdout) || !freopen(err_path, "w", stderr)) _exit(126);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    for (int i = 0; i < limit_s * 100; i++) {
        int st;
        if (waitpid(pid, &st, WNOHANG) == pid) return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
        usleep(10000);
    }
    kill(pid, SIGKILL);
    waitpid(pid, NULL, 0);
    return -1;
}

/* slurp: a whole text file (malloc'd, NUL-terminated), failing the test when unreadable. */
static char *slurp(const char *path)
{
    size_t len;
    uint8_t *b = tu_read_file(path, &len);
    if (!b) fail_msg("cannot read %s", path);
    char *s = realloc(b, len + 1);
    assert_non_null(s);
    s[len] = 0;
    return s;
}

/* run_view_with: `splat view bun --script FILE --verbose` at 320x240 with the options in extra
 * (NULL-terminated; may be NULL) besides; its stdout in a malloc'd string. Fails the test on a
 * non-zero exit, showing stderr. */
static char *run_view_with(fx *f, const char *script_text, const char *tag,
                           const char *const *extra)
{
    char script[800], out[800], err[800], port[16];
    snprintf(script, sizeof script, "%s/%s.script", f->root, tag);
    snprintf(out, sizeof out, "%s/%s.out", f->root, tag);
    snprintf(err, sizeof err, "%s/%s.err", f->root, tag);
    snprintf(port, sizeof port, "%d", f->d.port);
    assert_int_equal(tu_write_file(script, script_text, strlen(script_text)), 0);
    const char *argv[16] = {tu_splat_bin(), "--port", port, "view", "bun", "--size", "320x240",
                            "--script", script, "--verbose"};
    int n = 10;
    for (; extra && *extra && n < 15; extra++) argv[n++] = *extra;
    argv[n] = NULL;
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int rc = run_cmd(argv, out, err, 30);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    char *e = slurp(err);
    if (rc != 0) fail_msg("splat view exited %d:\n%s", rc, e);
    free(e);
    printf("splat view (%s) ran %.2f s\n", tag,
           (t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9);
    return slurp(out);
}

static char *run_view(fx *f, const char *script_text, const char *tag)
{
    return run_view_with(f, script_text, tag, NULL);
}

/* read_png: the top-down RGBA8 pixels of a PNG file (malloc'd); fails the test when it cannot. */
static uint8_t *read_png(const char *path, uint32_t *w, uint32_t *h)
{
    uint8_t *px = NULL;
    if (tu_png_read(path, 0, w, h, &px) < 0) fail_msg("%s: not a readable PNG", path);
    return px;
}

static void skip_without_x(void)
{
    if (xvfb_pid <= 0)
        TU_SKIP("no X server for the window: /usr/bin/Xvfb is missing or found no free display "
                "(deploy/deps.sh installs the package xvfb)");
}

/* An orbit, a pipeline change (key 1: points), keys for things this server may lack, E
 * (shading=edl) and a save: the saved PNG equals `splat render` of the final camera with
 * pipeline=points and shading=edl. */
static void test_view_save_matches_render(void **state)
{
    skip_without_x();
    fx *f = *state;
    start_daemon(f);
    char png[800], ref[800], script[2400];
    snprintf(png, sizeof png, "%s/view.png", f->root);
    snprintf(ref, sizeof ref, "%s/ref.png", f->root);
    snprintf(script, sizeof script,
             "# orbit a little, switch to points, press keys that may be unavailable\n"
             "wait 200\n"
             "drag 40 0\n"
             "wait 50\n"
             "drag 30 -20   # and up\n"
             "wheel 2\n"
             "wait 300\n"
             "key 1\n"
             "wait 300\n"
             "key 9\n"
             "wait 100\n"
             "key U\n"
             "wait 100\n"
             "key J\n"
             "wait 100\n"
             "key E   # shading=edl\n"
             "wait 300\n"
             "save %s\n"
             "quit\n", png);
    char *out = run_view(f, script, "save");
    /* The pipeline key reached the server: a frame rendered by `points` came back. */
    if (!strstr(out, "pipeline=points")) fail_msg("no frame from pipeline points:\n%s", out);
    if (!strstr(out, "pipeline=splat")) fail_msg("no frame before the key (splat):\n%s", out);
    /* A digit past the server's pipelines is a status line, not an error. */
    if (!strstr(out, "status no pipeline 9")) fail_msg("key 9 gave no status:\n%s", out);
    const char *cam = strstr(out, "\ncamera --eye ");
    if (!cam) fail_msg("no final camera in the output:\n%s", out);
    double e[3], t[3], u[3], fov;
    unsigned w, h;
    assert_int_equal(sscanf(cam, "\ncamera --eye %lf,%lf,%lf --target %lf,%lf,%lf --up %lf,%lf,%lf "
                            "--fov %lf --size %ux%u", &e[0], &e[1], &e[2], &t[0], &t[1], &t[2],
                            &u[0], &u[1], &u[2], &fov, &w, &h), 12);
    assert_int_equal(w, 320);
    assert_int_equal(h, 240);

    /* The same camera through `splat render`. */
    char eye[200], target[200], up[200], fovs[40], size[40], port[16];
    snprintf(eye, sizeof eye, "%.17g,%.17g,%.17g", e[0], e[1], e[2]);
    snprintf(target, sizeof target, "%.17g,%.17g,%.17g", t[0], t[1], t[2]);
    snprintf(up, sizeof up, "%.17g,%.17g,%.17g", u[0], u[1], u[2]);
    snprintf(fovs, sizeof fovs, "%.9g", fov);
    snprintf(size, sizeof size, "%ux%u", w, h);
    snprintf(port, sizeof port, "%d", f->d.port);
    char rout[800], rerr[800];
    snprintf(rout, sizeof rout, "%s/render.out", f->root);
    snprintf(rerr, sizeof rerr, "%s/render.err", f->root);
    /* At rest the viewer asks for what `splat render` gets by default but for the pipeline
     * and the shading (U then J leave lambda where it was, and lambda does not touch
     * `points`): the E key must have reached the server too. */
    const char *argv[] = {tu_splat_bin(), "--port", port, "render", "bun", "-o", ref, "--eye",
                          eye, "--target", target, "--up", up, "--fov", fovs, "--size", size,
                          "--set", "pipeline=points", "--set", "shading=edl", NULL};
    int rc = run_cmd(argv, rout, rerr, 30);
    if (rc != 0) {
        char *m = slurp(rerr);
        fail_msg("splat render exited %d: %s", rc, m);
    }

    uint32_t vw, vh, rw, rh;
    uint8_t *a = read_png(png, &vw, &vh), *b = read_png(ref, &rw, &rh);
    assert_int_equal(vw, 320);
    assert_int_equal(vh, 240);
    assert_int_equal(rw, vw);
    assert_int_equal(rh, vh);
    size_t n = (size_t)vw * vh, lit;
    double psnr = tu_psnr_all(a, b, n, &lit);
    printf("saved view: %zu of %zu pixels lit; PSNR against splat render %.2f dB (bound %.0f)\n",
           lit, n, psnr, MIN_PSNR_DB);
    if (lit < n / 50) fail_msg("the saved view is blank: %zu of %zu pixels lit", lit, n);
    if (psnr < MIN_PSNR_DB) fail_msg("PSNR %.2f dB < %.0f dB", psnr, MIN_PSNR_DB);
    free(a);
    free(b);
    free(out);
}

/* parse_frames: the sizes of the frames in a --verbose log, in order (*n of them). */
static int parse_frames(const char *out, unsigned *ws, unsigned *hs, int *moving, int cap)
{
    int n = 0;
    for (const char *p = out; (p = strstr(p, "frame ")) && n < cap; p++) {
        if (p != out && p[-1] != '\n') continue;
        const char *m = strstr(p, "moving=");
        if (sscanf(p, "frame %ux%u", &ws[n], &hs[n]) == 2 && m) {
            moving[n] = m[7] == '1';
            n++;
        }
    }
    return n;
}

/* A continuous drag of 2 s: reduced-resolution frames (160x120) during it, the full frame
 * (320x240) after it; then a resize to 400x300 gives frames of that size. */
static void test_view_progressive_drag(void **state)
{
    skip_without_x();
    fx *f = *state;
    start_daemon(f);
    char script[4096] = "wait 300\n";
    for (int i = 0; i < 40; i++) strcat(script, "drag 6 1\nwait 50\n"); /* 40 x 50 ms = 2 s */
    strcat(script, "wait 700\nresize 400 300\nwait 700\nquit\n");
    char *out = run_view(f, script, "drag");
    unsigned ws[4096], hs[4096];
    int mv[4096];
    int n = parse_frames(out, ws, hs, mv, 4096);
    int reduced = 0, last_reduced = -1;
    for (int i = 0; i < n; i++)
        if (ws[i] == 160 && hs[i] == 120) reduced++, last_reduced = i;
    const char *st = strstr(out, "stats ");
    printf("drag: %d frames, %d at 160x120; %.*s\n", n, reduced,
           st ? (int)strcspn(st, "\n") : 0, st ? st : "");
    if (reduced < 5) fail_msg("only %d reduced frames during a 2 s drag:\n%s", reduced, out);
    assert_true(n > 0);
    int full_after = 0;
    for (int i = last_reduced + 1; i < n; i++) full_after += ws[i] == 320 && hs[i] == 240;
    if (!full_after) fail_msg("no full 320x240 frame after the drag:\n%s", out);
    /* The resize after the drag: the frame size follows the window, full at rest. */
    if (ws[n - 1] != 400 || hs[n - 1] != 300 || mv[n - 1])
        fail_msg("the last frame is %ux%u (moving %d), not 400x300 at rest:\n%s", ws[n - 1],
                 hs[n - 1], mv[n - 1], out);
    free(out);
}

/* The daemon stops and comes back on the same port: the viewer reports the disconnection,
 * reconnects by itself, and renders (and saves) again. */
static void test_view_reconnects(void **state)
{
    skip_without_x();
    fx *f = *state;
    start_daemon(f);
    int port_n = f->d.port;
    char script[800], out[800], err[800], png[800], port[16];
    snprintf(script, sizeof script, "%s/re.script", f->root);
    snprintf(out, sizeof out, "%s/re.out", f->root);
    snprintf(err, sizeof err, "%s/re.err", f->root);
    snprintf(png, sizeof png, "%s/after.png", f->root);
    snprintf(port, sizeof port, "%d", port_n);
    char text[1200];
    snprintf(text, sizeof text, "wait 300\ndrag 10 0\nwait 3500\ndrag 10 0\nwait 500\n"
             "save %s\nquit\n", png);
    assert_int_equal(tu_write_file(script, text, strlen(text)), 0);
    const char *argv[] = {tu_splat_bin(), "--port", port, "view", "bun", "--size", "160x120",
                          "--script", script, "--verbose", NULL};
    fflush(stdout);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        if (!freopen(out, "w", stdout) || !freopen(err, "w", stderr)) _exit(126);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    /* Stop the daemon once the viewer has its first frame; restart it on the same port. */
    for (int i = 0; i < 1000; i++) {
        size_t len;
        uint8_t *b = tu_read_file(out, &len); /* NULL until the child has created it */
        int has = b && memmem(b, len, "frame ", 6) != NULL;
        free(b);
        if (has) break;
        usleep(10000);
    }
    assert_int_equal(tu_daemon_stop(&f->d), 0);
    usleep(600000);
    char listen[64];
    snprintf(listen, sizeof listen, "127.0.0.1:%d", port_n);
    const char *args[] = {"--listen", listen, "--data", f->data, "--cache", f->cache, NULL};
    assert_int_equal(tu_daemon_start(&f->d, f->root, NULL, args), 0);
    int st = 0, rc = -1;
    for (int i = 0; i < 2000; i++) {
        if (waitpid(pid, &st, WNOHANG) == pid) {
            rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
            break;
        }
        usleep(10000);
    }
    if (rc == -1) {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
    }
    char *o = slurp(out), *e = slurp(err);
    if (rc != 0) fail_msg("splat view exited %d: %s\n%s", rc, e, o);
    const char *dis = strstr(o, "status disconnected");
    if (!dis) fail_msg("no disconnection reported:\n%s", o);
    if (!strstr(dis, "\nframe ")) fail_msg("no frame after reconnecting:\n%s", o);
    if (!strstr(o, "saved ")) fail_msg("no save after reconnecting:\n%s", o);
    uint32_t w, h;
    uint8_t *px = read_png(png, &w, &h);
    assert_int_equal(w, 160);
    assert_int_equal(h, 120);
    free(px);
    free(o);
    free(e);
}

/* A viewer at rest outlives the server's idle timeout by sending PING (--keepalive): with a
 * 2 s --idle-timeout and 4.5 s of rest, the viewer without keep-alive is closed by the server
 * (the defect: it reports the disconnection), the one with --keepalive 1 is not and saves. */
static void test_view_keepalive(void **state)
{
    skip_without_x();
    fx *f = *state;
    const char *const dargs[] = {"--idle-timeout", "2", NULL};
    start_daemon_with(f, dargs);
    char png[800], text[1200];
    snprintf(png, sizeof png, "%s/rest.png", f->root);
    snprintf(text, sizeof text, "wait 300\ndrag 10 0\nwait 4500\nsave %s\nquit\n", png);
    const char *const off[] = {"--keepalive", "0", NULL};
    char *o = run_view_with(f, text, "nokeep", off);
    if (!strstr(o, "status disconnected"))
        fail_msg("without keep-alive the server's 2 s idle timeout did not close the viewer:\n%s",
                 o);
    if (strstr(o, "\nping\n")) fail_msg("--keepalive 0 sent PING:\n%s", o);
    free(o);
    const char *const on[] = {"--keepalive", "1", NULL};
    o = run_view_with(f, text, "keep", on);
    if (strstr(o, "status disconnected"))
        fail_msg("with --keepalive 1 the viewer was disconnected:\n%s", o);
    int pings = 0;
    for (const char *q = o; (q = strstr(q, "\nping\n")); q++) pings++;
    if (pings < 3) fail_msg("%d PINGs in 4.5 s of rest with --keepalive 1 (expected >= 3):\n%s",
                            pings, o);
    if (!strstr(o, "saved ")) fail_msg("no save after the rest:\n%s", o);
    free(o);
}

static uint32_t be32(const uint8_t *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* xwd_lit: the pixels brighter than 8 in any channel in an xwd dump of the screen (4 bytes
 * per pixel, TrueColor), or -1 when the file is not one. */
static long xwd_lit(const char *path)
{
    size_t len;
    uint8_t *b = tu_read_file(path, &len);
    if (!b || len < 100) return free(b), -1;
    uint32_t hsize = be32(b), w = be32(b + 16), h = be32(b + 20), order = be32(b + 28);
    uint32_t bpp = be32(b + 44), bpl = be32(b + 48), ncolors = be32(b + 76);
    uint32_t masks[3] = {be32(b + 56), be32(b + 60), be32(b + 64)};
    size_t off = (size_t)hsize + (size_t)ncolors * 12;
    /* Xvfb's depth-24 dumps say 24 bits per pixel but store 4 bytes each. */
    if ((bpp != 24 && bpp != 32) || w == 0 || bpl / w != 4 || off + (size_t)bpl * h > len)
        return free(b), -1;
    long lit = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            const uint8_t *q = b + off + (size_t)y * bpl + 4 * x;
            uint32_t v = order ? be32(q) : (uint32_t)q[3] << 24 | (uint32_t)q[2] << 16 |
                                               (uint32_t)q[1] << 8 | q[0];
            int bright = 0;
            for (int c = 0; c < 3; c++) {
                uint32_t m = masks[c], val = v & m;
                while (m && !(m & 1)) m >>= 1, val >>= 1;
                bright |= val > 8;
            }
            lit += bright;
        }
    free(b);
    return lit;
}

/* The window shows the frames: a dump of the virtual screen while the viewer rests holds
 * about as many lit pixels as the saved view of the same camera (JPEG q95 on screen against
 * the lossless save: within a factor 1.5). Needs xwd (Debian package x11-apps). */
static void test_view_window_shows_frames(void **state)
{
    skip_without_x();
    if (access("/usr/bin/xwd", X_OK) != 0)
        TU_SKIP("no /usr/bin/xwd to capture the screen (Debian package x11-apps)");
    fx *f = *state;
    start_daemon(f);
    char script[800], out[800], err[800], png[800], dump[800], port[16], text[1200];
    snprintf(script, sizeof script, "%s/win.script", f->root);
    snprintf(out, sizeof out, "%s/win.out", f->root);
    snprintf(err, sizeof err, "%s/win.err", f->root);
    snprintf(png, sizeof png, "%s/win.png", f->root);
    snprintf(dump, sizeof dump, "%s/screen.xwd", f->root);
    snprintf(port, sizeof port, "%d", f->d.port);
    snprintf(text, sizeof text, "wait 300\ndrag 30 0\nwait 2500\nsave %s\nquit\n", png);
    assert_int_equal(tu_write_file(script, text, strlen(text)), 0);
    const char *argv[] = {tu_splat_bin(), "--port", port, "view", "bun", "--size", "320x240",
                          "--script", script, "--verbose", NULL};
    fflush(stdout);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        if (!freopen(out, "w", stdout) || !freopen(err, "w", stderr)) _exit(126);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    /* Wait for the full frame after the drag, then dump the screen. */
    int rest = 0;
    for (int i = 0; i < 1000 && !rest; i++) {
        size_t len;
        uint8_t *b = tu_read_file(out, &len);
        const uint8_t *moved = b ? memmem(b, len, "frame 160x120", 13) : NULL;
        rest = moved && memmem(moved, len - (size_t)(moved - b), "frame 320x240", 13);
        free(b);
        usleep(10000);
    }
    usleep(500000);
    char dout[800], derr[800];
    snprintf(dout, sizeof dout, "%s/xwd.out", f->root);
    snprintf(derr, sizeof derr, "%s/xwd.err", f->root);
    const char *xargv[] = {"/usr/bin/xwd", "-root", "-silent", "-display", display, "-out", dump,
                           NULL};
    int xrc = run_cmd(xargv, dout, derr, 20);
    int st = 0, rc = -1;
    for (int i = 0; i < 2000; i++) {
        if (waitpid(pid, &st, WNOHANG) == pid) {
            rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
            break;
        }
        usleep(10000);
    }
    if (rc == -1) {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
    }
    assert_true(rest);
    assert_int_equal(xrc, 0);
    assert_int_equal(rc, 0);
    long screen = xwd_lit(dump);
    uint32_t w, h;
    uint8_t *px = read_png(png, &w, &h);
    long saved = 0;
    for (size_t i = 0; i < (size_t)w * h; i++)
        saved += px[4 * i] > 8 || px[4 * i + 1] > 8 || px[4 * i + 2] > 8;
    free(px);
    printf("window: %ld lit pixels on the screen, %ld in the saved view\n", screen, saved);
    assert_true(saved > 1000);
    if (screen < saved / 1.5 || screen > saved * 1.5)
        fail_msg("the screen has %ld lit pixels, the saved view %ld", screen, saved);
}

/* A bad script is refused before any window opens, naming file and line. */
static void test_view_script_errors(void **state)
{
    fx *f = *state;
    static const struct { const char *text; const char *needle; } bad[] = {
        {"wait 10\n# fine\nfly 1 2\n", ":3: unknown command"},
        {"drag 1\n", ":1: wrong number of arguments"},
        {"wait ten\n", ":1: not a number"},
        {"\n\nkey NoSuchKey\n", ":3: unknown SDL key name"},
        {"resize 0 10\n", ":1: resize needs"},
        {"quit now\n", ":1: wrong number"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char script[800], out[800], err[800];
        snprintf(script, sizeof script, "%s/bad%zu.script", f->root, i);
        snprintf(out, sizeof out, "%s/bad.out", f->root);
        snprintf(err, sizeof err, "%s/bad.err", f->root);
        assert_int_equal(tu_write_file(script, bad[i].text, strlen(bad[i].text)), 0);
        const char *argv[] = {tu_splat_bin(), "--port", "1", "view", "bun", "--script", script,
                              NULL};
        int rc = run_cmd(argv, out, err, 20);
        char *e = slurp(err);
        if (rc != 2 || !strstr(e, bad[i].needle) || !strstr(e, script))
            fail_msg("case %zu: exit %d, expected 2 and '%s' in: %s", i, rc, bad[i].needle, e);
        free(e);
    }
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_view_save_matches_render, setup, teardown),
        cmocka_unit_test_setup_teardown(test_view_progressive_drag, setup, teardown),
        cmocka_unit_test_setup_teardown(test_view_reconnects, setup, teardown),
        cmocka_unit_test_setup_teardown(test_view_keepalive, setup, teardown),
        cmocka_unit_test_setup_teardown(test_view_window_shows_frames, setup, teardown),
        cmocka_unit_test_setup_teardown(test_view_script_errors, setup, teardown),
    };
    return cmocka_run_group_tests(tests, group_setup, group_teardown);
}
