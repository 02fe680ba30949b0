/* test_encode.c — frame encoders (server/encode.h) and the client's frame decoder
 * (client/frame_decode.h): each format is decoded by an independent library (TurboJPEG,
 * libpng, OpenEXR's reader) and compared with the source frame; row order, atomic file
 * output, buffer reuse and the rejection of damaged LZ4 frames. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <math.h>
#include <openexr.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <turbojpeg.h>

#include "encode.h"
#include "frame_decode.h"
#include "frame_lz4.h"
#include "half.h"
#include "common/testutil.h"
#include "testutil.h"

/* ---- synthetic frames ---- */

/* make_frame: a w x h frame, rows bottom-up like GL's. Top-down row t = h-1-y has a smooth
 * gradient (R along x, G down the image), B = 128 plus a 32-pixel checkerboard of +-40 (sharp
 * edges, which JPEG handles worst), alpha = (x ^ t) & 255. The bottom GL row (y = 0, the
 * image's last row) is pure red and the top GL row pure blue, to check the row order. The
 * float planes hold awkward values: negatives, values beyond 1, half subnormals, +inf depth on
 * a checkerboard and -0 depth at one pixel. */
static rnd_frame make_frame(int w, int h, int with_float)
{
    rnd_frame f = { .width = w, .height = h };
    f.rgba8 = malloc((size_t)w * h * 4);
    assert_non_null(f.rgba8);
    if (with_float) {
        f.rgba16f = malloc((size_t)w * h * 8);
        f.depth = malloc((size_t)w * h * 4);
        assert_non_null(f.rgba16f);
        assert_non_null(f.depth);
    }
    for (int y = 0; y < h; y++) {
        int t = h - 1 - y;
        for (int x = 0; x < w; x++) {
            uint8_t *p = f.rgba8 + ((size_t)y * w + x) * 4;
            int check = ((x / 32) + (t / 32)) & 1;
            p[0] = (uint8_t)(255 * x / (w - 1));
            p[1] = (uint8_t)(255 * t / (h - 1));
            p[2] = (uint8_t)(check ? 168 : 88);
            p[3] = (uint8_t)((x ^ t) & 255);
            if (y == 0) { p[0] = 255; p[1] = 0; p[2] = 0; p[3] = 255; }
            if (y == h - 1) { p[0] = 0; p[1] = 0; p[2] = 255; p[3] = 255; }
            if (with_float) {
                size_t i = (size_t)y * w + x;
                f.rgba16f[i * 4 + 0] = half_from_float(4.0f * x / w - 1.0f);
                f.rgba16f[i * 4 + 1] = half_from_float(0.01f * t);
                f.rgba16f[i * 4 + 2] = half_from_float(1e-6f * (float)(x + 1)); /* subnormal */
                f.rgba16f[i * 4 + 3] = half_from_float(check ? 1.0f : 0.5f);
                f.depth[i] = check ? INFINITY : 1.0f + (float)t * 0.37f + (float)x * 1e-3f;
            }
        }
    }
    if (with_float) f.depth[0] = -0.0f;
    return f;
}

static void free_frame(rnd_frame *f)
{
    free(f->rgba8);
    free(f->rgba16f);
    free(f->depth);
    memset(f, 0, sizeof *f);
}

/* expect_rgba8_top_down: asserts that img (top-down RGBA8) equals frame f's pixels exactly. */
static void expect_rgba8_top_down(const uint8_t *img, const rnd_frame *f)
{
    size_t row = (size_t)f->width * 4;
    for (int t = 0; t < f->height; t++)
        assert_memory_equal(img + (size_t)t * row, f->rgba8 + (size_t)(f->height - 1 - t) * row,
                            row);
}

static sp_params params_fmt(int fmt)
{
    sp_params p;
    sp_params_defaults(&p);
    p.format = fmt;
    return p;
}

/* ---- half ---- */

