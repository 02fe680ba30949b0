/* test_io_pcd.c — the PCD reader (server/io_pcd.c) and the LZF decoder (server/lzf.c).
 *
 * Real files go through pc_load so that finalisation (NaN removal, bounding box) runs. The
 * expected numbers come from outside the reader: a small independent parse in this file for
 * the ascii and binary files, and for the binary_compressed files values found once with a
 * throwaway Python LZF decoder (see the comments at each). Broken files are written to a
 * temporary directory: each must give the right code and a message naming the file and the
 * line or byte offset.
 *
 * Point by point: every point of the four real files against a decoding written here (strtod
 * for ascii, the record layout for binary, an LZF decoder of this file for binary_compressed),
 * and every TYPE/SIZE in every DATA kind in files written here with iotest.h's byte writers. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cloud.h"
#include "lzf.h"
#include "common/testutil.h"
#include "cloudtest.h"
#include "iotest.h"
#include "rng.h"
#include "testutil.h"

static char g_tmp[512];

static int setup(void **state)
{
    (void)state;
    return tu_tmpdir(g_tmp, sizeof g_tmp) ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    tu_rm_rf(g_tmp);
    return 0;
}

static const char *tmp_path(const char *name, char *buf, size_t len)
{
    snprintf(buf, len, "%s/%s", g_tmp, name);
    return buf;
}

/* Tolerance for bounding boxes: 1e-3 of the box's extent on that axis. The readers copy the
 * float32/float64 values exactly, so a decoding error (wrong field, offset or byte order) is
 * orders of magnitude larger; 1e-3 of the extent is tighter than 1e-3 of the value for
 * georeferenced data (UTM northings of 5.4e6 m). */
static void assert_box(const pc_cloud *c, const double lo[3], const double hi[3])
{
    for (int k = 0; k < 3; k++) {
        double tol = 1e-3 * (hi[k] - lo[k]);
        if (fabs(c->bmin[k] - lo[k]) > tol || fabs(c->bmax[k] - hi[k]) > tol)
            fail_msg("axis %d: box [%.9g, %.9g], expected [%.9g, %.9g] (tolerance %g)", k,
                     c->bmin[k], c->bmax[k], lo[k], hi[k], tol);
    }
}

/* Loads path, expecting failure with code: the message must name the file and a line or a
 * byte offset. */
static void expect_fail(const char *path, int code)
{
    pc_cloud c;
    sd_err e = {0};
    int rc = pc_load(path, &c, &e);
    if (rc != code || e.code != code)
        fail_msg("%s: got %d (%s), expected %d; message: %s", path, rc, sd_strerror(rc), code,
                 e.msg);
    if (!strstr(e.msg, path) || (!strstr(e.msg, "offset") && !strstr(e.msg, "line")))
        fail_msg("message lacks the file name or the line/offset: %s", e.msg);
    assert_null(c.pos);
}

/* Writes len bytes of data to a temporary file named name and expects code from pc_load. */
static void expect_fail_bytes(const char *name, const void *data, size_t len, int code)
{
    char p[1024];
    tmp_path(name, p, sizeof p);
    assert_int_equal(tu_write_file(p, data, len), 0);
    expect_fail(p, code);
}

static void load_text(const char *name, const char *text, pc_cloud *c)
{
    char p[1024];
    tmp_path(name, p, sizeof p);
    assert_int_equal(tu_write_file(p, text, strlen(text)), 0);
    tu_load_ok(p, c);
}

/* Offset of the first byte after the "DATA ..." header line. */
static size_t data_offset(const uint8_t *b, size_t len)
{
    const char *d = strstr((const char *)b, "\nDATA ");
    assert_non_null(d);
    const char *nl = memchr(d + 1, '\n', len - (size_t)((const uint8_t *)d + 1 - b));
    assert_non_null(nl);
    return (size_t)((const uint8_t *)nl + 1 - b);
}

/* Replaces the first occurrence of from by to (same length) in the header of b. */
static void patch(uint8_t *b, const char *from, const char *to)
{
    assert_int_equal(strlen(from), strlen(to));
    char *p = strstr((char *)b, from);
    assert_non_null(p);
    memcpy(p, to, strlen(to));
}

/* ---- LZF ---- */

static void test_lzf_literal(void **state)
{
    (void)state;
    const uint8_t in[] = {2, 'a', 'b', 'c', 0, 'd'};
    uint8_t out[4];
    sd_err e = {0};
    assert_int_equal(pc_lzf_decompress(in, sizeof in, out, 4, "t", 0, &e), 0);
    assert_memory_equal(out, "abcd", 4);
    /* An empty stream is an empty output. */
    assert_int_equal(pc_lzf_decompress(in, 0, out, 0, "t", 0, &e), 0);
}

static void test_lzf_back_reference(void **state)
{
    (void)state;
    /* "abc" then a reference 3 back, len field 4 -> 6 bytes, overlapping its own output. */
    const uint8_t in[] = {2, 'a', 'b', 'c', (4 << 5) | 0, 2};
    uint8_t out[9];
    sd_err e = {0};
    assert_int_equal(pc_lzf_decompress(in, sizeof in, out, 9, "t", 0, &e), 0);
    assert_memory_equal(out, "abcabcabc", 9);
}

static void test_lzf_long_back_reference(void **state)
{
    (void)state;
    /* 300 literal bytes (10 runs of 30), then a reference 300 back with an extra length byte:
     * len = 7 + 93 = 100 -> 102 bytes; distance 300 = (1 << 8) + 43 + 1. */
    uint8_t in[400], out[402], want[402];
    size_t n = 0;
    for (int r = 0; r < 10; r++) {
        in[n++] = 29;
        for (int i = 0; i < 30; i++) in[n++] = (uint8_t)(r * 30 + i) ^ 0x5a;
    }
    in[n++] = (7 << 5) | 1;
    in[n++] = 93;
    in[n++] = 43;
    for (int i = 0; i < 300; i++) want[i] = (uint8_t)i ^ 0x5a;
    for (int i = 0; i < 102; i++) want[300 + i] = want[i];
    sd_err e = {0};
    assert_int_equal(pc_lzf_decompress(in, n, out, 402, "t", 0, &e), 0);
    assert_memory_equal(out, want, 402);

    /* The longest reference: 7 + 255 + 2 = 264 bytes from 3 input bytes (the 88:1 bound). */
    const uint8_t run[] = {0, 'z', 0xE0, 255, 0};
    uint8_t big[265];
    assert_int_equal(pc_lzf_decompress(run, sizeof run, big, 265, "t", 0, &e), 0);
    for (int i = 0; i < 265; i++) assert_int_equal(big[i], 'z');
}

