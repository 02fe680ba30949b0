/* ws_bench.c — the browser listener's cost against plain TCP, on a running splatd.
 *
 *   ws_bench --port P --http-port H --cloud NAME [--size WxH] [--pipeline P] [--frames N]
 *            [--framing 0|1] [--page N]
 *
 * 1. Latency: N cameras of an orbit (default 40), each sent as CAMERA + RENDER on a TCP
 *    connection and, alternately, on a WebSocket connection (/ws, the browser's transport), the
 *    time until the FRAME message is fully received (not decoded); the two connections render
 *    the same cameras, interleaved so that both see the same load. Medians, and each minus the
 *    frame's own render + read-back + encode time.
 * 2. (--framing 1, the default) Framing cost per frame, in process: the bytes WebSocket
 *    framing adds (server frame header, client header + mask of each request), ws_decode of
 *    a masked CAMERA message and the server's frame header + first-4-KiB staging (ws_conn.c),
 *    in ns.
 * 3. (--page N) The page itself in headless Chromium (chromedriver; skipped with a line when
 *    absent): N single mouse drags 0.6 s apart on the canvas of WxH; for every frame the page
 *    drew, its camera sent -> frame received and -> drawn (window.splatStats), then the same
 *    cameras at the same sizes again over TCP and over the C WebSocket client. Medians.
 * Output: Markdown table rows on stdout. */
#include <arpa/inet.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "framing.h"
#include "params.h"
#include "proto.h"
#include "testutil.h"
#include "webdriver.h"
#include "ws.h"
#include "wsclient.h"

/* One connection: TCP (fd) or WebSocket (ws), the same calls for both. */
typedef struct conn {
    int is_ws;
    int fd;
    tu_ws ws;
    uint8_t *msg;              /* the last message received (TCP: malloc'd here) */
    size_t cap;
    uint32_t seq;
} conn;

static int c_send(conn *c, proto_buf *b)
{
    int rc = c->is_ws ? tu_ws_send(&c->ws, WS_OP_BINARY, b->data, b->len)
                      : tu_send_all(c->fd, b->data, b->len);
    proto_buf_free(b);
    return rc;
}

/* c_recv: the next protocol message; header in *h, payload at the returned pointer. */
static const uint8_t *c_recv(conn *c, proto_header *h)
{
    if (c->is_ws) {
        if (tu_ws_recv(&c->ws, 60000) != WS_EV_END || c->ws.msg_len < PROTO_HEADER_LEN) return NULL;
        proto_get_header(c->ws.msg, h);
        return c->ws.msg + PROTO_HEADER_LEN;
    }
    uint8_t hd[PROTO_HEADER_LEN];
    if (tu_recv_all(c->fd, hd, sizeof hd) != 0) return NULL;
    proto_get_header(hd, h);
    if (h->len > c->cap) {
        free(c->msg);
        c->cap = h->len;
        c->msg = malloc(c->cap);
        if (!c->msg) return NULL;
    }
    if (h->len && tu_recv_all(c->fd, c->msg, h->len) != 0) return NULL;
    return c->msg;
}

/* c_expect: waits for the answer of type to seq (skipping PROGRESS). */
static const uint8_t *c_expect(conn *c, unsigned type, uint32_t seq, proto_header *h)
{
    for (;;) {
        const uint8_t *p = c_recv(c, h);
        if (!p) return NULL;
        if (h->type == PROTO_MSG_PROGRESS) continue;
        if (h->type == type && h->seq == seq) return p;
        if (h->type == PROTO_MSG_ERROR) {
            proto_errmsg em;
            proto_error e;
            if (proto_parse_error(p, h->len, &em, &e) == 0)
                fprintf(stderr, "ws_bench: ERROR %u: %s\n", em.code, em.text);
            return NULL;
        }
    }
}

static int tcp_connect(int port)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd < 0 || connect(fd, (struct sockaddr *)&a, sizeof a) != 0) return -1;
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return fd;
}