static void test_half_conversion(void **state)
{
    (void)state;
    /* Every non-NaN half survives half -> float -> half unchanged (half_to_float is exact). */
    for (uint32_t h = 0; h < 0x10000u; h++) {
        if ((h & 0x7c00u) == 0x7c00u && (h & 0x3ffu)) {
            assert_true(isnan(half_to_float((uint16_t)h)));
            assert_true(isnan(half_to_float(half_from_float(half_to_float((uint16_t)h)))));
            continue;
        }
        assert_int_equal(half_from_float(half_to_float((uint16_t)h)), h);
    }
    /* Known encodings and the round-to-nearest-even cases (values from IEEE 754 binary16). */
    assert_int_equal(half_from_float(1.0f), 0x3c00);
    assert_int_equal(half_from_float(-2.0f), 0xc000);
    assert_int_equal(half_from_float(65504.0f), 0x7bff);           /* largest finite */
    assert_int_equal(half_from_float(65519.0f), 0x7bff);           /* below the midpoint */
    assert_int_equal(half_from_float(65520.0f), 0x7c00);           /* midpoint, ties to inf */
    assert_int_equal(half_from_float(1.0f + 1.0f / 2048), 0x3c00);  /* tie -> even (1.0) */
    assert_int_equal(half_from_float(1.0f + 3.0f / 2048), 0x3c02);  /* tie -> even (up) */
    assert_int_equal(half_from_float(ldexpf(1.0f, -24)), 0x0001);  /* smallest subnormal */
    assert_int_equal(half_from_float(ldexpf(1.0f, -25)), 0x0000);  /* tie -> even (0) */
    assert_int_equal(half_from_float(ldexpf(1.5f, -25)), 0x0001);
    assert_int_equal(half_from_float(ldexpf(3.0f, -25)), 0x0002);  /* 1.5 units: tie -> 2 */
    assert_int_equal(half_from_float(ldexpf(1023.5f, -24)), 0x0400); /* rounds up to normal */
    assert_int_equal(half_from_float(-0.0f), 0x8000);
    assert_int_equal(half_from_float(INFINITY), 0x7c00);
    assert_true((half_from_float(NAN) & 0x7fffu) > 0x7c00u);
    assert_true(half_to_float(0x3555) == 0x1.554p-2f);             /* 0.333251953125 */
}

/* ---- JPEG ---- */

/* psnr_rgb: PSNR in dB of img (top-down RGBA8, w x h) against f, over R, G and B. */
static double psnr_rgb(const uint8_t *img, const rnd_frame *f)
{
    double se = 0;
    for (int t = 0; t < f->height; t++)
        for (int x = 0; x < f->width; x++)
            for (int c = 0; c < 3; c++) {
                double d = (double)img[((size_t)t * f->width + x) * 4 + c] -
                           (double)f->rgba8[((size_t)(f->height - 1 - t) * f->width + x) * 4 + c];
                se += d * d;
            }
    double mse = se / ((double)f->width * f->height * 3);
    return mse == 0 ? 99.0 : 10.0 * log10(255.0 * 255.0 / mse);
}

/* row_mean: mean of channel c over top-down row t of img. */
static double row_mean(const uint8_t *img, int w, int t, int c)
{
    double s = 0;
    for (int x = 0; x < w; x++) s += img[((size_t)t * w + x) * 4 + c];
    return s / w;
}

