/* enc_bench.c — frame encoder and decoder times at 1280x720 (median of 20 runs after 2 warm-up
 * runs), printed as Markdown table rows for `make bench` (tests/bench/bench_encode.sh).
 *
 * The frame imitates a rendered scan: a flat background on 35% of the image, and an object of
 * smoothly shaded surfaces carrying per-pixel colour noise of +-12 levels (scan texture), the
 * same in the half-float colour; depth is smooth on the object and +inf on the background.
 * Compression ratios depend on content: a real scan frame will differ.
 * usage: enc_bench [width height [runs]] */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "encode.h"
#include "frame_decode.h"
#include "half.h"

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* hash_noise: deterministic per-pixel value in [-1, 1]. */
static float hash_noise(uint32_t x, uint32_t y)
{
    uint32_t h = x * 374761393u + y * 668265263u;
    h = (h ^ (h >> 13)) * 1274126177u;
    return (float)((h ^ (h >> 16)) & 0xffff) / 32767.5f - 1.0f;
}

static rnd_frame make_scene(int w, int h)
{
    rnd_frame f = { .width = w, .height = h };
    f.rgba8 = malloc((size_t)w * h * 4);
    f.rgba16f = malloc((size_t)w * h * 8);
    f.depth = malloc((size_t)w * h * 4);
    if (!f.rgba8 || !f.rgba16f || !f.depth) {
        fprintf(stderr, "enc_bench: out of memory\n");
        exit(1);
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            float u = (x - 0.5f * w) / (0.42f * w), v = (y - 0.45f * h) / (0.45f * h);
            float r2 = u * u + v * v, c[3] = { 0.08f, 0.09f, 0.11f }, z = INFINITY;
            if (r2 < 1.0f) {
                float nz = sqrtf(1.0f - r2);
                float shade = 0.25f + 0.75f * (0.3f * u + 0.5f * v + 0.8f * nz);
                float n = hash_noise((uint32_t)x, (uint32_t)y) * 12.0f / 255.0f;
                float band = 0.1f * sinf(0.05f * (float)x + 0.03f * (float)y);
                c[0] = shade * (0.62f + band) + n;
                c[1] = shade * 0.55f + n;
                c[2] = shade * (0.45f - band) + n;
                z = 10.0f - 3.0f * nz;
            }
            for (int k = 0; k < 3; k++) {
                float s = c[k] < 0 ? 0 : c[k] > 1 ? 1 : c[k];
                f.rgba8[i * 4 + k] = (uint8_t)lrintf(s * 255.0f);
                f.rgba16f[i * 4 + k] = half_from_float(c[k]);
            }
            f.rgba8[i * 4 + 3] = 255;
            f.rgba16f[i * 4 + 3] = half_from_float(1.0f);
            f.depth[i] = z;
        }
    return f;
}

typedef struct { double median, min; size_t bytes; } result;

/* run_encode: times enc_encode with params p over runs; exits on error. */
static result run_encode(enc_ctx *e, const rnd_frame *f, const sp_params *p, int runs)
{
    double t[256];
    result r = { 0, 0, 0 };
    sd_err err = { 0 };
    for (int i = -2; i < runs; i++) {
        const uint8_t *out;
        size_t len;
        double t0 = now_ms();
        if (enc_encode(e, f, p, &out, &len, &err) != 0) {
            fprintf(stderr, "enc_bench: %s\n", err.msg);
            exit(1);
        }
        if (i >= 0) t[i] = now_ms() - t0;
        r.bytes = len;
    }
    qsort(t, (size_t)runs, sizeof t[0], cmp_double);
    r.median = t[runs / 2];
    r.min = t[0];
    return r;
}