static void test_lzf_overruns(void **state)
{
    (void)state;
    uint8_t out[16];
    sd_err e = {0};
    /* Literal run longer than the input. */
    const uint8_t a[] = {5, 'a', 'b'};
    assert_int_equal(pc_lzf_decompress(a, sizeof a, out, 6, "s", 100, &e), SD_ETRUNC);
    assert_non_null(strstr(e.msg, "offset 100"));
    /* Literal run longer than the output. */
    const uint8_t b[] = {3, 'a', 'b', 'c', 'd'};
    assert_int_equal(pc_lzf_decompress(b, sizeof b, out, 3, "s", 0, &e), SD_EFORMAT);
    /* Back reference before the start of the output. */
    const uint8_t c[] = {0, 'a', (1 << 5), 1};
    assert_int_equal(pc_lzf_decompress(c, sizeof c, out, 4, "s", 0, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "offset 2"));
    /* Back reference past the end of the output. */
    const uint8_t d[] = {0, 'a', (6 << 5), 0};
    assert_int_equal(pc_lzf_decompress(d, sizeof d, out, 5, "s", 0, &e), SD_EFORMAT);
    /* Back reference whose distance byte, or extra length byte, is missing. */
    const uint8_t f[] = {0, 'a', (1 << 5)};
    assert_int_equal(pc_lzf_decompress(f, sizeof f, out, 4, "s", 0, &e), SD_ETRUNC);
    const uint8_t g[] = {0, 'a', 0xE0};
    assert_int_equal(pc_lzf_decompress(g, sizeof g, out, 16, "s", 0, &e), SD_ETRUNC);
    const uint8_t h[] = {0, 'a', 0xE0, 1};
    assert_int_equal(pc_lzf_decompress(h, sizeof h, out, 16, "s", 0, &e), SD_ETRUNC);
    /* A stream that ends before the output is full. */
    const uint8_t i[] = {1, 'a', 'b'};
    assert_int_equal(pc_lzf_decompress(i, sizeof i, out, 3, "s", 0, &e), SD_ETRUNC);
}

/* ---- real files ---- */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void test_mug_compressed_rgba(void **state)
{
    (void)state;
    char p[1024];
    pc_cloud c;
    tu_load_ok(tu_data("table_scene_mug_stereo_textured.pcd", p, sizeof p), &c);
    /* Counts from SOURCES.md (PCL 1.13) and the throwaway decoder: 640 x 480, NaN holes. */
    assert_int_equal(c.n, 209280);
    assert_int_equal(c.n_dropped, 97920);
    assert_int_equal(c.attrs, PC_ATTR_RGB);
    assert_string_equal(c.format, "PCD 0.7 binary_compressed");
    /* Values from the throwaway Python LZF decoder (/tmp/pcdref/ref.py during development:
     * it decoded the 1,722,056-byte payload to 4,915,200 bytes and scanned the finite points). */
    const double lo[3] = {-0.456429988, -0.510739982, 0.690010011};
    const double hi[3] = {0.71517998, 0.179230005, 2.5927};
    assert_box(&c, lo, hi);
    /* Same source: the first finite point (index 6538) is rgba 0xff43433e, stored B G R A
     * from the low byte, so R = 0x43, G = 0x43, B = 0x3e; and the channel sums over all
     * finite points. Both catch a swapped byte order. */
    assert_int_equal(c.rgba[0], 0x43);
    assert_int_equal(c.rgba[1], 0x43);
    assert_int_equal(c.rgba[2], 0x3e);
    uint64_t sum[3] = {0, 0, 0};
    for (size_t i = 0; i < c.n; i++) {
        for (int k = 0; k < 3; k++) sum[k] += c.rgba[4 * i + k];
        assert_int_equal(c.rgba[4 * i + 3], 255);
    }
    assert_int_equal(sum[0], 35454973);
    assert_int_equal(sum[1], 35504128);
    assert_int_equal(sum[2], 24300682);
    pc_cloud_free(&c);

    /* Speed: median of 5 loads (printed, not asserted: the machine is shared and noisy). */
    double t[5];
    for (int r = 0; r < 5; r++) {
        double t0 = now_s();
        tu_load_ok(p, &c);
        t[r] = now_s() - t0;
        pc_cloud_free(&c);
    }
    qsort(t, 5, sizeof t[0], cmp_double);
    print_message("mug PCD load (read + LZF + finalize): median %.2f ms of 5\n", t[2] * 1e3);
}

static void test_samp11_compressed_utm(void **state)
{
    (void)state;
    char p[1024];
    pc_cloud c;
    tu_load_ok(tu_data("samp11-utm.pcd", p, sizeof p), &c);
    assert_int_equal(c.n, 38010);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, 0);
    /* From the throwaway Python LZF decoder (/tmp/pcdref/ref.py), min/max of the float32
     * values. The y values are multiples of 0.5 m (float32 at 5.4e6), so exact. */
    const double lo[3] = {512700.875, 5403547.5, 295.25};
    const double hi[3] = {512834.75, 5403850.0, 404.079987};
    assert_box(&c, lo, hi);
    assert_float_equal(c.bmin[1], 5403547.5, 0.0);
    assert_float_equal(c.bmax[1], 5403850.0, 0.0);
    /* Re-centring keeps float precision: a point's position is within float rounding of its
     * offset from the centre (the box is ~300 m, so 1e-4 m is far above rounding). */
    for (int k = 0; k < 3; k++) assert_true(fabs(c.offset[k] - 0.5 * (lo[k] + hi[k])) < 1e-3);
    pc_cloud_free(&c);
}

static void test_rops_ascii(void **state)
{
    (void)state;
    char p[1024];
    tu_data("rops_cloud.pcd", p, sizeof p);
    /* Independent parse: everything after "DATA ascii\n" is "x y z" lines. */
    size_t len;
    uint8_t *b = tu_read_data("rops_cloud.pcd", &len);
    char *s = (char *)b + data_offset(b, len);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    size_t n = 0;
    for (;;) {
        double v[3];
        char *e;
        v[0] = strtod(s, &e);
        if (e == s) break;
        v[1] = strtod(e, &e);
        v[2] = strtod(e, &s);
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], v[k]);
            hi[k] = fmax(hi[k], v[k]);
        }
        n++;
    }
    free(b);
    assert_int_equal(n, 32087);
    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, n);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, 0);
    assert_string_equal(c.format, "PCD 0.7 ascii");
    assert_box(&c, lo, hi);
    pc_cloud_free(&c);
}

static void test_autzen_binary(void **state)
{
    (void)state;
    char p[1024];
    tu_data("autzen-utm.pcd", p, sizeof p);
    /* Independent parse: the SIZE line gives the record layout; the fields are, in order,
     * X Y Z Intensity ReturnNumber NumberOfReturns ScanDirectionFlag EdgeOfFlightLine
     * Classification ScanAngleRank UserData PointSourceId GpsTime Red Green Blue. */
    size_t len;
    uint8_t *b = tu_read_data("autzen-utm.pcd", &len);
    const char *sz = strstr((char *)b, "\nSIZE ");
    assert_non_null(sz);
    int size[16], off[17] = {0};
    const char *q = sz + 6;
    for (int i = 0; i < 16; i++) {
        char *e;
        size[i] = (int)strtol(q, &e, 10);
        q = e;
        off[i + 1] = off[i] + size[i];
    }
    assert_int_equal(off[16], 52); /* 3*8 + 2 + 5*1 + 4 + 1 + 2 + 8 + 3*2 */
    size_t d0 = data_offset(b, len), n = 1065;
    assert_int_equal(d0 + n * 52, len);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    unsigned imin = 65535, imax = 0, cmax = 0, hist[256] = {0};
    for (size_t i = 0; i < n; i++) {
        const uint8_t *r = b + d0 + i * 52;
        for (int k = 0; k < 3; k++) {
            double v;
            memcpy(&v, r + off[k], 8);
            lo[k] = fmin(lo[k], v);
            hi[k] = fmax(hi[k], v);
        }
        uint16_t it;
        memcpy(&it, r + off[3], 2);
        imin = it < imin ? it : imin;
        imax = it > imax ? it : imax;
        hist[r[off[8]]]++;
        for (int k = 0; k < 3; k++) {
            uint16_t v;
            memcpy(&v, r + off[13 + k], 2);
            cmax = v > cmax ? v : cmax;
        }
    }

    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, n);
    assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_CLASS);
    assert_string_equal(c.format, "PCD 0.7 binary");
    assert_box(&c, lo, hi);
    float fmin_i = INFINITY, fmax_i = -INFINITY;
    unsigned got[256] = {0};
    for (size_t i = 0; i < c.n; i++) {
        fmin_i = fminf(fmin_i, c.intensity[i]);
        fmax_i = fmaxf(fmax_i, c.intensity[i]);
        got[c.cls[i]]++;
    }
    assert_float_equal(fmin_i, imin, 0);
    assert_float_equal(fmax_i, imax, 0);
    assert_memory_equal(got, hist, sizeof hist);
    /* Its Red Green Blue are u16 fields holding 39-249: no value needs more than 8 bits,
     * so they are kept as they are (the scaled case is test_split_rgb_16bit). */
    assert_true(cmax <= 255 && cmax > 200);
    for (size_t i = 0; i < n; i++) {
        const uint8_t *r = b + d0 + i * 52;
        for (int k = 0; k < 3; k++) {
            uint16_t v;
            memcpy(&v, r + off[13 + k], 2);
            assert_int_equal(c.rgba[4 * i + k], v);
        }
    }
    pc_cloud_free(&c);
    free(b);
}