static void check_jpeg(int w, int h)
{
    rnd_frame f = make_frame(w, h, 0);
    sd_err err = { 0 };
    enc_ctx *e = enc_create(&err);
    assert_non_null(e);
    sp_params p = params_fmt(SP_FMT_JPEG);
    p.quality = 90;
    p.subsampling = SP_SUB_444;
    const uint8_t *out;
    size_t len;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_true(len > 2 && out[0] == 0xff && out[1] == 0xd8);

    /* Decode with TurboJPEG directly, independently of the client decoder. */
    tjhandle tj = tjInitDecompress();
    assert_non_null(tj);
    int dw, dh, samp, cs;
    assert_int_equal(tjDecompressHeader3(tj, out, len, &dw, &dh, &samp, &cs), 0);
    assert_int_equal(dw, w);
    assert_int_equal(dh, h);
    assert_int_equal(samp, TJSAMP_444);
    uint8_t *img = malloc((size_t)w * h * 4);
    assert_non_null(img);
    assert_int_equal(tjDecompress2(tj, out, len, img, w, w * 4, h, TJPF_RGBA, 0), 0);
    /* q90 scales the standard quantisation tables to 20%, so smooth areas come back within a
     * level or so (this frame measures 48-50 dB); 35 dB (RMS error 4.5 levels) leaves room for
     * ringing at sharp edges and for other libjpeg-turbo builds. A wrong row order, channel
     * order or stride gives well under 20 dB on this frame. */
    double psnr = psnr_rgb(img, &f);
    print_message("jpeg q90 4:4:4 %dx%d: %zu bytes, PSNR %.1f dB\n", w, h, len, psnr);
    assert_true(psnr >= 35.0);
    /* Row order: GL's bottom row (red) is the image's last row, GL's top row (blue) its
     * first. Means over the row; JPEG ringing from the neighbouring rows stays below 60. */
    assert_true(row_mean(img, w, h - 1, 0) > 200 && row_mean(img, w, h - 1, 2) < 60);
    assert_true(row_mean(img, w, 0, 2) > 200 && row_mean(img, w, 0, 0) < 60);

    /* The client decoder gives the same pixels as TurboJPEG itself. */
    char msg[256];
    fd_ctx *d = fd_create(msg, sizeof msg);
    assert_non_null(d);
    const uint8_t *rgba;
    int ow = 0, oh = 0;
    assert_int_equal(fd_decode(d, SP_FMT_JPEG, out, len, w, h, &rgba, &ow, &oh, msg, sizeof msg),
                     0);
    assert_int_equal(ow, w);
    assert_int_equal(oh, h);
    assert_memory_equal(rgba, img, (size_t)w * h * 4);

    /* Gray: one component, decoded to R = G = B. */
    p.subsampling = SP_SUB_GRAY;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(tjDecompressHeader3(tj, out, len, &dw, &dh, &samp, &cs), 0);
    assert_int_equal(samp, TJSAMP_GRAY);
    assert_int_equal(fd_decode(d, SP_FMT_JPEG, out, len, 0, 0, &rgba, NULL, NULL, msg,
                               sizeof msg), 0);
    assert_true(rgba[0] == rgba[1] && rgba[1] == rgba[2] && rgba[3] == 255);

    /* 4:2:2: the subsampling asked for is the one the JPEG header declares (TurboJPEG's own
     * header parser, independent of the encoder's mapping of SP_SUB_* values). */
    p.subsampling = SP_SUB_422;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(tjDecompressHeader3(tj, out, len, &dw, &dh, &samp, &cs), 0);
    assert_int_equal(samp, TJSAMP_422);

    /* 4:2:0 at q85 (the defaults) is what the header says, and smaller than 4:4:4 q90. */
    size_t len444 = 0;
    p.subsampling = SP_SUB_444;
    p.quality = 90;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len444, &err), 0);
    sp_params_defaults(&p);
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(tjDecompressHeader3(tj, out, len, &dw, &dh, &samp, &cs), 0);
    assert_int_equal(samp, TJSAMP_420);
    assert_true(len < len444);

    fd_destroy(d);
    tjDestroy(tj);
    free(img);
    enc_destroy(e);
    free_frame(&f);
}

static void test_jpeg_1280x720(void **state) { (void)state; check_jpeg(1280, 720); }
static void test_jpeg_333x171(void **state) { (void)state; check_jpeg(333, 171); }

static void test_jpeg_buffer_reused(void **state)
{
    (void)state;
    rnd_frame f = make_frame(640, 360, 0), g = make_frame(1280, 720, 0);
    sd_err err = { 0 };
    enc_ctx *e = enc_create(&err);
    assert_non_null(e);
    sp_params p = params_fmt(SP_FMT_JPEG);
    const uint8_t *a, *b;
    size_t la, lb;
    assert_int_equal(enc_encode(e, &f, &p, &a, &la, &err), 0);
    f.rgba8[100] ^= 0xff; /* different content, same size */
    p.quality = 100;
    p.subsampling = SP_SUB_444; /* the buffer is sized for the 4:4:4 worst case */
    assert_int_equal(enc_encode(e, &f, &p, &b, &lb, &err), 0);
    assert_ptr_equal(a, b);
    assert_true(lb > la); /* q100 4:4:4 is bigger: really a new frame in the same buffer */
    /* A bigger frame may grow the buffer once; from then on it is stable again, also when
     * going back to the smaller size. */
    assert_int_equal(enc_encode(e, &g, &p, &a, &la, &err), 0);
    assert_int_equal(enc_encode(e, &g, &p, &b, &lb, &err), 0);
    assert_ptr_equal(a, b);
    assert_int_equal(enc_encode(e, &f, &p, &b, &lb, &err), 0);
    assert_ptr_equal(a, b);
    enc_destroy(e);
    free_frame(&f);
    free_frame(&g);
}