/* c_open: HELLO, OPEN cloud, PARAMS pipeline; the cloud's info into *info. 0 or -1. */
static int c_open(conn *c, const char *cloud, const char *pipeline, proto_info *info)
{
    proto_buf b = {0};
    proto_hello hm = {.min_version = 1, .max_version = 1};
    snprintf(hm.client, sizeof hm.client, "ws_bench");
    proto_header h;
    proto_error e;
    const uint8_t *p;
    proto_enc_hello(&b, ++c->seq, &hm);
    if (c_send(c, &b) || !c_expect(c, PROTO_MSG_WELCOME, c->seq, &h)) return -1;
    proto_enc_open(&b, ++c->seq, cloud);
    if (c_send(c, &b) || !(p = c_expect(c, PROTO_MSG_INFO, c->seq, &h)) ||
        proto_parse_info(p, h.len, info, &e) != 0)
        return -1;
    sp_params sp;
    sp_params_defaults(&sp);
    if (sp_param_set_text(&sp, "pipeline", pipeline, NULL, 0) != 0) return -1;
    proto_param_rec r;
    proto_param_rec_from(&sp, SP_PIPELINE, &r);
    proto_enc_params(&b, ++c->seq, &r, 1);
    if (c_send(c, &b) || !c_expect(c, PROTO_MSG_OK, c->seq, &h)) return -1;
    return 0;
}

/* c_quality: PARAMS quality q, waiting for its OK. 0 or -1. */
static int c_quality(conn *c, int q)
{
    sp_params sp;
    sp_params_defaults(&sp);
    sp.quality = q;
    proto_param_rec r;
    proto_param_rec_from(&sp, SP_QUALITY, &r);
    proto_buf b = {0};
    proto_header h;
    proto_enc_params(&b, ++c->seq, &r, 1);
    return c_send(c, &b) || !c_expect(c, PROTO_MSG_OK, c->seq, &h) ? -1 : 0;
}

/* c_frame: CAMERA cam + RENDER; the latency until the FRAME is in (us) and the frame's
 * render + read-back + encode time (us) in *work and its bytes in *bytes. 0 or -1. */
static int c_frame(conn *c, const proto_camera *cam, double *lat, double *work, size_t *bytes)
{
    proto_buf b = {0};
    proto_header h;
    proto_error e;
    double t0 = tu_now_us();
    proto_enc_camera(&b, ++c->seq, cam);
    if (c_send(c, &b)) return -1;
    proto_enc_empty(&b, PROTO_MSG_RENDER, ++c->seq);
    if (c_send(c, &b)) return -1;
    const uint8_t *p = c_expect(c, PROTO_MSG_FRAME, c->seq, &h);
    *lat = tu_now_us() - t0;
    proto_frame fr;
    if (!p || proto_parse_frame(p, h.len, &fr, &e) != 0) return -1;
    *work = (double)(fr.render_us + fr.readback_us + fr.encode_us);
    *bytes = PROTO_HEADER_LEN + h.len;
    return 0;
}

/* framing_cost: in-process ns per frame of the server's WebSocket work (see the header). */
static void framing_cost(size_t frame_bytes)
{
    /* A masked CAMERA message, as the page sends it. */
    proto_buf b = {0};
    proto_camera cam = {.eye = {1, 2, 3}, .up = {0, 0, 1}, .fov_deg = 45, .width = 1280,
                        .height = 720};
    proto_enc_camera(&b, 7, &cam);
    uint8_t f[WS_MAX_HEADER + 256], out[256], stage[WS_MAX_HEADER + 4096];
    const uint8_t mask[4] = {9, 8, 7, 6};
    size_t hl = ws_frame_header(f, 1, WS_OP_BINARY, b.len, mask);
    memcpy(f + hl, b.data, b.len);
    ws_mask(f + hl, b.len, mask, 0);
    const int n = 2000000;
    volatile size_t sink = 0;
    double t0 = tu_now_us();
    for (int i = 0; i < n; i++) {
        ws_decoder d = {.require_mask = 1, .binary_only = 1, .max_message = 65552};
        ws_event ev;
        size_t used, prod;
        ws_decode(&d, f, hl + b.len, &used, out, sizeof out, &prod, &ev);
        sink += prod;
    }
    double dec_ns = (tu_now_us() - t0) * 1e3 / n;
    uint8_t *payload = calloc(1, frame_bytes);
    t0 = tu_now_us();
    for (int i = 0; i < n; i++) {
        size_t h = ws_frame_header(stage, 1, WS_OP_BINARY, frame_bytes, NULL);
        size_t k = frame_bytes < 4096 ? frame_bytes : 4096;
        memcpy(stage + h, payload, k);
        sink += h + stage[h + (size_t)i % k];
    }
    double enc_ns = (tu_now_us() - t0) * 1e3 / n;
    (void)sink;
    free(payload);
    printf("| WebSocket bytes per frame | %d + %d | server frame header (10 for a frame of 64 "
           "KiB or more, 4 below) + client header and mask of CAMERA and RENDER (2 x 6) |\n",
           frame_bytes >= 65536 ? 10 : 4, 12);
    printf("| ws_decode of a masked CAMERA (%zu B) | %.0f ns | unmasking into the session's input, "
           "in process |\n", b.len, dec_ns);
    printf("| frame header + 4 KiB staging | %.0f ns | per FRAME sent (the rest of the frame goes "
           "straight from the session's buffer) |\n", enc_ns);
    proto_buf_free(&b);
}