/* ---- hand-made files: the fields and layouts the real files do not cover ---- */

static void test_ascii_fields(void **state)
{
    (void)state;
    /* Keywords in another order, CRLF, comments, a packed float rgb written both as PCL's
     * integer bit pattern and as a float, normals to be normalised, an unknown field of
     * COUNT 2, an organized 2 x 2 cloud with a NaN point. 0x00ff8040 as a float is
     * 2.34848e-38 (a denormal-free normal float: 0x00ff8040 has exponent 1). */
    float f;
    uint32_t bits = 0x00ff8040;
    memcpy(&f, &bits, 4);
    char text[1024];
    snprintf(text, sizeof text,
             "# hand made\r\nVERSION .7\r\nWIDTH 2\r\nHEIGHT 2\r\nFIELDS x y z rgb normal_x "
             "normal_y normal_z hist intensity\r\nSIZE 4 4 4 4 4 4 4 2 4\r\nTYPE F F F F F F F "
             "U F\r\nCOUNT 1 1 1 1 1 1 1 2 1\r\nVIEWPOINT 0 0 0 1 0 0 0\r\nPOINTS 4\r\nDATA "
             "ascii\r\n"
             "1 2 3 %u 0 0 2 7 8 0.5\r\n"
             "nan nan nan 0 0 0 1 1 1 1\r\n"
             "\r\n"
             "-1 -2 -3 %.9g 3 4 0 65535 0 2.5\r\n"
             "4 5 6 16711680 0 0 0 0 0 1e3\r\n",
             bits, (double)f);
    pc_cloud c;
    load_text("fields.pcd", text, &c);
    assert_int_equal(c.n, 3);
    assert_int_equal(c.n_dropped, 1);
    assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_INTENSITY);
    assert_string_equal(c.format, "PCD 0.7 ascii");
    const double lo[3] = {-1, -2, -3}, hi[3] = {4, 5, 6};
    assert_box(&c, lo, hi);
    /* 0x00ff8040: B 0x40, G 0x80, R 0xff (both spellings); 0x00ff0000: pure red. */
    const uint8_t rgba[3][4] = {{0xff, 0x80, 0x40, 255}, {0xff, 0x80, 0x40, 255},
                                {0xff, 0, 0, 255}};
    assert_memory_equal(c.rgba, rgba, sizeof rgba);
    /* Normals: (0,0,2) -> (0,0,1); (3,4,0) -> (0.6,0.8,0); (0,0,0) has no direction -> 0. */
    const float nrm[9] = {0, 0, 1, 0.6f, 0.8f, 0, 0, 0, 0};
    for (int i = 0; i < 9; i++) assert_float_equal(c.normal[i], nrm[i], 1e-6);
    assert_float_equal(c.intensity[0], 0.5, 0);
    assert_float_equal(c.intensity[1], 2.5, 0);
    assert_float_equal(c.intensity[2], 1000, 0);
    pc_cloud_free(&c);
}

/* VIEWPOINT: a pose other than PCL's identity default gives the sensor's position (prep
 * orients normals towards it); the identity says nothing; a malformed line is an error naming
 * the keyword and the line. */
static void test_viewpoint(void **state)
{
    (void)state;
    const char *fmt = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                      "WIDTH 2\nHEIGHT 1\nVIEWPOINT %s\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n";
    char text[512];
    pc_cloud c;
    snprintf(text, sizeof text, fmt, "1.5 -2 1e1 1 0 0 0");
    load_text("vp.pcd", text, &c);
    assert_int_equal(c.has_viewpoint, 1);
    assert_true(c.viewpoint[0] == 1.5 && c.viewpoint[1] == -2 && c.viewpoint[2] == 10);
    pc_cloud_free(&c);
    snprintf(text, sizeof text, fmt, "0.0 0 0 1.0 0 0 0");
    load_text("vp_identity.pcd", text, &c);
    assert_int_equal(c.has_viewpoint, 0);
    pc_cloud_free(&c);
    /* The mug was captured by a camera at the origin, its pose rotated: known. */
    char p[1024];
    tu_load_ok(tu_data("table_scene_mug_stereo_textured.pcd", p, sizeof p), &c);
    assert_int_equal(c.has_viewpoint, 1);
    assert_true(c.viewpoint[0] == 0 && c.viewpoint[1] == 0 && c.viewpoint[2] == 0);
    pc_cloud_free(&c);
    const char *bad[] = {"0 0 0 1 0 0", "0 0 x 1 0 0 0", "0 0 nan 1 0 0 0", "0 0 0 1 0 0 0 0"};
    for (int i = 0; i < 4; i++) {
        snprintf(text, sizeof text, fmt, bad[i]);
        expect_fail_bytes("vp_bad.pcd", text, strlen(text), SD_EFORMAT);
        sd_err e = {0};
        assert_int_equal(pc_load(tmp_path("vp_bad.pcd", p, sizeof p), &c, &e), SD_EFORMAT);
        assert_non_null(strstr(e.msg, "VIEWPOINT at line 8"));
    }
}

static void test_binary_types(void **state)
{
    (void)state;
    /* Binary record: x I16, y I32, z F8, red green blue U8, Classification U2, a skipped U8
     * with COUNT 3; PCD 0.5-style COLUMNS and no HEIGHT. 8-bit colours stay as they are. */
    const char *hdr = "VERSION 0.5\nCOLUMNS x y z red green blue Classification pad\n"
                      "SIZE 2 4 8 1 1 1 2 8\nTYPE I I F U U U U U\nCOUNT 1 1 1 1 1 1 1 3\n"
                      "WIDTH 2\nPOINTS 2\nDATA binary\n";
    enum { REC = 2 + 4 + 8 + 3 + 2 + 24 };
    uint8_t buf[512];
    size_t h = strlen(hdr);
    memcpy(buf, hdr, h);
    for (int i = 0; i < 2; i++) {
        uint8_t *r = buf + h + i * REC;
        int16_t x = (int16_t)(i ? -300 : 7);
        int32_t y = i ? 100000 : -5;
        double z = i ? 0.25 : -1e6;
        uint16_t cls = (uint16_t)(i ? 300 : 6); /* 300 does not fit a class byte: 255 */
        memcpy(r, &x, 2);
        memcpy(r + 2, &y, 4);
        memcpy(r + 6, &z, 8);
        r[14] = (uint8_t)(10 + i);
        r[15] = (uint8_t)(20 + i);
        r[16] = (uint8_t)(200 + i);
        memcpy(r + 17, &cls, 2);
        memset(r + 19, 0xEE, 24);
    }
    char p[1024];
    tmp_path("types.pcd", p, sizeof p);
    assert_int_equal(tu_write_file(p, buf, h + 2 * REC), 0);
    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, 2);
    assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_CLASS);
    assert_string_equal(c.format, "PCD 0.5 binary");
    const double lo[3] = {-300, -5, -1e6}, hi[3] = {7, 100000, 0.25};
    assert_box(&c, lo, hi);
    for (int i = 0; i < 2; i++) {
        assert_int_equal(c.rgba[4 * i + 0], 10 + i);
        assert_int_equal(c.rgba[4 * i + 1], 20 + i);
        assert_int_equal(c.rgba[4 * i + 2], 200 + i);
    }
    assert_int_equal(c.cls[0], 6);
    assert_int_equal(c.cls[1], 255);
    pc_cloud_free(&c);
}