/* ---- PNG ---- */

static void check_png(int w, int h)
{
    rnd_frame f = make_frame(w, h, 0);
    sd_err err = { 0 };
    enc_ctx *e = enc_create(&err);
    assert_non_null(e);
    sp_params p = params_fmt(SP_FMT_PNG);
    const uint8_t *out;
    size_t len;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(png_sig_cmp(out, 0, 8), 0);

    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_memory(&img, out, len));
    assert_int_equal(img.width, w);
    assert_int_equal(img.height, h);
    img.format = PNG_FORMAT_RGBA;
    uint8_t *pix = malloc(PNG_IMAGE_SIZE(img));
    assert_non_null(pix);
    assert_true(png_image_finish_read(&img, NULL, pix, 0, NULL));
    expect_rgba8_top_down(pix, &f); /* lossless: exactly the same bytes, alpha included */
    free(pix);
    enc_destroy(e);
    free_frame(&f);
}

static void test_png_exact(void **state)
{
    (void)state;
    check_png(1280, 720);
    check_png(333, 171);
}

/* ---- LZ4 and raw ---- */

static void check_lz4(rnd_frame *f)
{
    sd_err err = { 0 };
    char msg[256];
    enc_ctx *e = enc_create(&err);
    fd_ctx *d = fd_create(msg, sizeof msg);
    assert_non_null(e);
    assert_non_null(d);
    sp_params p = params_fmt(SP_FMT_LZ4);
    const uint8_t *out, *rgba;
    size_t len;
    int w = 0, h = 0;
    assert_int_equal(enc_encode(e, f, &p, &out, &len, &err), 0);
    /* The header, byte by byte (little-endian). */
    assert_memory_equal(out, "SPL4", 4);
    assert_int_equal(out[4] | out[5] << 8 | out[6] << 16 | out[7] << 24, f->width);
    assert_int_equal(out[8] | out[9] << 8 | out[10] << 16 | out[11] << 24, f->height);
    assert_int_equal((uint32_t)out[12] | (uint32_t)out[13] << 8 | (uint32_t)out[14] << 16 |
                     (uint32_t)out[15] << 24, (uint32_t)f->width * f->height * 4);
    assert_int_equal(fd_decode(d, SP_FMT_LZ4, out, len, f->width, f->height, &rgba, &w, &h, msg,
                               sizeof msg), 0);
    assert_int_equal(w, f->width);
    assert_int_equal(h, f->height);
    expect_rgba8_top_down(rgba, f);
    fd_destroy(d);
    enc_destroy(e);
}

static void test_lz4_round_trip(void **state)
{
    (void)state;
    rnd_frame f = make_frame(1280, 720, 0);
    check_lz4(&f);
    free_frame(&f);
    f = make_frame(333, 171, 0);
    check_lz4(&f);
    /* A uniform frame compresses near LZ4's limit ratio and must still pass the header's
     * expansion check. */
    memset(f.rgba8, 0, (size_t)f.width * f.height * 4);
    check_lz4(&f);
    free_frame(&f);
}

