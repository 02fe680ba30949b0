/* tls_bench.c — what TLS costs per frame: two running splatd, one plaintext and one TLS, the
 * same cloud, the same requests, measured alternately in rounds so that load from elsewhere
 * falls on both alike.
 *
 *   tls_bench --make-cert DIR         writes DIR/bench.crt and DIR/bench.key (IP 127.0.0.1)
 *   tls_bench --plain P --tls Q --ca FILE --cloud NAME [--rounds R] [--frames N]
 *             [--pids PLAIN_PID,TLS_PID]
 *
 * Rows (Markdown): connection set-up (connect + HELLO, and TLS's handshake); PING round trip;
 * per frame format and size: the overhead of one frame at a time (end-to-end time minus the
 * server's render, read-back and encode times, so the renderer's own time, which TLS does not
 * change, is left out) and the throughput of a path with 4 frames in flight (frames/s and MB/s
 * of frame bytes). Each figure is the median over rounds of per-round medians. With --pids,
 * also the daemons' resident memory per idle connection (24 connected clients each). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "splat_client.h"
#include "testutil.h"
#include "tlscert.h"

enum { MAXR = 16, MAXN = 200 };

static double now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e6 + (double)ts.tv_nsec * 1e-3;
}

typedef struct bench {
    int port[2];                  /* 0: plaintext, 1: TLS */
    int pid[2];                   /* the daemons, for their memory; 0: not measured */
    const char *ca, *cloud;
    int rounds, frames;
} bench;

static spc_client *conn(const bench *b, int tls)
{
    spc_options o = {.port = b->port[tls], .client_name = "tls_bench", .tls_ca = tls ? b->ca : NULL};
    spc_client *c = NULL;
    char err[1024];
    if (spc_connect(&o, &c, err, sizeof err) != 0) {
        fprintf(stderr, "tls_bench: %s\n", err);
        exit(1);
    }
    return c;
}

static void die(spc_client *c, const char *what)
{
    fprintf(stderr, "tls_bench: %s: %s\n", what, spc_errmsg(c));
    exit(1);
}

/* one_round: for one transport, the median connect time, PING, frame overhead and path
 * throughput (frames/s, MB/s) of format fmt at w x h into out[0..4]. */
static void one_round(const bench *b, int tls, const char *fmt, int w, int h, double out[5])
{
    double v[MAXN];
    int n = b->frames;
    for (int i = 0; i < n; i++) {
        double t0 = now_us();
        spc_client *c = conn(b, tls);
        v[i] = now_us() - t0;
        spc_close(c);
    }
    out[0] = tu_median(v, n);
    spc_client *c = conn(b, tls);
    for (int i = 0; i < n; i++) {
        uint64_t rtt = 0;
        if (spc_ping(c, &rtt) < 0) die(c, "ping");
        v[i] = (double)rtt;
    }
    out[1] = tu_median(v, n);
    spc_info info;
    if (spc_open(c, b->cloud, &info, NULL, NULL) < 0) die(c, "open");
    char kv[32];
    snprintf(kv, sizeof kv, "format=%s", fmt);
    const char *kvs[2] = {"pipeline=points", kv};
    if (spc_set_params(c, kvs, 2) < 0) die(c, "params");
    spc_camera cam;
    spc_frame f;
    for (int i = 0; i < 3; i++) { /* warm-up at this size */
        spc_camera_orbit(&info, NULL, i, n, 45, (uint32_t)w, (uint32_t)h, &cam);
        if (spc_send_render(c, &cam, NULL) < 0 || spc_recv_frame(c, &f, 0) < 0) die(c, "warm-up");
    }
    for (int i = 0; i < n; i++) {
        spc_camera_orbit(&info, NULL, i, n, 45, (uint32_t)w, (uint32_t)h, &cam);
        double t0 = now_us();
        if (spc_send_render(c, &cam, NULL) < 0 || spc_recv_frame(c, &f, 0) < 0) die(c, "render");
        v[i] = now_us() - t0 - (double)(f.render_us + f.readback_us + f.encode_us);
    }
    out[2] = tu_median(v, n);
    int sent = 0, got = 0;
    double bytes = 0, t0 = now_us();
    while (got < n) {
        while (sent < n && sent - got < 4) {
            spc_camera_orbit(&info, NULL, sent, n, 45, (uint32_t)w, (uint32_t)h, &cam);
            if (spc_send_render(c, &cam, NULL) < 0) die(c, "send");
            sent++;
        }
        if (spc_recv_frame(c, &f, 0) < 0) die(c, "receive");
        bytes += (double)f.data_len;
        got++;
    }
    double secs = (now_us() - t0) / 1e6;
    out[3] = n / secs;
    out[4] = bytes / secs / 1e6;
    spc_close(c);
}

/* rss_kb: VmRSS of process pid in KiB, or -1. */
static long rss_kb(int pid)
{
    char path[64], line[256];
    snprintf(path, sizeof path, "/proc/%d/status", pid);
    FILE *f = fopen(path, "r");
    if (!f) return -1;
    long kb = -1;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "VmRSS: %ld", &kb) == 1) break;
    fclose(f);
    return kb;
}