static void test_split_rgb_16bit(void **state)
{
    (void)state;
    /* Separate 16-bit colours with a value above 255: all are scaled by 255/65535, rounded. */
    pc_cloud c;
    load_text("rgb16.pcd",
              "FIELDS x y z red green blue\nSIZE 4 4 4 2 2 2\nTYPE F F F U U U\nWIDTH 2\n"
              "HEIGHT 1\nPOINTS 2\nDATA ascii\n0 0 0 65535 257 0\n1 1 1 32768 100 1000\n", &c);
    assert_int_equal(c.attrs, PC_ATTR_RGB);
    const uint8_t want[8] = {255, 1, 0, 255, 128, 0, 4, 255};
    assert_memory_equal(c.rgba, want, 8);
    pc_cloud_free(&c);
}

/* ---- broken files ---- */

/* Writes the first cut bytes of real file name and expects code. */
static void expect_cut(const uint8_t *b, size_t cut, const char *tag, int code)
{
    char name[64];
    snprintf(name, sizeof name, "cut_%s_%zu.pcd", tag, cut);
    expect_fail_bytes(name, b, cut, code);
}

static void test_truncated_files(void **state)
{
    (void)state;
    static const char *const files[] = {"table_scene_mug_stereo_textured.pcd",
                                        "samp11-utm.pcd", "autzen-utm.pcd", "rops_cloud.pcd"};
    for (size_t f = 0; f < 4; f++) {
        size_t len;
        uint8_t *b = tu_read_data(files[f], &len);
        size_t d0 = data_offset(b, len);
        char tag[8];
        snprintf(tag, sizeof tag, "%zu", f);
        expect_cut(b, 0, tag, SD_ETRUNC);       /* empty file */
        expect_cut(b, 40, tag, SD_ETRUNC);      /* inside the header */
        expect_cut(b, d0 - 1, tag, SD_ETRUNC);  /* DATA line without its newline, no data */
        expect_cut(b, d0, tag, SD_ETRUNC);      /* just after the header */
        expect_cut(b, d0 + 5, tag, SD_ETRUNC);  /* inside the first record / the sizes */
        expect_cut(b, (d0 + len) / 2 + 3, tag, SD_ETRUNC); /* mid-record */
        if (f < 2) {
            /* binary_compressed: PCL leaves bytes after the LZF payload (3,901 in the mug,
             * 3,913 in samp11), so "one byte short" is one byte short of the payload's end;
             * cut exactly at that end, the file still loads. */
            uint32_t csize;
            memcpy(&csize, b + d0, 4);
            size_t end = d0 + 8 + csize;
            assert_true(end < len);
            expect_cut(b, end - 1, tag, SD_ETRUNC);
            char p[1024];
            tmp_path("payload_end.pcd", p, sizeof p);
            assert_int_equal(tu_write_file(p, b, end), 0);
            pc_cloud c;
            tu_load_ok(p, &c);
            assert_int_equal(c.n + c.n_dropped, f == 0 ? 307200 : 38010);
            pc_cloud_free(&c);
        } else if (f == 2) {
            expect_cut(b, len - 1, tag, SD_ETRUNC);  /* one byte short */
        } else {
            /* Ascii: a lost last byte only shortens a number; cut the last value instead,
             * and the whole last line. */
            size_t last = len;
            while (b[last - 1] != ' ') last--;
            expect_cut(b, last - 1, tag, SD_ETRUNC);
            while (b[last - 1] != '\n') last--;
            expect_cut(b, last, tag, SD_ETRUNC);
        }
        free(b);
    }
}