/* put32: little-endian store for building damaged headers. */
static void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static void test_lz4_rejects_damage(void **state)
{
    (void)state;
    rnd_frame f = make_frame(333, 171, 0);
    sd_err err = { 0 };
    char msg[256];
    enc_ctx *e = enc_create(&err);
    fd_ctx *d = fd_create(msg, sizeof msg);
    sp_params p = params_fmt(SP_FMT_LZ4);
    const uint8_t *out, *rgba;
    size_t len;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    uint8_t *b = malloc(len);
    assert_non_null(b);
    int w, h;
#define RESET() memcpy(b, out, len)
#define DEC(n, ew, eh) fd_decode(d, SP_FMT_LZ4, b, (n), (ew), (eh), &rgba, &w, &h, msg, sizeof msg)

    RESET();
    assert_int_equal(DEC(10, 0, 0), FD_ETRUNC);                /* shorter than the header */
    assert_non_null(strstr(msg, "shorter than the 16-byte header"));
    assert_int_equal(DEC(0, 0, 0), FD_ETRUNC);
    b[0] = 'X';
    assert_int_equal(DEC(len, 0, 0), FD_EFORMAT);              /* magic */
    assert_non_null(strstr(msg, "magic"));
    RESET();
    put32(b + 4, 0);
    assert_int_equal(DEC(len, 0, 0), FD_ELIMIT);               /* width 0 */
    RESET();
    put32(b + 4, 100000);
    put32(b + 12, 100000u * 171 * 4);
    assert_int_equal(DEC(len, 0, 0), FD_ELIMIT);               /* width over the limit */
    assert_non_null(strstr(msg, "100000x171"));
    RESET();
    put32(b + 12, 333u * 171 * 4 + 4);
    assert_int_equal(DEC(len, 0, 0), FD_EFORMAT);              /* raw size != w*h*4 */
    assert_non_null(strstr(msg, "byte 12"));
    /* frame_lz4.h: each dimension in 1..SP_FRAME_MAX_DIM. A one-pixel-wide column of
     * SP_FRAME_MAX_DIM rows passes the header check, one more row (or column) is refused by
     * name; the header alone is parsed, with a length the block could expand from. */
    {
        uint8_t hd[SP_LZ4_HEADER_SIZE];
        uint32_t hw = 0, hh = 0;
        char over[16];
        snprintf(over, sizeof over, "%d", SP_FRAME_MAX_DIM + 1);
        const size_t big = (size_t)SP_LZ4_HEADER_SIZE + 4u * (SP_FRAME_MAX_DIM + 1);
        memcpy(hd, b, 4);
        for (int side = 0; side < 2; side++) {
            put32(hd + 4 + 4 * side, 1);
            put32(hd + 8 - 4 * side, SP_FRAME_MAX_DIM);
            put32(hd + 12, 4u * SP_FRAME_MAX_DIM);
            assert_int_equal(sp_lz4_header_get(hd, big, &hw, &hh, msg, sizeof msg), SP_LZ4_OK);
            assert_int_equal(side ? hw : hh, SP_FRAME_MAX_DIM);
            put32(hd + 8 - 4 * side, SP_FRAME_MAX_DIM + 1);
            put32(hd + 12, 4u * (SP_FRAME_MAX_DIM + 1));
            assert_int_equal(sp_lz4_header_get(hd, big, &hw, &hh, msg, sizeof msg),
                             SP_LZ4_ELIMIT);
            assert_non_null(strstr(msg, over));
        }
    }
    /* An oversized but consistent header (16384x16384 = 1 GiB) on a small payload is refused
     * before anything is allocated for it. */
    RESET();
    put32(b + 4, 16384);
    put32(b + 8, 16384);
    put32(b + 12, 16384u * 16384u * 4u);
    assert_int_equal(DEC(len, 0, 0), FD_EFORMAT);
    assert_non_null(strstr(msg, "cannot come out of"));
    /* The header disagrees with the size the FRAME message announced. */
    RESET();
    assert_int_equal(DEC(len, 334, 171), FD_EFORMAT);
    assert_non_null(strstr(msg, "announced 334x171"));
    /* One more row than the data holds: decompression stops short. */
    RESET();
    put32(b + 8, 172);
    put32(b + 12, 333u * 172 * 4);
    assert_int_equal(DEC(len, 0, 0), FD_ETRUNC);
    /* Truncated block. */
    RESET();
    int rc = DEC(len - 50, 0, 0);
    assert_true(rc == FD_EFORMAT || rc == FD_ETRUNC);
    /* Garbage token bytes: literal lengths that run past the end of the block. */
    RESET();
    memset(b + 16, 0xff, 64);
    assert_int_equal(DEC(len, 0, 0), FD_EFORMAT);
    assert_non_null(strstr(msg, "corrupt"));
    /* The intact frame still decodes with the same buffers. */
    RESET();
    assert_int_equal(DEC(len, 333, 171), 0);
    expect_rgba8_top_down(rgba, &f);
#undef DEC
#undef RESET

    /* Other formats. */
    assert_int_equal(fd_decode(d, SP_FMT_PNG, out, len, 0, 0, &rgba, NULL, NULL, msg, sizeof msg),
                     FD_EUNSUP);
    assert_non_null(strstr(msg, "png"));
    assert_int_equal(fd_decode(d, 42, out, len, 0, 0, &rgba, NULL, NULL, msg, sizeof msg),
                     FD_EUNSUP);
    uint8_t junk[64];
    memset(junk, 0x5a, sizeof junk);
    assert_int_equal(fd_decode(d, SP_FMT_JPEG, junk, sizeof junk, 0, 0, &rgba, NULL, NULL, msg,
                               sizeof msg), FD_EFORMAT);
    /* A JPEG cut in half is an error, not a half-grey image. */
    p.format = SP_FMT_JPEG;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(fd_decode(d, SP_FMT_JPEG, out, len / 2, 0, 0, &rgba, NULL, NULL, msg,
                               sizeof msg), FD_EFORMAT);
    /* Raw: the length must be exactly w*h*4. */
    p.format = SP_FMT_RAW;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_int_equal(len, 333u * 171 * 4);
    assert_int_equal(fd_decode(d, SP_FMT_RAW, out, len - 1, 333, 171, &rgba, NULL, NULL, msg,
                               sizeof msg), FD_ETRUNC);
    assert_int_equal(fd_decode(d, SP_FMT_RAW, out, len, 0, 0, &rgba, NULL, NULL, msg,
                               sizeof msg), FD_EINVAL);
    assert_int_equal(fd_decode(d, SP_FMT_RAW, out, len, 333, 171, &rgba, &w, &h, msg,
                               sizeof msg), 0);
    expect_rgba8_top_down(rgba, &f);

    free(b);
    fd_destroy(d);
    enc_destroy(e);
    free_frame(&f);
}

