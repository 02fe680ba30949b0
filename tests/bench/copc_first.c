/* copc_first.c — time from OPEN of a cloud to its first frame through a running splatd, with
 * libsplatclient (bench_copc.sh runs it against a fresh daemon and cache each time).
 *
 *   copc_first --port P --cloud NAME [--provisional 0|1] [--size WxH]
 *
 * Sends provisional=N (before the OPEN), OPEN, then one RENDER of the server's default camera
 * framing (JPEG), and prints one line: "first_ms full_ms points provisional", where first_ms
 * is OPEN sent -> first frame received (client side, the frame not decoded), full_ms OPEN sent
 * -> the full cloud's INFO (spc_wait_ready; = the OPEN's answer without a provisional cloud),
 * points the first frame's points_drawn, provisional its flag. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "splat_client.h"

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static int die(spc_client *c, const char *what, int rc)
{
    fprintf(stderr, "copc_first: %s: %s (%s)\n", what, c ? spc_errmsg(c) : "", spc_strerror(rc));
    return 1;
}

int main(int argc, char **argv)
{
    int port = 7878, prov = 1;
    unsigned w = 1280, h = 720;
    const char *cloud = "ellipsoid.copc.laz";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--port")) port = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--cloud")) cloud = argv[i + 1];
        else if (!strcmp(argv[i], "--provisional")) prov = atoi(argv[i + 1]) != 0;
        else if (!strcmp(argv[i], "--size")) sscanf(argv[i + 1], "%ux%u", &w, &h);
        else { fprintf(stderr, "copc_first: unknown option %s\n", argv[i]); return 2; }
    }
    spc_options o = {.host = "127.0.0.1", .port = port, .client_name = "copc_first",
                     .timeout_ms = 600000};
    spc_client *c;
    char err[256];
    int rc = spc_connect(&o, &c, err, sizeof err);
    if (rc) { fprintf(stderr, "copc_first: %s\n", err); return 1; }
    if ((rc = spc_set_param(c, prov ? "provisional=1" : "provisional=0"))) return die(c, "param", rc);
    spc_info info;
    double t0 = now_ms();
    if ((rc = spc_open(c, cloud, &info, NULL, NULL))) return die(c, "open", rc);
    spc_camera cam;
    spc_camera_frame(&info, w, h, &cam);
    if ((rc = spc_set_camera(c, &cam, NULL))) return die(c, "camera", rc);
    spc_frame f;
    if ((rc = spc_render(c, &f, 0))) return die(c, "render", rc);
    double first = now_ms() - t0;
    unsigned long long pts = (unsigned long long)f.points_drawn;
    int fprov = f.provisional;
    double full = first;
    if (spc_open_provisional(c) || fprov) {
        if ((rc = spc_wait_ready(c, &info, NULL, NULL)) < 0) return die(c, "wait", rc);
        full = now_ms() - t0;
    }
    printf("%.1f %.1f %llu %d\n", first, full, pts, fprov);
    spc_close(c);
    return 0;
}