static void test_header_errors(void **state)
{
    (void)state;
    size_t len;
    uint8_t *mug = tu_read_data("table_scene_mug_stereo_textured.pcd", &len);
    uint8_t *b = malloc(len);
    char p[1024];
    size_t d0 = data_offset(mug, len);

    /* A SIZE that does not fit its TYPE names the field and the lines. */
    memcpy(b, mug, len);
    patch(b, "SIZE 4 4 4 4", "SIZE 4 2 4 4");
    expect_fail_bytes("size_type.pcd", b, len, SD_EFORMAT);
    sd_err e = {0};
    pc_cloud c;
    assert_int_equal(pc_load(tmp_path("size_type.pcd", p, sizeof p), &c, &e), SD_EFORMAT);
    assert_non_null(strstr(e.msg, "'y'"));
    assert_non_null(strstr(e.msg, "line 4"));

    memcpy(b, mug, len); /* an I field of 3 bytes */
    patch(b, "TYPE F F F U", "TYPE F F F I");
    patch(b, "SIZE 4 4 4 4", "SIZE 4 4 4 3");
    expect_fail_bytes("size_i3.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len); /* WIDTH x HEIGHT != POINTS */
    patch(b, "HEIGHT 480", "HEIGHT 479");
    expect_fail_bytes("wh.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len); /* more points than the uncompressed size holds */
    patch(b, "WIDTH 640", "WIDTH 641");
    patch(b, "POINTS 307200", "POINTS 307680");
    expect_fail_bytes("more_points.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len); /* compressed size larger than the file */
    uint32_t big = 0xFFFFFF00u;
    memcpy(b + d0, &big, 4);
    expect_fail_bytes("csize.pcd", b, len, SD_ETRUNC);

    memcpy(b, mug, len); /* uncompressed size that disagrees with POINTS x point size */
    uint32_t us;
    memcpy(&us, b + d0 + 4, 4);
    assert_int_equal(us, 307200u * 16);
    us += 16;
    memcpy(b + d0 + 4, &us, 4);
    expect_fail_bytes("usize.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len); /* a back reference as the first chunk: corrupt payload */
    b[d0 + 8] = 0xE0;
    expect_fail_bytes("lzf_bad.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len); /* an uncompressed size LZF cannot make from so few bytes */
    patch(b, "WIDTH 640", "WIDTH 1  ");
    patch(b, "HEIGHT 480", "HEIGHT 1  ");
    patch(b, "POINTS 307200", "POINTS 1     ");
    uint32_t sizes[2] = {0, 16};
    memcpy(b + d0, sizes, 8);
    expect_fail_bytes("ratio.pcd", b, len, SD_EFORMAT);

    memcpy(b, mug, len);
    patch(b, "DATA binary_compressed", "DATA binary_lz4567890x");
    expect_fail_bytes("data_kind.pcd", b, len, SD_EUNSUP);

    memcpy(b, mug, len);
    patch(b, "VERSION 0.7", "VERSION 0.9");
    expect_fail_bytes("version.pcd", b, len, SD_EUNSUP);
    free(b);
    free(mug);

    /* A PLY (wrong magic) renamed to .pcd. */
    uint8_t *ply = tu_read_data("Guanyin.ply", &len);
    expect_fail_bytes("ply.pcd", ply, len, SD_EFORMAT);
    free(ply);

    /* More points than the binary data holds (same digit count keeps the layout). */
    uint8_t *az = tu_read_data("autzen-utm.pcd", &len);
    patch(az, "WIDTH 1065", "WIDTH 1066");
    patch(az, "POINTS 1065", "POINTS 1066");
    expect_fail_bytes("az_more.pcd", az, len, SD_ETRUNC);
    free(az);
    uint8_t *rops = tu_read_data("rops_cloud.pcd", &len);
    patch(rops, "WIDTH 32087", "WIDTH 32088");
    patch(rops, "POINTS 32087", "POINTS 32088");
    expect_fail_bytes("rops_more.pcd", rops, len, SD_ETRUNC);
    patch(rops, "WIDTH 32088", "WIDTH 99999");
    patch(rops, "POINTS 32088", "POINTS 99999"); /* more than the bytes can hold at all */
    expect_fail_bytes("rops_much_more.pcd", rops, len, SD_ETRUNC);
    free(rops);

    static const char *const bad_text[][2] = {
        {"no_xyz.pcd", "FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"count_mismatch.pcd", "FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"dup.pcd", "FIELDS x y z\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"keyword.pcd", "FIELDS x y z\nSIZES 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"type.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F D\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"count0.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 0\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"},
        {"few_values.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 2\n40 50 60\n"},
        {"many_values.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 2 3 4\n4 5 6\n"},
        {"bad_value.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 2 x\n4 5 6\n"},
        {"u8_range.pcd", "FIELDS x y z c\nSIZE 4 4 4 1\nTYPE F F F U\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 2 3 256\n4 5 6 1\n"},
        {"width_big.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 99999999999\nHEIGHT 99999999999\nPOINTS 1\nDATA ascii\n1 2 3\n"},
    };
    for (size_t i = 0; i < sizeof bad_text / sizeof bad_text[0]; i++)
        expect_fail_bytes(bad_text[i][0], bad_text[i][1], strlen(bad_text[i][1]), SD_EFORMAT);

    /* Zero points: SD_EEMPTY from pc_load, for each data kind. */
    static const char *const empty[] = {
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nHEIGHT 1\nPOINTS 0\nDATA ascii\n",
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nHEIGHT 1\nPOINTS 0\nDATA binary\n",
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nHEIGHT 1\nPOINTS 0\nDATA binary_compressed\n"
        "\0\0\0\0\0\0\0\0",
    };
    for (size_t i = 0; i < 3; i++) {
        char name[32];
        snprintf(name, sizeof name, "empty%zu.pcd", i);
        expect_fail_bytes(name, empty[i], strlen(empty[i]) + (i == 2 ? 8 : 0), SD_EEMPTY);
    }
    /* All points NaN: the reader succeeds, finalize finds nothing finite. */
    const char *nan = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\nnan 0 0\n";
    tmp_path("all_nan.pcd", p, sizeof p);
    assert_int_equal(tu_write_file(p, nan, strlen(nan)), 0);
    assert_int_equal(pc_load(p, &c, &e), SD_EEMPTY);
}

static void test_garbage_headers(void **state)
{
    (void)state;
    size_t n = 10u << 20;
    char *g = malloc(n);
    /* 10 MB of comment lines: no DATA line within the header limit. */
    for (size_t i = 0; i < n; i++) g[i] = (i % 64 == 63) ? '\n' : '#';
    expect_fail_bytes("comments.pcd", g, n, SD_ELIMIT);
    /* 10 MB of one line. */
    memset(g, 'A', n);
    expect_fail_bytes("one_line.pcd", g, n, SD_ELIMIT);
    /* 10 MB of pseudo-random bytes (fixed seed): the first line is not a keyword. */
    uint32_t x = 12345;
    for (size_t i = 0; i < n; i++) {
        x = x * 1103515245u + 12345u;
        g[i] = (char)(x >> 23);
    }
    expect_fail_bytes("random.pcd", g, n, SD_EFORMAT);
    /* A valid-looking header whose FIELDS line has 5000 names. */
    size_t k = (size_t)snprintf(g, n, "FIELDS");
    for (int i = 0; i < 5000; i++) k += (size_t)snprintf(g + k, n - k, " f%d", i);
    k += (size_t)snprintf(g + k, n - k, "\nDATA ascii\n");
    expect_fail_bytes("fields5000.pcd", g, k, SD_EFORMAT);
    free(g);
}

/* ---- every TYPE/SIZE in every DATA kind, checked point by point ---- */

/* The files here are written by this test: header text, then the values one by one through
 * iotest.h's little-endian writers (ascii: printf tokens; binary: one record per point;
 * binary_compressed: each field's values for all points together, LZF-coded as literal runs
 * by pcd_lzf_literal below). Expected values are the written values themselves, or for ascii
 * the number the written token denotes at the field's type (F4: strtod rounded to float). */

enum { K_ASCII, K_BINARY, K_COMPRESSED };
static const char *const kind_name[3] = {"ascii", "binary", "binary_compressed"};

typedef struct pcd_fdef {
    const char *name;
    char type;       /* 'I', 'U' or 'F' */
    unsigned size, count;
    int packed;      /* a packed colour: u holds the 32 bits whatever the TYPE */
} pcd_fdef;

/* One value: the two's-complement bits of an integer (or a packed colour), or a float value. */
typedef struct pv {
    uint64_t u;
    double f;
} pv;

#define PF_MAX 16

/* The ascii token for value v of field f: integers in decimal, F4 with 9 and F8 with 17
 * significant digits, packed colours as PCL writes them (their 32 bits as an integer, signed
 * for TYPE I). */
static void pcd_token(char *buf, size_t len, const pcd_fdef *f, const pv *v)
{
    if (f->packed && f->type == 'I') snprintf(buf, len, "%d", (int32_t)(uint32_t)v->u);
    else if (f->packed) snprintf(buf, len, "%u", (uint32_t)v->u);
    else if (f->type == 'F') snprintf(buf, len, f->size == 4 ? "%.9g" : "%.17g", v->f);
    else if (f->type == 'U') snprintf(buf, len, "%llu", (unsigned long long)v->u);
    else snprintf(buf, len, "%lld", (long long)(int64_t)v->u);
}

/* The number a correct reader makes of value v of field f in DATA kind. */
static double pcd_expect(const pcd_fdef *f, const pv *v, int kind)
{
    if (kind == K_ASCII) {
        char tok[64];
        pcd_token(tok, sizeof tok, f, v);
        double d = strtod(tok, NULL);
        return f->type == 'F' && f->size == 4 ? (double)(float)d : d;
    }
    if (f->type == 'F') return v->f;
    if (f->type == 'U') return (double)v->u;
    return (double)(int64_t)v->u;
}

static void pcd_bytes(io_buf *b, const pcd_fdef *f, const pv *v)
{
    if (f->packed || f->type != 'F') io_put_uint(b, v->u, f->size, 0);
    else if (f->size == 4) io_put_f32(b, (float)v->f, 0);
    else io_put_f64(b, v->f, 0);
}

/* LZF as literal runs only (control byte len - 1, then up to 32 bytes): a valid LZF stream
 * that needs no compressor. */
static void pcd_lzf_literal(io_buf *out, const uint8_t *d, size_t n)
{
    for (size_t i = 0; i < n; i += 32) {
        size_t m = n - i < 32 ? n - i : 32;
        uint8_t c = (uint8_t)(m - 1);
        io_put(out, &c, 1);
        io_put(out, d + i, m);
    }
}

/* Writes a PCD of n points with the nf fields f in DATA kind to g_tmp/name; v[(i * nf + k) *
 * 4 + j] is value j of field k of point i (COUNT up to 4). Returns the path in path. */
static const char *pcd_write(const char *name, int kind, const pcd_fdef *f, size_t nf, size_t n,
                             const pv *v, char *path, size_t len)
{
    io_buf b = {0};
    io_printf(&b, "# .PCD v0.7 - written by test_io_pcd\nVERSION 0.7\nFIELDS");
    for (size_t k = 0; k < nf; k++) io_printf(&b, " %s", f[k].name);
    io_printf(&b, "\nSIZE");
    for (size_t k = 0; k < nf; k++) io_printf(&b, " %u", f[k].size);
    io_printf(&b, "\nTYPE");
    for (size_t k = 0; k < nf; k++) io_printf(&b, " %c", f[k].type);
    io_printf(&b, "\nCOUNT");
    for (size_t k = 0; k < nf; k++) io_printf(&b, " %u", f[k].count);
    io_printf(&b, "\nWIDTH %zu\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %zu\nDATA %s\n", n, n,
              kind_name[kind]);
    if (kind == K_ASCII) {
        for (size_t i = 0; i < n; i++) {
            for (size_t k = 0; k < nf; k++)
                for (unsigned j = 0; j < f[k].count; j++) {
                    char tok[64];
                    pcd_token(tok, sizeof tok, &f[k], &v[(i * nf + k) * 4 + j]);
                    io_printf(&b, "%s%s", k == 0 && j == 0 ? "" : " ", tok);
                }
            io_printf(&b, "\n");
        }
    } else if (kind == K_BINARY) {
        for (size_t i = 0; i < n; i++)
            for (size_t k = 0; k < nf; k++)
                for (unsigned j = 0; j < f[k].count; j++)
                    pcd_bytes(&b, &f[k], &v[(i * nf + k) * 4 + j]);
    } else {
        io_buf soa = {0}, z = {0};
        for (size_t k = 0; k < nf; k++)
            for (size_t i = 0; i < n; i++)
                for (unsigned j = 0; j < f[k].count; j++)
                    pcd_bytes(&soa, &f[k], &v[(i * nf + k) * 4 + j]);
        pcd_lzf_literal(&z, soa.d, soa.n);
        io_put_uint(&b, z.n, 4, 0);
        io_put_uint(&b, soa.n, 4, 0);
        io_put(&b, z.d, z.n);
        io_free(&soa);
        io_free(&z);
    }
    io_save(&b, g_tmp, name, path, len);
    io_free(&b);
    return path;
}

typedef struct pcd_type {
    char type;
    unsigned size;
} pcd_type;

static const pcd_type pcd_types[] = {{'I', 1}, {'U', 1}, {'I', 2}, {'U', 2}, {'I', 4},
                                     {'U', 4}, {'I', 8}, {'U', 8}, {'F', 4}, {'F', 8}};

/* An integer value of type t clipped to the type's range. */
static pv pcd_int_value(const pcd_type *t, int64_t x)
{
    pv v = {0, 0};
    if (t->type == 'F') {
        v.f = (double)x;
        return v;
    }
    unsigned bits = 8 * t->size;
    int64_t lo = t->type == 'U' ? 0 : bits == 64 ? INT64_MIN : -((int64_t)1 << (bits - 1));
    int64_t hi = bits == 64 ? INT64_MAX
                 : t->type == 'U' ? (int64_t)((1ull << bits) - 1) : ((int64_t)1 << (bits - 1)) - 1;
    if (x < lo) x = lo;
    if (x > hi) x = hi;
    v.u = (uint64_t)x;
    return v;
}

/* A random value over the whole range of type t: integers of every width (64-bit ones too),
 * floats of random sign with magnitudes 1e-3..1e5 (F4, rounded to float) or 1e-3..1e7 with all
 * 53 bits (F8, so reading one as F4 or through float changes it). */
static pv pcd_any(rng *r, const pcd_type *t)
{
    pv v = {0, 0};
    if (t->type == 'F') {
        double x = (2 * uni(r) - 1) * pow(10, (int)(next64(r) % (t->size == 4 ? 9 : 11)) - 3);
        v.f = t->size == 4 ? (double)(float)x : x;
        return v;
    }
    unsigned bits = 8 * t->size;
    uint64_t m = next64(r);
    if (bits < 64) m &= (1ull << bits) - 1;
    if (t->type == 'I' && bits < 64 && (m >> (bits - 1)) & 1) m |= ~0ull << bits; /* sign */
    v.u = m;
    return v;
}

enum { PR_PAD, PR_X, PR_Y, PR_Z, PR_NX, PR_NY, PR_NZ, PR_I, PR_CLS, PR_R, PR_G, PR_B, PR_TAIL,
       PR_N };

/* The matrix cloud of type t: the used fields all of type t between two skipped fields of
 * COUNT 3 and 2, so that every used field sits at an offset no single-field layout has. */
static void pcd_matrix_fields(const pcd_type *t, pcd_fdef f[PR_N])
{
    static const char *const names[PR_N] = {"pad", "x", "y", "z", "normal_x", "normal_y",
                                            "normal_z", "intensity", "classification", "red",
                                            "green", "blue", "tail"};
    for (int k = 0; k < PR_N; k++) {
        f[k] = (pcd_fdef){names[k], t->type, t->size, 1, 0};
    }
    f[PR_PAD] = (pcd_fdef){"pad", 'U', 2, 3, 0};
    f[PR_TAIL] = (pcd_fdef){"tail", 'F', 8, 2, 0};
}

#define PM_N 40

/* Checks the colours of the split red/green/blue fields: each value clamped to 0..65535; when
 * one exceeds 255, all scaled by 255/65535 to nearest. */
static void pcd_check_split_colours(const char *path, const pc_raw *raw, double want[][3],
                                    size_t n)
{
    double c16[PM_N * 3], mx = 0;
    assert_true(n <= PM_N);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double x = want[i][k];
            x = !(x > 0) ? 0 : x >= 65535 ? 65535 : floor(x + 0.5);
            c16[3 * i + k] = x;
            if (x > mx) mx = x;
        }
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) {
            double x = c16[3 * i + k];
            int w = mx > 255 ? (int)floor(x / 257.0 + 0.5) : (int)x;
            if (raw->rgba[4 * i + k] != w)
                fail_msg("%s: point %zu channel %d: read %d, want %d (written %.17g)", path, i, k,
                         raw->rgba[4 * i + k], w, want[i][k]);
        }
        assert_int_equal(raw->rgba[4 * i + 3], 255);
    }
}

/* Every TYPE/SIZE the reader accepts (I1 U1 I2 U2 I4 U4 I8 U8 F4 F8) in ascii, binary and
 * binary_compressed, for x y z, the normals, intensity, classification and split red green
 * blue, with skipped fields of COUNT > 1 around them. Point by point: positions exactly (raw
 * doubles; pos + offset after pc_load within float rounding), normals as the unit vector of
 * what was written, intensity exactly as float, classification clamped to 0..255, colours
 * (8-bit kept, wider scaled). An F8 read as F4, a field read at another size or signedness, a
 * wrong record or structure-of-arrays offset, or a value put in the wrong array fails here. */
static void test_type_matrix(void **state)
{
    (void)state;
    for (int kind = K_ASCII; kind <= K_COMPRESSED; kind++)
        for (size_t ti = 0; ti < sizeof pcd_types / sizeof pcd_types[0]; ti++) {
            const pcd_type *t = &pcd_types[ti];
            rng r = {0x9cd00 + 31u * ti + (unsigned)kind};
            pcd_fdef f[PR_N];
            pcd_matrix_fields(t, f);
            static pv v[PM_N * PR_N * 4];
            /* 8-bit colours stay 8-bit; for wider types half the files hold only 0..255 in
             * them (kept as they are), the other half up to 70000 (scaled). */
            int narrow = t->size == 1 || (ti + (size_t)kind) % 2;
            for (size_t i = 0; i < PM_N; i++)
                for (int k = 0; k < PR_N; k++)
                    for (unsigned j = 0; j < f[k].count; j++) {
                        pv *x = &v[(i * PR_N + k) * 4 + j];
                        pcd_type ft = {f[k].type, f[k].size};
                        if (k == PR_CLS) *x = pcd_int_value(t, (int64_t)(next64(&r) % 301) - 20);
                        else if (k >= PR_R && k <= PR_B)
                            *x = pcd_int_value(t, narrow ? (int64_t)(next64(&r) % 256)
                                                         : (int64_t)(next64(&r) % 70101) - 100);
                        else *x = pcd_any(&r, &ft);
                    }
            char name[64], path[1024];
            snprintf(name, sizeof name, "mx_%s_%c%u.pcd", kind_name[kind], t->type, t->size);
            pcd_write(name, kind, f, PR_N, PM_N, v, path, sizeof path);

            double xyz[3 * PM_N], col[PM_N][3];
            pc_raw raw;
            io_read_ok(pc_read_pcd, path, &raw);
            assert_int_equal(raw.attrs, PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_INTENSITY |
                                            PC_ATTR_CLASS);
            for (size_t i = 0; i < PM_N; i++) {
                double e[PR_N];
                for (int k = 0; k < PR_N; k++)
                    e[k] = pcd_expect(&f[k], &v[(i * PR_N + k) * 4], kind);
                for (int k = 0; k < 3; k++) {
                    xyz[3 * i + k] = e[PR_X + k];
                    col[i][k] = e[PR_R + k];
                }
                double l = sqrt(e[PR_NX] * e[PR_NX] + e[PR_NY] * e[PR_NY] + e[PR_NZ] * e[PR_NZ]);
                for (int k = 0; k < 3; k++) {
                    double w = l > 0 ? e[PR_NX + k] / l : 0;
                    if (!(fabs(raw.normal[3 * i + k] - w) <= 2e-6))
                        fail_msg("%s: point %zu normal %d: read %.9g, want %.9g", path, i, k,
                                 raw.normal[3 * i + k], w);
                }
                if (raw.intensity[i] != (float)e[PR_I])
                    fail_msg("%s: point %zu intensity: read %.9g, want %.9g", path, i,
                             raw.intensity[i], (float)e[PR_I]);
                int wc = !(e[PR_CLS] > 0) ? 0 : e[PR_CLS] >= 255 ? 255 : (int)e[PR_CLS];
                if (raw.cls[i] != wc)
                    fail_msg("%s: point %zu class: read %d, want %d", path, i, raw.cls[i], wc);
            }
            io_check_raw_xyz(&raw, xyz, PM_N, 0, path);
            pcd_check_split_colours(path, &raw, col, PM_N);
            pc_raw_free(&raw);
            pc_cloud c;
            tu_load_ok(path, &c);
            io_check_cloud_xyz(&c, xyz, PM_N, 0, path);
            pc_cloud_free(&c);
        }
}

/* Packed colours (rgb/rgba, SIZE 4, TYPE F, U or I: PCL's B G R A from the low byte) in every
 * DATA kind, with F8 positions, next to a skipped field: every point's R G B are bytes 2, 1, 0
 * of the 32 bits written, alpha 255. */
static void test_packed_colour_matrix(void **state)
{
    (void)state;
    static const pcd_fdef packed[3] = {{"rgb", 'F', 4, 1, 1}, {"rgba", 'U', 4, 1, 1},
                                       {"rgb", 'I', 4, 1, 1}};
    for (int kind = K_ASCII; kind <= K_COMPRESSED; kind++)
        for (int p = 0; p < 3; p++) {
            const pcd_fdef f[5] = {{"x", 'F', 8, 1, 0}, {"y", 'F', 8, 1, 0}, packed[p],
                                   {"skip", 'I', 2, 3, 0}, {"z", 'F', 8, 1, 0}};
            rng r = {0x7ac4 + 3u * (unsigned)kind + (unsigned)p};
            pv v[PM_N * 5 * 4];
            const pcd_type f8 = {'F', 8}, i2 = {'I', 2};
            for (size_t i = 0; i < PM_N; i++)
                for (int k = 0; k < 5; k++)
                    for (unsigned j = 0; j < f[k].count; j++) {
                        pv *x = &v[(i * 5 + k) * 4 + j];
                        if (k == 2) {
                            x->u = (uint32_t)next64(&r);
                            /* Keep F bit patterns away from NaN so that the ascii integer
                             * spelling is what PCL itself would print. */
                            if (f[k].type == 'F') x->u &= 0x7f7fffffu;
                        } else {
                            *x = pcd_any(&r, k == 3 ? &i2 : &f8);
                        }
                    }
            char name[64], path[1024];
            snprintf(name, sizeof name, "packed_%s_%c.pcd", kind_name[kind], f[2].type);
            pcd_write(name, kind, f, 5, PM_N, v, path, sizeof path);
            pc_raw raw;
            io_read_ok(pc_read_pcd, path, &raw);
            assert_int_equal(raw.attrs, PC_ATTR_RGB);
            double xyz[3 * PM_N];
            for (size_t i = 0; i < PM_N; i++) {
                const int at[3] = {0, 1, 4};
                for (int k = 0; k < 3; k++)
                    xyz[3 * i + k] = pcd_expect(&f[at[k]], &v[(i * 5 + at[k]) * 4], kind);
                uint32_t bits = (uint32_t)v[(i * 5 + 2) * 4].u;
                const int w[4] = {(int)(bits >> 16) & 255, (int)(bits >> 8) & 255,
                                  (int)bits & 255, 255};
                for (int k = 0; k < 4; k++)
                    if (raw.rgba[4 * i + k] != w[k])
                        fail_msg("%s: point %zu channel %d: read %d, want %d (bits 0x%08x)",
                                 path, i, k, raw.rgba[4 * i + k], w[k], bits);
            }
            io_check_raw_xyz(&raw, xyz, PM_N, 0, path);
            pc_raw_free(&raw);
        }
}

/* ---- real files, every point ---- */

/* An LZF decoder written for this test from the format's description (control byte < 32: a
 * literal run of c + 1 bytes; else a back reference of length c >> 5 (7: plus the next byte)
 * + 2 at distance ((c & 31) << 8 | next byte) + 1). Returns the bytes written. */
static size_t ref_lzf(const uint8_t *in, size_t n, uint8_t *out, size_t cap)
{
    size_t i = 0, o = 0;
    while (i < n) {
        unsigned c = in[i++];
        if (c < 32) {
            size_t m = c + 1;
            assert_true(i + m <= n && o + m <= cap);
            memcpy(out + o, in + i, m);
            i += m;
            o += m;
            continue;
        }
        size_t m = c >> 5;
        if (m == 7) {
            assert_true(i < n);
            m += in[i++];
        }
        assert_true(i < n);
        size_t back = ((size_t)(c & 31) << 8 | in[i++]) + 1;
        m += 2;
        assert_true(back <= o && o + m <= cap);
        for (size_t k = 0; k < m; k++, o++) out[o] = out[o - back];
    }
    return o;
}

/* Decodes the binary_compressed body of a real file whose fields are all 4 bytes and COUNT 1
 * (the mug: x y z rgba; samp11: x y z) with ref_lzf; returns the n * nf * 4 bytes, field by
 * field. */
static uint8_t *ref_compressed(const uint8_t *b, size_t len, size_t n, size_t nf)
{
    size_t d0 = data_offset(b, len);
    uint32_t csize = (uint32_t)io_get_uint(b + d0, 4, 0);
    uint32_t usize = (uint32_t)io_get_uint(b + d0 + 4, 4, 0);
    assert_int_equal(usize, n * nf * 4);
    assert_true(d0 + 8 + csize <= len);
    uint8_t *u = malloc(usize);
    assert_non_null(u);
    assert_int_equal(ref_lzf(b + d0 + 8, csize, u, usize), usize);
    return u;
}

/* Compares raw with n reference points (NaN where the file has NaN) and pc_load's cloud with
 * the finite ones, in order. */
static void check_real_xyz(const char *path, const pc_raw *raw, const double *want, size_t n)
{
    assert_int_equal(raw->n, n);
    double *fin = malloc(3 * n * sizeof *fin);
    assert_non_null(fin);
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        int finite = 1;
        for (int k = 0; k < 3; k++) {
            double w = want[3 * i + k], g = raw->xyz[3 * i + k];
            if (isnan(w) ? !isnan(g) : g != w)
                fail_msg("%s: point %zu axis %c: read %.17g, file %.17g", path, i, "xyz"[k], g, w);
            finite &= isfinite(w);
        }
        if (finite) memcpy(fin + 3 * m++, want + 3 * i, 3 * sizeof *fin);
    }
    pc_cloud c;
    tu_load_ok(path, &c);
    assert_int_equal(c.n_dropped, n - m);
    io_check_cloud_xyz(&c, fin, m, 0, path);
    pc_cloud_free(&c);
    free(fin);
}

/* The mug: all 307,200 points decoded here (ref_lzf, then x, y, z and rgba blocks of float32 /
 * uint32 one after another): positions exactly, NaN where the file has NaN, and the colour
 * bytes of every point. */
static void test_mug_every_point(void **state)
{
    (void)state;
    char p[1024];
    tu_data("table_scene_mug_stereo_textured.pcd", p, sizeof p);
    size_t len, n = 307200;
    uint8_t *b = tu_read_data("table_scene_mug_stereo_textured.pcd", &len);
    assert_non_null(strstr((char *)b, "\nFIELDS x y z rgba\nSIZE 4 4 4 4\nTYPE F F F U\n"));
    uint8_t *u = ref_compressed(b, len, n, 4);
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) want[3 * i + k] = io_get_f32(u + 4 * ((size_t)k * n + i), 0);
    pc_raw raw;
    io_read_ok(pc_read_pcd, p, &raw);
    for (size_t i = 0; i < n; i++) {
        const uint8_t *c = u + 4 * (3 * n + i);
        const uint8_t w[4] = {c[2], c[1], c[0], 255};
        if (memcmp(raw.rgba + 4 * i, w, 4) != 0) fail_msg("mug: point %zu colour differs", i);
    }
    check_real_xyz(p, &raw, want, n);
    pc_raw_free(&raw);
    free(want);
    free(u);
    free(b);
}

/* samp11-utm.pcd: all 38,010 points decoded here (float32 x, y, z blocks), exactly. */
static void test_samp11_every_point(void **state)
{
    (void)state;
    char p[1024];
    tu_data("samp11-utm.pcd", p, sizeof p);
    size_t len, n = 38010;
    uint8_t *b = tu_read_data("samp11-utm.pcd", &len);
    assert_non_null(strstr((char *)b, "\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"));
    uint8_t *u = ref_compressed(b, len, n, 3);
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) want[3 * i + k] = io_get_f32(u + 4 * ((size_t)k * n + i), 0);
    pc_raw raw;
    io_read_ok(pc_read_pcd, p, &raw);
    check_real_xyz(p, &raw, want, n);
    pc_raw_free(&raw);
    free(want);
    free(u);
    free(b);
}