/* ---- EXR ---- */

/* read_exr_check: reads path with OpenEXR's C reader and asserts channels A B G R (half) and Z
 * (float), compression comp, increasing-Y, and pixels bit-identical to f (flipped). */
static void read_exr_check(const char *path, const rnd_frame *f, exr_compression_t comp)
{
    int w = f->width, h = f->height;
    exr_context_t c = NULL;
    assert_int_equal(exr_start_read(&c, path, NULL), EXR_ERR_SUCCESS);
    const exr_attr_chlist_t *cl = NULL;
    assert_int_equal(exr_get_channels(c, 0, &cl), EXR_ERR_SUCCESS);
    assert_int_equal(cl->num_channels, 5);
    static const char *names[] = { "A", "B", "G", "R", "Z" };
    for (int i = 0; i < 5; i++) {
        assert_string_equal(cl->entries[i].name.str, names[i]);
        assert_int_equal(cl->entries[i].pixel_type, i == 4 ? EXR_PIXEL_FLOAT : EXR_PIXEL_HALF);
    }
    exr_compression_t cm;
    assert_int_equal(exr_get_compression(c, 0, &cm), EXR_ERR_SUCCESS);
    assert_int_equal(cm, comp);
    exr_lineorder_t lo;
    assert_int_equal(exr_get_lineorder(c, 0, &lo), EXR_ERR_SUCCESS);
    assert_int_equal(lo, EXR_LINEORDER_INCREASING_Y);
    exr_attr_box2i_t dw;
    assert_int_equal(exr_get_data_window(c, 0, &dw), EXR_ERR_SUCCESS);
    assert_true(dw.min.x == 0 && dw.min.y == 0 && dw.max.x == w - 1 && dw.max.y == h - 1);

    uint16_t *col = calloc((size_t)w * h * 4, 2);
    float *z = calloc((size_t)w * h, 4);
    assert_non_null(col);
    assert_non_null(z);
    int32_t lines = 0;
    assert_int_equal(exr_get_scanlines_per_chunk(c, 0, &lines), EXR_ERR_SUCCESS);
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int started = 0;
    for (int y = 0; y < h; y += lines) {
        exr_chunk_info_t ci;
        assert_int_equal(exr_read_scanline_chunk_info(c, 0, y, &ci), EXR_ERR_SUCCESS);
        assert_int_equal(started ? exr_decoding_update(c, 0, &ci, &dec)
                                 : exr_decoding_initialize(c, 0, &ci, &dec), EXR_ERR_SUCCESS);
        for (int k = 0; k < dec.channel_count; k++) {
            exr_coding_channel_info_t *ch = &dec.channels[k];
            if (ch->channel_name[0] == 'Z') {
                ch->decode_to_ptr = (uint8_t *)(z + (size_t)ci.start_y * w);
                ch->user_pixel_stride = 4;
                ch->user_line_stride = w * 4;
                ch->user_data_type = EXR_PIXEL_FLOAT;
                ch->user_bytes_per_element = 4;
            } else {
                int off = strchr("RGBA", ch->channel_name[0]) - "RGBA";
                ch->decode_to_ptr = (uint8_t *)(col + (size_t)ci.start_y * w * 4 + off);
                ch->user_pixel_stride = 8;
                ch->user_line_stride = w * 8;
                ch->user_data_type = EXR_PIXEL_HALF;
                ch->user_bytes_per_element = 2;
            }
        }
        if (!started) {
            assert_int_equal(exr_decoding_choose_default_routines(c, 0, &dec), EXR_ERR_SUCCESS);
            started = 1;
        }
        assert_int_equal(exr_decoding_run(c, 0, &dec), EXR_ERR_SUCCESS);
    }
    assert_int_equal(exr_decoding_destroy(c, &dec), EXR_ERR_SUCCESS);
    assert_int_equal(exr_finish(&c), EXR_ERR_SUCCESS);
    /* Lossless: the same bits (inf, -0 and subnormals included), row t = GL row h-1-t. */
    for (int t = 0; t < h; t++) {
        size_t src = (size_t)(h - 1 - t) * w;
        assert_memory_equal(col + (size_t)t * w * 4, f->rgba16f + src * 4, (size_t)w * 8);
        assert_memory_equal(z + (size_t)t * w, f->depth + src, (size_t)w * 4);
    }
    free(col);
    free(z);
}