/* page_cams: one camera of the page's statistics. */
typedef struct page_cam {
    proto_camera cam;
    int quality;
    double recv_ms, drawn_ms, work_ms;
} page_cam;

/* page_run: the page in Chromium on the http port, nd single drags; fills up to cap cameras.
 * Returns their number, or -1 (a line on stdout says why). */
static int page_run(int hport, const char *cloud, const char *pipeline, int w, int h, int nd,
                    page_cam *pc, int cap)
{
    char why[300], dir[512], url[512], v[256], id[160];
    if (!tu_wd_available(why, sizeof why)) {
        printf("| browser page | skipped | %s |\n", why);
        return -1;
    }
    if (!tu_tmpdir(dir, sizeof dir)) return -1;
    tu_wd wd;
    if (tu_wd_start(&wd, dir, w + 100, h + 200, why, sizeof why) != 0) {
        printf("| browser page | failed | %s |\n", why);
        return -1;
    }
    snprintf(url, sizeof url, "http://127.0.0.1:%d/?cloud=%s&size=%dx%d&pipeline=%s", hport, cloud,
             w, h, pipeline);
    int n = -1;
    char *stats = NULL;
    if (tu_wd_go(&wd, url) != 0 || tu_wd_element(&wd, "#canvas", id, sizeof id) != 0) goto out;
    for (int d = -1; d < nd; d++) {
        if (d >= 0) {
            char act[1024];
            snprintf(act, sizeof act,
                     "{\"actions\":[{\"type\":\"pointer\",\"id\":\"m\",\"parameters\":"
                     "{\"pointerType\":\"mouse\"},\"actions\":[{\"type\":\"pointerMove\","
                     "\"duration\":0,\"origin\":"
                     "{\"element-6066-11e4-a52e-4f735466cecf\":\"%s\"},\"x\":0,\"y\":0},"
                     "{\"type\":\"pointerDown\",\"button\":0},{\"type\":\"pointerMove\","
                     "\"duration\":0,\"origin\":\"pointer\",\"x\":12,\"y\":0},"
                     "{\"type\":\"pointerUp\",\"button\":0}]}]}", id);
            if (tu_wd_post(&wd, "actions", act) != 0) goto out;
            usleep(600000);
        }
        /* Rest: nothing due or in flight (the page's #idle), at most 30 s. */
        for (int k = 0; k < 1500; k++) {
            if (tu_wd_eval(&wd, "return document.getElementById('idle').textContent", v,
                           sizeof v) == 0 && !strcmp(v, "1"))
                break;
            usleep(20000);
        }
    }
    stats = malloc(1 << 20);
    if (!stats || tu_wd_eval(&wd, "return window.splatStats()", stats, 1 << 20) != 0) goto out;
    n = 0;
    for (char *line = strtok(stats, "\n"); line && n < cap; line = strtok(NULL, "\n")) {
        page_cam *c = &pc[n];
        memset(c, 0, sizeof *c);
        double fov;
        if (sscanf(line, "%u %u %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %d %lf %lf %lf",
                   &c->cam.width, &c->cam.height, &c->cam.eye[0], &c->cam.eye[1], &c->cam.eye[2],
                   &c->cam.target[0], &c->cam.target[1], &c->cam.target[2], &c->cam.up[0],
                   &c->cam.up[1], &c->cam.up[2], &fov, &c->quality, &c->recv_ms, &c->drawn_ms,
                   &c->work_ms) != 16)
            continue;
        c->cam.fov_deg = (float)fov;
        n++;
    }
out:
    free(stats);
    tu_wd_stop(&wd);
    tu_rm_rf(dir);
    if (n < 0) printf("| browser page | failed | see the chromedriver log |\n");
    return n;
}