/* run_decode: times fd_decode of one encoded frame (copied, since e's buffer is reused). */
static result run_decode(fd_ctx *d, enc_ctx *e, const rnd_frame *f, const sp_params *p, int runs)
{
    double t[256];
    result r = { 0, 0, 0 };
    sd_err err = { 0 };
    const uint8_t *out;
    size_t len;
    if (enc_encode(e, f, p, &out, &len, &err) != 0) {
        fprintf(stderr, "enc_bench: %s\n", err.msg);
        exit(1);
    }
    uint8_t *copy = malloc(len);
    if (!copy) exit(1);
    memcpy(copy, out, len);
    for (int i = -2; i < runs; i++) {
        const uint8_t *rgba;
        char msg[256];
        double t0 = now_ms();
        if (fd_decode(d, p->format, copy, len, f->width, f->height, &rgba, NULL, NULL, msg,
                      sizeof msg) != 0) {
            fprintf(stderr, "enc_bench: %s\n", msg);
            exit(1);
        }
        if (i >= 0) t[i] = now_ms() - t0;
    }
    free(copy);
    qsort(t, (size_t)runs, sizeof t[0], cmp_double);
    r.median = t[runs / 2];
    r.min = t[0];
    r.bytes = len;
    return r;
}

static void row(const char *what, result r, size_t raw, const char *note)
{
    printf("| %s | %.2f | %.2f | %.0f | %.2f | %s |\n", what, r.median, r.min, r.bytes / 1024.0,
           (double)raw / (double)r.bytes, note);
}

int main(int argc, char **argv)
{
    int w = argc > 2 ? atoi(argv[1]) : 1280, h = argc > 2 ? atoi(argv[2]) : 720;
    int runs = argc > 3 ? atoi(argv[3]) : 20;
    if (w < 1 || h < 1 || w > ENC_MAX_DIM || h > ENC_MAX_DIM || runs < 1 || runs > 256) {
        fprintf(stderr, "usage: enc_bench [width height [runs 1-256]]\n");
        return 2;
    }
    rnd_frame f = make_scene(w, h);
    sd_err err = { 0 };
    char msg[256];
    enc_ctx *e = enc_create(&err);
    fd_ctx *d = fd_create(msg, sizeof msg);
    if (!e || !d) { fprintf(stderr, "enc_bench: %s%s\n", err.msg, msg); return 1; }
    size_t raw8 = (size_t)w * h * 4, rawf = (size_t)w * h * 12;

    printf("### Frame encoders, %dx%d synthetic scan-like frame, median of %d\n\n", w, h, runs);
    printf("| step | median ms | min ms | KiB | ratio | note |\n");
    printf("|---|---:|---:|---:|---:|---|\n");
    sp_params p;
    sp_params_defaults(&p);
    p.format = SP_FMT_JPEG;
    p.quality = 85;
    p.subsampling = SP_SUB_420;
    row("JPEG q85 4:2:0 encode", run_encode(e, &f, &p, runs), raw8, "TurboJPEG, BOTTOMUP");
    row("JPEG q85 4:2:0 decode", run_decode(d, e, &f, &p, runs), raw8, "client fd_decode");
    p.quality = 90;
    p.subsampling = SP_SUB_444;
    row("JPEG q90 4:4:4 encode", run_encode(e, &f, &p, runs), raw8, "");
    p.format = SP_FMT_PNG;
    row("PNG encode", run_encode(e, &f, &p, runs), raw8, "libpng, zlib level 1");
    p.format = SP_FMT_LZ4;
    row("LZ4 encode", run_encode(e, &f, &p, runs), raw8, "SPL4, incl. row flip");
    row("LZ4 decode", run_decode(d, e, &f, &p, runs), raw8, "client fd_decode");
    p.format = SP_FMT_RAW;
    row("raw encode", run_encode(e, &f, &p, runs), raw8, "row flip only");
    p.format = SP_FMT_EXR;
    row("EXR PIZ encode", run_encode(e, &f, &p, runs), rawf, "half RGBA + float Z");
    enc_set_exr_compression(e, ENC_EXR_ZIP, NULL);
    row("EXR ZIP encode", run_encode(e, &f, &p, runs), rawf, "half RGBA + float Z");
    enc_set_exr_compression(e, ENC_EXR_RLE, NULL);
    row("EXR RLE encode", run_encode(e, &f, &p, runs), rawf, "half RGBA + float Z");
    enc_set_exr_compression(e, ENC_EXR_NONE, NULL);
    row("EXR uncompressed encode", run_encode(e, &f, &p, runs), rawf, "half RGBA + float Z");

    fd_destroy(d);
    enc_destroy(e);
    free(f.rgba8);
    free(f.rgba16f);
    free(f.depth);
    return 0;
}