/* dir_entries: number of entries in dir besides . and .. */
static int dir_entries(const char *dir)
{
    DIR *d = opendir(dir);
    assert_non_null(d);
    int n = 0;
    struct dirent *de;
    while ((de = readdir(d)))
        if (strcmp(de->d_name, ".") && strcmp(de->d_name, "..")) n++;
    closedir(d);
    return n;
}

static void test_exr_file_and_memory(void **state)
{
    (void)state;
    char dir[512], path[600];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    sd_err err = { 0 };
    for (int k = 0; k < 2; k++) {
        rnd_frame f = k ? make_frame(333, 171, 1) : make_frame(1280, 720, 1);
        snprintf(path, sizeof path, "%s/frame%d.EXR", dir, k);
        assert_int_equal(enc_write_file(path, &f, NULL, &err), 0);
        read_exr_check(path, &f, EXR_COMPRESSION_PIZ);
        free_frame(&f);
    }
    /* In memory with ZIP, read back through a file. */
    rnd_frame f = make_frame(333, 171, 1);
    enc_ctx *e = enc_create(&err);
    assert_int_equal(enc_set_exr_compression(e, ENC_EXR_ZIP, &err), 0);
    assert_int_equal(enc_set_exr_compression(e, (enc_exr_compression)9, &err), SD_EINVAL);
    sp_params p = params_fmt(SP_FMT_EXR);
    const uint8_t *out;
    size_t len;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), 0);
    assert_true(len > 4 && out[0] == 0x76 && out[1] == 0x2f && out[2] == 0x31 && out[3] == 0x01);
    snprintf(path, sizeof path, "%s/zip.exr", dir);
    assert_int_equal(tu_write_file(path, out, len), 0);
    read_exr_check(path, &f, EXR_COMPRESSION_ZIP);
    assert_int_equal(dir_entries(dir), 3); /* frame0.EXR frame1.EXR zip.exr: no temporaries */

    /* EXR needs the float planes: an error, and no file. */
    free(f.depth);
    f.depth = NULL;
    snprintf(path, sizeof path, "%s/nodepth.exr", dir);
    assert_int_equal(enc_write_file(path, &f, NULL, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "nodepth.exr"));
    assert_non_null(strstr(err.msg, "depth"));
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), SD_EINVAL);
    assert_int_equal(dir_entries(dir), 3);
    enc_destroy(e);
    free_frame(&f);
    tu_rm_rf(dir);
}

/* ---- files and argument errors ---- */