/* page_compare: the page's frames against the same cameras over TCP and the C WebSocket. */
static int page_compare(conn *tcp, conn *ws, const page_cam *pc, int n, int w, int h)
{
    double *a = calloc((size_t)n, sizeof *a), *b = calloc((size_t)n, sizeof *b);
    double *t = calloc((size_t)n, sizeof *t), *u = calloc((size_t)n, sizeof *u);
    double *k = calloc((size_t)n, sizeof *k), *q = calloc((size_t)n, sizeof *q);
    double *oa = calloc((size_t)n, sizeof *oa), *ot = calloc((size_t)n, sizeof *ot);
    double *ou = calloc((size_t)n, sizeof *ou);
    size_t bytes;
    int full = 0;
    int quality = -1;
    for (int i = 0; i < n; i++) {
        double lt, lw, wt, ww;
        /* The page's JPEG quality for that frame (50 dragging, 95 at rest), set untimed. */
        if (pc[i].quality != quality && pc[i].quality > 0) {
            quality = pc[i].quality;
            if (c_quality(tcp, quality) || c_quality(ws, quality)) return -1;
        }
        if (c_frame(tcp, &pc[i].cam, &lt, &wt, &bytes) || c_frame(ws, &pc[i].cam, &lw, &ww, &bytes))
            return -1;
        a[i] = pc[i].recv_ms;
        b[i] = pc[i].drawn_ms;
        k[i] = pc[i].work_ms;
        t[i] = lt / 1e3;
        u[i] = lw / 1e3;
        q[i] = 0.5 * (wt + ww) / 1e3;
        oa[i] = pc[i].recv_ms - pc[i].work_ms; /* what is not the server's render + encode */
        ot[i] = (lt - wt) / 1e3;
        ou[i] = (lw - ww) / 1e3;
        full += pc[i].cam.width == (uint32_t)w;
    }
    printf("| page: camera sent -> frame received (%dx%d at rest, half while dragging) | %.2f ms | "
           "median of %d frames (%d full size); minus each frame's render + read-back + encode: "
           "%.2f ms |\n", w, h, tu_median(a, n), n, full, tu_median(oa, n));
    printf("| page: camera sent -> frame drawn | %.2f ms | + createImageBitmap and drawImage |\n",
           tu_median(b, n));
    printf("| same cameras and JPEG quality, C client over TCP | %.2f ms | minus render + "
           "read-back + encode: %.2f ms |\n", tu_median(t, n), tu_median(ot, n));
    printf("| same cameras and JPEG quality, C client over WebSocket | %.2f ms | minus render + "
           "read-back + encode: %.2f ms (render + read-back + encode of both: %.2f ms; the page's: "
           "%.2f ms) |\n", tu_median(u, n), tu_median(ou, n), tu_median(q, n), tu_median(k, n));
    free(a); free(b); free(t); free(u); free(k); free(q); free(oa); free(ot); free(ou);
    return 0;
}