/* rops_cloud.pcd: all 32,087 lines parsed here with strtod; the fields are F4, so each value
 * must be strtod's number rounded to float, exactly. */
static void test_rops_every_point(void **state)
{
    (void)state;
    char p[1024];
    tu_data("rops_cloud.pcd", p, sizeof p);
    size_t len, n = 32087;
    uint8_t *b = tu_read_data("rops_cloud.pcd", &len);
    assert_non_null(strstr((char *)b, "\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"));
    char *s = (char *)b + data_offset(b, len);
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            char *e;
            want[3 * i + k] = (float)strtod(s, &e);
            assert_true(e > s);
            s = e;
        }
    while (*s == ' ' || *s == '\n' || *s == '\r') s++;
    assert_int_equal(*s, 0); /* nothing after the last point */
    pc_raw raw;
    io_read_ok(pc_read_pcd, p, &raw);
    check_real_xyz(p, &raw, want, n);
    pc_raw_free(&raw);
    free(want);
    free(b);
}

/* autzen-utm.pcd: all 1,065 records of 52 bytes decoded here: X Y Z float64 exactly,
 * Intensity u16 exactly, Classification u8 exactly, per point. */
static void test_autzen_every_point(void **state)
{
    (void)state;
    char p[1024];
    tu_data("autzen-utm.pcd", p, sizeof p);
    size_t len, n = 1065;
    uint8_t *b = tu_read_data("autzen-utm.pcd", &len);
    assert_non_null(strstr((char *)b, "\nSIZE 8 8 8 2 1 1 1 1 1 4 1 2 8 2 2 2\n"));
    size_t d0 = data_offset(b, len);
    assert_int_equal(d0 + 52 * n, len);
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    pc_raw raw;
    io_read_ok(pc_read_pcd, p, &raw);
    for (size_t i = 0; i < n; i++) {
        const uint8_t *r = b + d0 + 52 * i;
        for (int k = 0; k < 3; k++) want[3 * i + k] = io_get_f64(r + 8 * k, 0);
        assert_true(raw.intensity[i] == (float)io_get_uint(r + 24, 2, 0));
        assert_int_equal(raw.cls[i], r[30]);
    }
    check_real_xyz(p, &raw, want, n);
    pc_raw_free(&raw);
    free(want);
    free(b);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_lzf_literal),
        cmocka_unit_test(test_lzf_back_reference),
        cmocka_unit_test(test_lzf_long_back_reference),
        cmocka_unit_test(test_lzf_overruns),
        cmocka_unit_test(test_mug_compressed_rgba),
        cmocka_unit_test(test_samp11_compressed_utm),
        cmocka_unit_test(test_rops_ascii),
        cmocka_unit_test(test_autzen_binary),
        cmocka_unit_test(test_ascii_fields),
        cmocka_unit_test(test_viewpoint),
        cmocka_unit_test(test_binary_types),
        cmocka_unit_test(test_split_rgb_16bit),
        cmocka_unit_test(test_truncated_files),
        cmocka_unit_test(test_header_errors),
        cmocka_unit_test(test_garbage_headers),
        cmocka_unit_test(test_type_matrix),
        cmocka_unit_test(test_packed_colour_matrix),
        cmocka_unit_test(test_mug_every_point),
        cmocka_unit_test(test_samp11_every_point),
        cmocka_unit_test(test_rops_every_point),
        cmocka_unit_test(test_autzen_every_point),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