static void test_write_file_formats_and_errors(void **state)
{
    (void)state;
    char dir[512], path[600];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    rnd_frame f = make_frame(333, 171, 0);
    sd_err err = { 0 };
    static const struct { const char *name; uint8_t b0, b1; } files[] = {
        { "a.jpg", 0xff, 0xd8 }, { "b.JPEG", 0xff, 0xd8 }, { "c.Png", 0x89, 'P' },
    };
    for (size_t i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i].name);
        assert_int_equal(enc_write_file(path, &f, NULL, &err), 0);
        size_t n = 0;
        uint8_t *b = tu_read_file(path, &n);
        assert_non_null(b);
        assert_true(n > 100 && b[0] == files[i].b0 && b[1] == files[i].b1);
        free(b);
    }
    snprintf(path, sizeof path, "%s/d.raw", dir);
    assert_int_equal(enc_write_file(path, &f, NULL, &err), 0);
    size_t n = 0;
    uint8_t *b = tu_read_file(path, &n);
    assert_int_equal(n, 333u * 171 * 4);
    expect_rgba8_top_down(b, &f);
    free(b);
    /* Overwriting an existing file replaces it whole. */
    assert_int_equal(enc_write_file(path, &f, NULL, &err), 0);
    assert_int_equal(dir_entries(dir), 4);

    /* Unknown or missing extension: an error naming it, nothing written. */
    snprintf(path, sizeof path, "%s/e.bmp", dir);
    assert_int_equal(enc_write_file(path, &f, NULL, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "\".bmp\""));
    snprintf(path, sizeof path, "%s/noext", dir);
    assert_int_equal(enc_write_file(path, &f, NULL, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "no extension"));
    assert_int_equal(enc_format_from_path("x.tar.Jpg", &err), SP_FMT_JPEG);
    assert_int_equal(enc_format_from_path("dir.png/x", &err), SD_EINVAL);
    /* A hidden file's leading dot starts its name, not an extension: "out/.png" has none. */
    assert_int_equal(enc_format_from_path("out/.png", &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "no extension"));
    assert_int_equal(enc_format_from_path(".jpg", &err), SD_EINVAL);
    assert_int_equal(dir_entries(dir), 4);

    /* A directory that does not exist: an error naming the path, nothing left behind. */
    snprintf(path, sizeof path, "%s/nosuchdir/f.png", dir);
    assert_int_equal(enc_write_file(path, &f, NULL, &err), SD_EIO);
    assert_non_null(strstr(err.msg, "nosuchdir/f.png"));
    snprintf(path, sizeof path, "%s/nosuchdir", dir);
    struct stat st;
    assert_int_equal(stat(path, &st), -1);
    assert_int_equal(dir_entries(dir), 4);

    /* Bad frames and parameters. */
    enc_ctx *e = enc_create(&err);
    sp_params p = params_fmt(SP_FMT_JPEG);
    const uint8_t *out = (const uint8_t *)"x";
    size_t len = 7;
    p.quality = 0;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "quality 0"));
    assert_null(out);
    assert_int_equal(len, 0);
    p.quality = 85;
    p.subsampling = 7;
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "subsampling 7"));
    p = params_fmt(99);
    assert_int_equal(enc_encode(e, &f, &p, &out, &len, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "format 99"));
    p = params_fmt(SP_FMT_PNG);
    rnd_frame bad = f;
    bad.width = 0;
    assert_int_equal(enc_encode(e, &bad, &p, &out, &len, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "0x171"));
    bad = f;
    bad.rgba8 = NULL;
    assert_int_equal(enc_encode(e, &bad, &p, &out, &len, &err), SD_EINVAL);
    bad = f;
    bad.height = ENC_MAX_DIM + 1;
    assert_int_equal(enc_encode(e, &bad, &p, &out, &len, &err), SD_EINVAL);
    enc_destroy(e);
    enc_destroy(NULL);
    fd_destroy(NULL);
    free_frame(&f);
    tu_rm_rf(dir);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_half_conversion),
        cmocka_unit_test(test_jpeg_1280x720),
        cmocka_unit_test(test_jpeg_333x171),
        cmocka_unit_test(test_jpeg_buffer_reused),
        cmocka_unit_test(test_png_exact),
        cmocka_unit_test(test_lz4_round_trip),
        cmocka_unit_test(test_lz4_rejects_damage),
        cmocka_unit_test(test_exr_file_and_memory),
        cmocka_unit_test(test_write_file_formats_and_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