int main(int argc, char **argv)
{
    int port = 0, hport = 0, w = 1280, h = 720, n = 40, framing = 1, page = 0;
    const char *cloud = "Guanyin", *pipeline = "points";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--port")) port = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--http-port")) hport = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--cloud")) cloud = argv[i + 1];
        else if (!strcmp(argv[i], "--size")) sscanf(argv[i + 1], "%dx%d", &w, &h);
        else if (!strcmp(argv[i], "--pipeline")) pipeline = argv[i + 1];
        else if (!strcmp(argv[i], "--frames")) n = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--framing")) framing = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--page")) page = atoi(argv[i + 1]);
        else { fprintf(stderr, "ws_bench: unknown option %s\n", argv[i]); return 2; }
    }
    if (port <= 0 || hport <= 0 || n < 2 || n > 10000) {
        fprintf(stderr, "ws_bench: --port and --http-port are required; --frames 2..10000\n");
        return 2;
    }
    conn tcp = {.fd = tcp_connect(port)}, ws = {.is_ws = 1};
    char resp[2048];
    if (tcp.fd < 0 || tu_ws_open(&ws.ws, hport, NULL, NULL, resp, sizeof resp) != 0) {
        fprintf(stderr, "ws_bench: cannot connect (TCP %d, WebSocket %d)\n", port, hport);
        return 1;
    }
    proto_info info;
    if (c_open(&tcp, cloud, pipeline, &info) != 0 || c_open(&ws, cloud, pipeline, &info) != 0) {
        fprintf(stderr, "ws_bench: opening %s failed\n", cloud);
        return 1;
    }
    if (page > 0) {
        /* The page first (its own connection), then its cameras again on ours. */
        static page_cam pc[4096];
        int np = page_run(hport, cloud, pipeline, w, h, page, pc, 4096);
        int rc = np > 0 ? page_compare(&tcp, &ws, pc, np, w, h) : 0;
        close(tcp.fd);
        tu_ws_close(&ws.ws);
        free(tcp.msg);
        return rc == 0 ? 0 : 1;
    }
    double *lt = calloc((size_t)n, sizeof *lt), *lw = calloc((size_t)n, sizeof *lw);
    double *ot = calloc((size_t)n, sizeof *ot), *ow = calloc((size_t)n, sizeof *ow);
    double *wk = calloc((size_t)n, sizeof *wk);
    size_t bytes = 0;
    /* A warm-up frame each, then the orbit; TCP first on even steps, WebSocket first on odd. */
    for (int i = -1; i < n; i++) {
        proto_camera cam = {.fov_deg = 45, .width = (uint32_t)w, .height = (uint32_t)h};
        sp_frame_orbit(&info.view, NULL, i < 0 ? 0 : i, n, w, h, 45, cam.eye,
                       cam.target, cam.up);
        double a, b, wa, wb;
        conn *first = (i & 1) ? &ws : &tcp, *second = (i & 1) ? &tcp : &ws;
        if (c_frame(first, &cam, &a, &wa, &bytes) != 0 ||
            c_frame(second, &cam, &b, &wb, &bytes) != 0) {
            fprintf(stderr, "ws_bench: frame %d failed\n", i);
            return 1;
        }
        if (i < 0) continue;
        double at = first == &tcp ? a : b, aw = first == &tcp ? b : a;
        double wt = first == &tcp ? wa : wb, ww = first == &tcp ? wb : wa;
        lt[i] = at / 1e3;
        lw[i] = aw / 1e3;
        ot[i] = (at - wt) / 1e3;
        ow[i] = (aw - ww) / 1e3;
        wk[i] = 0.5 * (wt + ww) / 1e3;
    }
    double mt = tu_median(lt, n), mw = tu_median(lw, n), mot = tu_median(ot, n), mow = tu_median(ow, n);
    printf("| camera -> frame received, TCP (%s, %dx%d) | %.2f ms | median of %d; minus the "
           "frame's render + read-back + encode: %.2f ms |\n", pipeline, w, h, mt, n, mot);
    printf("| camera -> frame received, WebSocket | %.2f ms | the same cameras interleaved; minus "
           "render + read-back + encode: %.2f ms, %+.2f ms against TCP (%zu B frames, render + "
           "read-back + encode median %.2f ms) |\n", mw, mow, mow - mot, bytes, tu_median(wk, n));
    if (framing) framing_cost(bytes);
    proto_buf b = {0};
    proto_enc_empty(&b, PROTO_MSG_BYE, ++tcp.seq);
    c_send(&tcp, &b);
    close(tcp.fd);
    tu_ws_close(&ws.ws);
    free(tcp.msg);
    free(lt); free(lw); free(ot); free(ow); free(wk);
    return 0;
}