/* idle_cost: the daemon's resident KiB per connected, idle client (24 of them, after HELLO). */
static double idle_cost(const bench *b, int tls)
{
    enum { N = 24 }; /* under --max-per-addr (32) */
    spc_client *c[N];
    c[0] = conn(b, tls); /* warm-up: the first connection's one-time allocations */
    spc_close(c[0]);
    usleep(200000);
    long before = rss_kb(b->pid[tls]);
    for (int i = 0; i < N; i++) c[i] = conn(b, tls);
    usleep(200000);
    long after = rss_kb(b->pid[tls]);
    for (int i = 0; i < N; i++) spc_close(c[i]);
    return (double)(after - before) / N;
}

int main(int argc, char **argv)
{
    if (argc == 3 && !strcmp(argv[1], "--make-cert")) {
        char cert[1024], key[1024];
        if (tu_make_cert(argv[2], "bench", "tls-bench", "127.0.0.1", "localhost", cert, key,
                         sizeof cert) != 0) {
            fprintf(stderr, "tls_bench: cannot write a certificate in %s\n", argv[2]);
            return 1;
        }
        return 0;
    }
    bench b = {.cloud = "bunny", .rounds = 3, .frames = 15};
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--plain")) b.port[0] = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--tls")) b.port[1] = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--ca")) b.ca = argv[i + 1];
        else if (!strcmp(argv[i], "--cloud")) b.cloud = argv[i + 1];
        else if (!strcmp(argv[i], "--rounds")) b.rounds = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--frames")) b.frames = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--pids")) sscanf(argv[i + 1], "%d,%d", &b.pid[0], &b.pid[1]);
        else { fprintf(stderr, "tls_bench: unknown option %s\n", argv[i]); return 2; }
    }
    if (!b.port[0] || !b.port[1] || !b.ca || b.rounds < 1 || b.rounds > MAXR || b.frames < 3 ||
        b.frames > MAXN) {
        fprintf(stderr, "tls_bench: --plain P --tls Q --ca FILE needed; --rounds 1..%d, "
                "--frames 3..%d\n", MAXR, MAXN);
        return 2;
    }
    static const struct { const char *fmt; int w, h; } cases[] = {
        {"jpeg", 1280, 720}, {"raw", 320, 240}, {"raw", 1280, 720}, {"raw", 1920, 1080},
    };
    int ncases = (int)(sizeof cases / sizeof cases[0]);
    double r[4][2][5][MAXR]; /* case, transport, measure, round */
    for (int k = 0; k < ncases; k++)
        for (int round = 0; round < b.rounds; round++)
            for (int t = 0; t < 2; t++) {
                int tls = (round & 1) ? !t : t; /* alternate which goes first */
                double out[5];
                one_round(&b, tls, cases[k].fmt, cases[k].w, cases[k].h, out);
                for (int m = 0; m < 5; m++) r[k][tls][m][round] = out[m];
            }
    double m[4][2][5];
    for (int k = 0; k < ncases; k++)
        for (int t = 0; t < 2; t++)
            for (int q = 0; q < 5; q++) m[k][t][q] = tu_median(r[k][t][q], b.rounds);
    /* connect and PING do not depend on the case: medians over all of them */
    double cv[2][4 * MAXR], pv[2][4 * MAXR];
    for (int t = 0; t < 2; t++)
        for (int k = 0; k < ncases; k++)
            for (int round = 0; round < b.rounds; round++) {
                cv[t][k * b.rounds + round] = r[k][t][0][round];
                pv[t][k * b.rounds + round] = r[k][t][1][round];
            }
    double c0 = tu_median(cv[0], ncases * b.rounds), c1 = tu_median(cv[1], ncases * b.rounds);
    double p0 = tu_median(pv[0], ncases * b.rounds), p1 = tu_median(pv[1], ncases * b.rounds);
    printf("| measure | plaintext | TLS | TLS cost |\n|---|---|---|---|\n");
    printf("| connect + HELLO (TLS: + handshake, ECDSA P-256) | %.2f ms | %.2f ms | +%.2f ms |\n",
           c0 / 1000, c1 / 1000, (c1 - c0) / 1000);
    printf("| PING round trip | %.0f us | %.0f us | %+.0f us |\n", p0, p1, p1 - p0);
    for (int k = 0; k < ncases; k++) {
        const double *a = m[k][0], *t = m[k][1];
        printf("| %dx%d %s, one frame at a time: time beyond render+read-back+encode | %.2f ms | "
               "%.2f ms | %+.2f ms |\n", cases[k].w, cases[k].h, cases[k].fmt, a[2] / 1000,
               t[2] / 1000, (t[2] - a[2]) / 1000);
        printf("| %dx%d %s, path of %d frames, 4 in flight | %.1f frames/s, %.0f MB/s | %.1f "
               "frames/s, %.0f MB/s | %.0f %% of plaintext's rate |\n", cases[k].w, cases[k].h,
               cases[k].fmt, b.frames, a[3], a[4], t[3], t[4], 100 * t[3] / a[3]);
    }
    if (b.pid[0] > 0 && b.pid[1] > 0) {
        double m0 = idle_cost(&b, 0), m1 = idle_cost(&b, 1);
        printf("| daemon memory per idle connected client (24 of them) | %.0f KiB | %.0f KiB | "
               "%+.0f KiB |\n", m0, m1, m1 - m0);
    }
    printf("\n(medians of %d alternating rounds of %d frames each; pipeline points, "
           "cloud %s)\n", b.rounds, b.frames, b.cloud);
    return 0;
}
