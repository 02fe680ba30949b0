/* net_bench.c — end-to-end network benchmark of a running splatd, through libsplatclient.
 *
 *   net_bench --port P --cloud NAME [--size WxH] [--pipeline P] [--latency N] [--path N]
 *
 * 1. Latency: N frames (default 20), one at a time: the time from sending CAMERA+RENDER to
 *    having the frame decoded at the client, against the render + read-back + encode time the
 *    frame reports; the difference minus the client's decode time is the protocol and transfer
 *    overhead. Medians.
 * 2. Throughput: a camera path of N frames (default 100, an orbit) with 1, 2 and 4 frames in
 *    flight, in frames/s, against the render-bound rate 1 / median(render + read-back).
 * Output: Markdown table rows on stdout. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "splat_client.h"
#include "testutil.h"

static double now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e6 + (double)ts.tv_nsec * 1e-3;
}

static int die(spc_client *c, const char *what, int rc)
{
    fprintf(stderr, "net_bench: %s: %s (%s)\n", what, c ? spc_errmsg(c) : "", spc_strerror(rc));
    return 1;
}

int main(int argc, char **argv)
{
    int port = 7878, w = 1280, h = 720, nlat = 20, npath = 100;
    const char *cloud = "Guanyin", *pipeline = "points";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--port")) port = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--cloud")) cloud = argv[i + 1];
        else if (!strcmp(argv[i], "--size")) sscanf(argv[i + 1], "%dx%d", &w, &h);
        else if (!strcmp(argv[i], "--pipeline")) pipeline = argv[i + 1];
        else if (!strcmp(argv[i], "--latency")) nlat = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--path")) npath = atoi(argv[i + 1]);
        else { fprintf(stderr, "net_bench: unknown option %s\n", argv[i]); return 2; }
    }
    if (nlat < 1 || nlat > 1000 || npath < 4 || npath > 10000) {
        fprintf(stderr, "net_bench: --latency 1..1000, --path 4..10000\n");
        return 2;
    }
    spc_options o = {.host = "127.0.0.1", .port = port, .client_name = "net_bench"};
    spc_client *c;
    char err[256];
    int rc = spc_connect(&o, &c, err, sizeof err);
    if (rc) { fprintf(stderr, "net_bench: %s\n", err); return 1; }
    spc_info info;
    if ((rc = spc_open(c, cloud, &info, NULL, NULL))) return die(c, "open", rc);
    char kv[64];
    snprintf(kv, sizeof kv, "pipeline=%s", pipeline);
    if ((rc = spc_set_param(c, kv)) || (rc = spc_set_param(c, "format=jpeg")))
        return die(c, "params", rc);

    /* Warm-up: shader compilation, buffer allocation at this size. */
    spc_camera cam;
    spc_camera_orbit(&info, NULL, 0, 36, 45, (uint32_t)w, (uint32_t)h, &cam);
    spc_frame f;
    for (int i = 0; i < 3; i++) {
        if ((rc = spc_set_camera(c, &cam, NULL)) || (rc = spc_render(c, &f, 1))) return die(c, "warm-up", rc);
    }

    /* 1. latency, one frame at a time */
    double *e2e = calloc((size_t)nlat, sizeof *e2e), *srv = calloc((size_t)nlat, sizeof *srv);
    double *dec = calloc((size_t)nlat, sizeof *dec), *ovh = calloc((size_t)nlat, sizeof *ovh);
    double *rr = calloc((size_t)(nlat > npath ? nlat : npath), sizeof *rr);
    if (!e2e || !srv || !dec || !ovh || !rr) return 1;
    for (int i = 0; i < nlat; i++) {
        spc_camera_orbit(&info, NULL, i, nlat, 45, (uint32_t)w, (uint32_t)h, &cam);
        double t0 = now_us();
        if ((rc = spc_send_render(c, &cam, NULL)) || (rc = spc_recv_frame(c, &f, 1))) return die(c, "render", rc);
        double t1 = now_us();
        e2e[i] = t1 - t0;
        srv[i] = (double)(f.render_us + f.readback_us + f.encode_us);
        dec[i] = (double)f.decode_us;
        ovh[i] = e2e[i] - srv[i] - dec[i];
        rr[i] = (double)(f.render_us + f.readback_us);
    }
    double m_e2e = tu_median(e2e, nlat), m_srv = tu_median(srv, nlat), m_dec = tu_median(dec, nlat);
    double m_ovh = tu_median(ovh, nlat);
    printf("| end-to-end latency, %dx%d JPEG, %s, median of %d | %.1f ms | render+readback+encode %.1f ms, "
           "client decode %.1f ms, protocol+transfer overhead %.2f ms (target <= 2 ms) |\n",
           w, h, pipeline, nlat, m_e2e / 1000, m_srv / 1000, m_dec / 1000, m_ovh / 1000);

    /* 2. a camera path with 1, 2 and 4 frames in flight */
    double render_bound = 0;
    for (int depth = 1; depth <= 4; depth *= 2) {
        int sent = 0, got = 0;
        double t0 = now_us();
        while (got < npath) {
            while (sent < npath && sent - got < depth) {
                spc_camera_orbit(&info, NULL, sent, npath, 45, (uint32_t)w, (uint32_t)h, &cam);
                if ((rc = spc_send_render(c, &cam, NULL))) return die(c, "send", rc);
                sent++;
            }
            if ((rc = spc_recv_frame(c, &f, 0))) return die(c, "receive", rc);
            rr[got] = (double)(f.render_us + f.readback_us);
            got++;
        }
        double fps = npath / ((now_us() - t0) / 1e6);
        double bound = 1e6 / tu_median(rr, npath);
        if (depth == 1) render_bound = bound;
        printf("| camera path, %d frames, %d in flight | %.1f frames/s | render-bound rate %.1f frames/s "
               "(1 / median render+readback); %.0f %% of it (target >= 95 %% when pipelined) |\n",
               npath, depth, fps, bound, 100 * fps / bound);
    }
    (void)render_bound;
    free(e2e); free(srv); free(dec); free(ovh); free(rr);
    spc_close(c);
    return 0;
}
