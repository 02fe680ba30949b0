/* test_io_las.c — the LAS reader (server/io_las.c).
 *
 * Real files go through pc_load so that finalisation runs. Expected values come from outside
 * the reader: the header's bounding box read here with a few freads, a plain scan of the
 * point records written in this file, and the counts of tests/data/SOURCES.md (independent
 * readers: @loaders.gl/las for 1.2, laspy for 1.4). Hand-made files cover the point formats
 * the real ones do not; broken files must give the right code and a message naming the file
 * and the byte offset.
 *
 * Point by point: every point of both real files against X * scale + offset computed here
 * from the records read at the offset to point data; and every point format 0-10 written here
 * (iotest.h's byte writers) with non-zero offsets and distinct scales on all three axes and
 * coordinates that need double precision. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cloud.h"
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

/* Writes len bytes to a temporary file name and expects code from pc_load, with a message
 * naming the file and a byte offset. Returns the message (static) for further checks. */
static const char *expect_fail_bytes(const char *name, const void *data, size_t len, int code)
{
    static sd_err e;
    char p[1024];
    snprintf(p, sizeof p, "%s/%s", g_tmp, name);
    assert_int_equal(tu_write_file(p, data, len), 0);
    pc_cloud c;
    memset(&e, 0, sizeof e);
    int rc = pc_load(p, &c, &e);
    if (rc != code || e.code != code)
        fail_msg("%s: got %d (%s), expected %d; message: %s", p, rc, sd_strerror(rc), code,
                 e.msg);
    if (!strstr(e.msg, p) || !strstr(e.msg, "offset"))
        fail_msg("message lacks the file name or the offset: %s", e.msg);
    assert_null(c.pos);
    return e.msg;
}

/* The header's bounding box, read with plain freads: max x, min x, max y, min y, max z,
 * min z at byte 179. */
static void header_box(const char *name, double lo[3], double hi[3])
{
    char p[1024];
    FILE *f = fopen(tu_data(name, p, sizeof p), "rb");
    assert_non_null(f);
    assert_int_equal(fseek(f, 179, SEEK_SET), 0);
    for (int k = 0; k < 3; k++) {
        assert_int_equal(fread(&hi[k], 8, 1, f), 1);
        assert_int_equal(fread(&lo[k], 8, 1, f), 1);
    }
    fclose(f);
}

/* Bounding boxes agree to 1e-3 of the extent on each axis: the header's values are rounded
 * to the scale (0.01 or 0.001), far below that; a wrong scale, offset or field is far above. */
static void assert_box(const pc_cloud *c, const double lo[3], const double hi[3])
{
    for (int k = 0; k < 3; k++) {
        double tol = 1e-3 * (hi[k] - lo[k]);
        if (fabs(c->bmin[k] - lo[k]) > tol || fabs(c->bmax[k] - hi[k]) > tol)
            fail_msg("axis %d: box [%.9g, %.9g], expected [%.9g, %.9g] (tolerance %g)", k,
                     c->bmin[k], c->bmax[k], lo[k], hi[k], tol);
    }
}

static uint16_t get16(const uint8_t *p) { uint16_t v; memcpy(&v, p, 2); return v; }
static uint32_t get32(const uint8_t *p) { uint32_t v; memcpy(&v, p, 4); return v; }
static double getd(const uint8_t *p) { double v; memcpy(&v, p, 8); return v; }

/* ---- real files ---- */

static void test_autzen_trim(void **state)
{
    (void)state;
    char p[1024];
    tu_data("autzen_trim.las", p, sizeof p);
    double hlo[3], hhi[3];
    header_box("autzen_trim.las", hlo, hhi);

    /* Independent scan of the format 3 records (34 bytes: XYZ int32, intensity u16, return
     * byte, class byte, scan angle, user data, source id u16, GPS time f64, RGB u16 x 3). */
    size_t len;
    uint8_t *b = tu_read_data("autzen_trim.las", &len);
    uint32_t off = get32(b + 96), n = get32(b + 107);
    assert_int_equal(b[104], 3);
    assert_int_equal(get16(b + 105), 34);
    assert_int_equal((size_t)off + (size_t)n * 34, len);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    unsigned imin = 65535, imax = 0, cmax = 0, hist[32] = {0};
    for (uint32_t i = 0; i < n; i++) {
        const uint8_t *r = b + off + (size_t)i * 34;
        for (int k = 0; k < 3; k++) {
            int32_t v;
            memcpy(&v, r + 4 * k, 4);
            double x = v * getd(b + 131 + 8 * k) + getd(b + 155 + 8 * k);
            lo[k] = fmin(lo[k], x);
            hi[k] = fmax(hi[k], x);
        }
        unsigned it = get16(r + 12);
        imin = it < imin ? it : imin;
        imax = it > imax ? it : imax;
        hist[r[15] & 31]++;
        for (int k = 0; k < 3; k++) cmax = get16(r + 28 + 2 * k) > cmax ? get16(r + 28 + 2 * k) : cmax;
    }

    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, 110000);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_CLASS);
    assert_string_equal(c.format, "LAS 1.2 format 3");
    assert_box(&c, hlo, hhi);
    assert_box(&c, lo, hi);
    /* SOURCES.md (@loaders.gl/las): classes {1: 83,893, 2: 26,107}, intensity 0-254,
     * RGB 0-236 in 16-bit fields; the scan above must agree, and so must the reader. */
    assert_int_equal(hist[1], 83893);
    assert_int_equal(hist[2], 26107);
    assert_int_equal(imin, 0);
    assert_int_equal(imax, 254);
    assert_int_equal(cmax, 236);
    unsigned got[256] = {0};
    float fmin_i = INFINITY, fmax_i = -INFINITY;
    for (size_t i = 0; i < c.n; i++) {
        got[c.cls[i]]++;
        fmin_i = fminf(fmin_i, c.intensity[i]);
        fmax_i = fmaxf(fmax_i, c.intensity[i]);
        /* Colours that fit in 8 bits are not scaled: the same values, point by point. */
        const uint8_t *r = b + off + i * 34;
        for (int k = 0; k < 3; k++) assert_int_equal(c.rgba[4 * i + k], get16(r + 28 + 2 * k));
        assert_int_equal(c.rgba[4 * i + 3], 255);
    }
    assert_int_equal(got[1], 83893);
    assert_int_equal(got[2], 26107);
    assert_int_equal(got[1] + got[2], c.n);
    assert_float_equal(fmin_i, 0, 0);
    assert_float_equal(fmax_i, 254, 0);
    pc_cloud_free(&c);
    free(b);
}

static void test_las14_format6(void **state)
{
    (void)state;
    char p[1024];
    tu_data("file_with_both_wkt_and_geotiff_vlrs.las", p, sizeof p);
    double hlo[3], hhi[3];
    header_box("file_with_both_wkt_and_geotiff_vlrs.las", hlo, hhi);
    pc_cloud c;
    tu_load_ok(p, &c);
    /* SOURCES.md (laspy): 25,408 points (legacy count 0, 64-bit count at byte 247), classes
     * {2: 9,808, 3: 158, 4: 724, 5: 10,956, 6: 3,737, 7: 25}, intensity 996-57,345. */
    assert_int_equal(c.n, 25408);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, PC_ATTR_INTENSITY | PC_ATTR_CLASS);
    assert_string_equal(c.format, "LAS 1.4 format 6");
    assert_box(&c, hlo, hhi);
    unsigned got[256] = {0};
    float fmin_i = INFINITY, fmax_i = -INFINITY;
    for (size_t i = 0; i < c.n; i++) {
        got[c.cls[i]]++;
        fmin_i = fminf(fmin_i, c.intensity[i]);
        fmax_i = fmaxf(fmax_i, c.intensity[i]);
    }
    const unsigned want[8] = {0, 0, 9808, 158, 724, 10956, 3737, 25};
    for (int k = 0; k < 8; k++) assert_int_equal(got[k], want[k]);
    assert_float_equal(fmin_i, 996, 0);
    assert_float_equal(fmax_i, 57345, 0);
    /* The coordinates keep their precision: the offset (2,445,000 / 603,000) is removed
     * exactly in double, and a float32 position relative to the centre of a ~60 m box is
     * within 1e-5 m of the 1 mm grid. */
    for (size_t i = 0; i < c.n; i += 997) {
        double x = c.pos[3 * i] + c.offset[0];
        assert_true(fabs(x * 1000 - round(x * 1000)) < 1e-2);
    }
    pc_cloud_free(&c);
}

/* ---- hand-made files: formats and layouts the real files do not cover ---- */

/* Writes a LAS header for version 1.minor into b (zeroed, hsize bytes) with the given format,
 * record length, count, scales 0.01, 0.02, 0.001 (different, so that a mixed-up axis shows)
 * and offsets 1000, 2000, 0; returns the header size. */
static size_t las_header(uint8_t *b, unsigned minor, unsigned fmt, uint16_t reclen, uint32_t n)
{
    uint16_t hsize = (uint16_t)(minor == 4 ? 375 : minor == 3 ? 235 : 227);
    memset(b, 0, hsize);
    memcpy(b, "LASF", 4);
    b[24] = 1;
    b[25] = (uint8_t)minor;
    memcpy(b + 94, &hsize, 2);
    uint32_t off = hsize;
    memcpy(b + 96, &off, 4);
    b[104] = (uint8_t)fmt;
    memcpy(b + 105, &reclen, 2);
    if (minor == 4 && fmt >= 6) {
        uint64_t n64 = n;
        memcpy(b + 247, &n64, 8);
    } else {
        memcpy(b + 107, &n, 4);
    }
    const double scale[3] = {0.01, 0.02, 0.001}, offset[3] = {1000, 2000, 0};
    memcpy(b + 131, scale, 24);
    memcpy(b + 155, offset, 24);
    return hsize;
}

static void put_xyz(uint8_t *r, int32_t x, int32_t y, int32_t z)
{
    memcpy(r, &x, 4);
    memcpy(r + 4, &y, 4);
    memcpy(r + 8, &z, 4);
}

static void test_format7_extra_bytes_16bit_rgb(void **state)
{
    (void)state;
    /* LAS 1.4 format 7 (36 bytes) with 4 extra bytes per record: class is all of byte 16,
     * RGB at byte 30; one colour above 255 makes all of them scale by 255/65535. */
    uint8_t b[375 + 3 * 40];
    size_t h = las_header(b, 4, 7, 40, 3);
    const uint16_t rgb[3][3] = {{65535, 0, 32768}, {257, 514, 1000}, {0, 65535, 128}};
    for (int i = 0; i < 3; i++) {
        uint8_t *r = b + h + 40 * i;
        memset(r, 0xAB, 40); /* garbage in the unused fields and the extra bytes */
        put_xyz(r, 100 * i, -50 * i, 7 * i);
        uint16_t it = (uint16_t)(1000 + i);
        memcpy(r + 12, &it, 2);
        r[15] = 0xFF;                 /* flags: must not leak into the class */
        r[16] = (uint8_t)(40 + i);    /* classes above 31 exist only in formats 6-10 */
        memcpy(r + 30, rgb[i], 6);
    }
    char p[1024];
    snprintf(p, sizeof p, "%s/f7.las", g_tmp);
    assert_int_equal(tu_write_file(p, b, sizeof b), 0);
    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, 3);
    assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_CLASS);
    assert_string_equal(c.format, "LAS 1.4 format 7");
    const double lo[3] = {1000, 1998, 0}, hi[3] = {1002, 2000, 0.014};
    assert_box(&c, lo, hi);
    for (int i = 0; i < 3; i++) {
        assert_int_equal(c.cls[i], 40 + i);
        assert_float_equal(c.intensity[i], 1000 + i, 0);
        for (int k = 0; k < 3; k++) /* within 1 of v * 255 / 65535 */
            assert_true(fabs(c.rgba[4 * i + k] - rgb[i][k] * 255.0 / 65535.0) <= 0.5 + 1e-9);
    }
    pc_cloud_free(&c);
}

static void test_legacy_formats(void **state)
{
    (void)state;
    /* LAS 1.0 format 0 (class in the low 5 bits of byte 15), LAS 1.3 format 1 with extra
     * bytes, LAS 1.2 format 2 (RGB right after the 20 base bytes), 1.4 formats 8-10. */
    static const struct { unsigned minor, fmt, reclen, rgb, cls; } cases[] = {
        {0, 0, 20, 0, 15}, {3, 1, 31, 0, 15}, {2, 2, 26, 20, 15}, {1, 4, 57, 0, 15},
        {2, 5, 63, 28, 15}, {4, 6, 30, 0, 16}, {4, 8, 38, 30, 16}, {4, 9, 59, 0, 16},
        {4, 10, 67, 30, 16},
    };
    for (size_t t = 0; t < sizeof cases / sizeof cases[0]; t++) {
        uint8_t b[400 + 2 * 70];
        unsigned rl = cases[t].reclen;
        size_t h = las_header(b, cases[t].minor, cases[t].fmt, (uint16_t)rl, 2);
        for (int i = 0; i < 2; i++) {
            uint8_t *r = b + h + rl * i;
            memset(r, 0, rl);
            put_xyz(r, 5 * i, 6 * i, -7 * i);
            if (cases[t].cls == 15) r[15] = (uint8_t)(0xE0 | (2 + i)); /* flag bits set */
            else r[16] = (uint8_t)(2 + i);
            if (cases[t].rgb) {
                const uint16_t c3[3] = {10, (uint16_t)(20 + i), 255};
                memcpy(r + cases[t].rgb, c3, 6);
            }
        }
        char p[1024];
        snprintf(p, sizeof p, "%s/fmt%u.las", g_tmp, cases[t].fmt);
        assert_int_equal(tu_write_file(p, b, h + 2 * rl), 0);
        pc_cloud c;
        tu_load_ok(p, &c);
        assert_int_equal(c.n, 2);
        char want[32];
        snprintf(want, sizeof want, "LAS 1.%u format %u", cases[t].minor, cases[t].fmt);
        assert_string_equal(c.format, want);
        const double lo[3] = {1000, 2000, -0.007}, hi[3] = {1000.05, 2000.12, 0};
        assert_box(&c, lo, hi);
        assert_int_equal(c.cls[0], 2);
        assert_int_equal(c.cls[1], 3);
        assert_int_equal(!!(c.attrs & PC_ATTR_RGB), !!cases[t].rgb);
        if (cases[t].rgb) { /* all fit in 8 bits: unscaled */
            assert_int_equal(c.rgba[0], 10);
            assert_int_equal(c.rgba[5], 21);
            assert_int_equal(c.rgba[6], 255);
        }
        pc_cloud_free(&c);
    }
}

/* ---- broken files ---- */

static void set16(uint8_t *b, size_t at, uint16_t v) { memcpy(b + at, &v, 2); }
static void set32(uint8_t *b, size_t at, uint32_t v) { memcpy(b + at, &v, 4); }
static void set64(uint8_t *b, size_t at, uint64_t v) { memcpy(b + at, &v, 8); }

static void test_truncated(void **state)
{
    (void)state;
    static const char *const files[] = {"autzen_trim.las",
                                        "file_with_both_wkt_and_geotiff_vlrs.las"};
    for (int f = 0; f < 2; f++) {
        size_t len;
        uint8_t *b = tu_read_data(files[f], &len);
        size_t hsize = get16(b + 94), off = get32(b + 96), rl = get16(b + 105);
        const size_t cuts[] = {0, 3, 100, 226, hsize - 1, hsize, off - 1, off, off + 7,
                               off + rl * 1000 + rl / 2, len - 1};
        for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++) {
            char name[64];
            snprintf(name, sizeof name, "cut%d_%zu.las", f, cuts[i]);
            expect_fail_bytes(name, b, cuts[i], SD_ETRUNC);
        }
        free(b);
    }
}

static void test_header_errors(void **state)
{
    (void)state;
    size_t len;
    uint8_t *orig = tu_read_data("autzen_trim.las", &len);
    uint8_t *b = malloc(len);
    const char *msg;

    /* One point more than the data holds: the message names count, record length, size. */
    memcpy(b, orig, len);
    set32(b, 107, 110001);
    msg = expect_fail_bytes("count.las", b, len, SD_ETRUNC);
    assert_non_null(strstr(msg, "110001"));
    assert_non_null(strstr(msg, " 34 "));
    assert_non_null(strstr(msg, "3742038"));

    memcpy(b, orig, len);
    set32(b, 107, 0xFFFFFFFFu);
    expect_fail_bytes("count_max.las", b, len, SD_ETRUNC);

    memcpy(b, orig, len);
    memcpy(b, "LASG", 4);
    expect_fail_bytes("magic.las", b, len, SD_EFORMAT);

    memcpy(b, orig, len);
    b[25] = 5;
    msg = expect_fail_bytes("v15.las", b, len, SD_EUNSUP);
    assert_non_null(strstr(msg, "1.5"));
    memcpy(b, orig, len);
    b[24] = 2;
    b[25] = 0;
    msg = expect_fail_bytes("v20.las", b, len, SD_EUNSUP);
    assert_non_null(strstr(msg, "2.0"));

    memcpy(b, orig, len);
    b[104] = 11;
    expect_fail_bytes("fmt11.las", b, len, SD_EUNSUP);
    memcpy(b, orig, len);
    b[104] = 0x83; /* LAZ: format 3 with the compression bit, read by the LAZ reader */
    msg = expect_fail_bytes("laz.las", b, len, SD_EFORMAT);
    assert_non_null(strstr(msg, "laszip encoded"));
    memcpy(b, orig, len);
    b[104] = 0x43;
    expect_fail_bytes("laz6.las", b, len, SD_EFORMAT);

    memcpy(b, orig, len);
    set16(b, 105, 33); /* shorter than format 3's 34 bytes */
    expect_fail_bytes("reclen.las", b, len, SD_EFORMAT);

    memcpy(b, orig, len);
    set16(b, 94, 60000); /* absurd header size */
    expect_fail_bytes("hsize.las", b, len, SD_EFORMAT);
    memcpy(b, orig, len);
    set16(b, 94, 100); /* below the 227 bytes of a 1.2 header */
    expect_fail_bytes("hsize_small.las", b, len, SD_EFORMAT);
    memcpy(b, orig, len);
    set32(b, 96, 0xFFFFFFF0u); /* offset to point data past the end */
    expect_fail_bytes("dataoff.las", b, len, SD_ETRUNC);
    memcpy(b, orig, len);
    set32(b, 96, 100); /* offset to point data inside the header */
    expect_fail_bytes("dataoff_small.las", b, len, SD_EFORMAT);

    memcpy(b, orig, len);
    double zero = 0, nan = NAN;
    memcpy(b + 139, &zero, 8);
    expect_fail_bytes("scale0.las", b, len, SD_EFORMAT);
    memcpy(b, orig, len);
    memcpy(b + 171, &nan, 8);
    expect_fail_bytes("offnan.las", b, len, SD_EFORMAT);

    memcpy(b, orig, len);
    set32(b, 107, 0); /* zero points: SD_EEMPTY from pc_load */
    expect_fail_bytes("zero.las", b, len, SD_EEMPTY);
    free(b);
    free(orig);

    /* LAS 1.4: the 64-bit count. */
    orig = tu_read_data("file_with_both_wkt_and_geotiff_vlrs.las", &len);
    b = malloc(len);
    memcpy(b, orig, len);
    set64(b, 247, 25409);
    expect_fail_bytes("count14.las", b, len, SD_ETRUNC);
    memcpy(b, orig, len);
    set64(b, 247, UINT64_MAX / 2); /* no overflow in offset + count x length */
    expect_fail_bytes("count14_huge.las", b, len, SD_ETRUNC);
    memcpy(b, orig, len);
    set64(b, 247, 0);
    expect_fail_bytes("zero14.las", b, len, SD_EEMPTY);
    memcpy(b, orig, len);
    set16(b, 94, 300); /* a 1.4 header is 375 bytes */
    expect_fail_bytes("hsize14.las", b, len, SD_EFORMAT);
    free(b);
    free(orig);

    /* A PCD renamed to .las. */
    orig = tu_read_data("rops_cloud.pcd", &len);
    expect_fail_bytes("pcd.las", orig, len, SD_EFORMAT);
    free(orig);
}

/* ---- every point format with non-zero offsets and distinct scales, point by point ---- */

/* The synthetic LAS files here are written field by field with iotest.h's little-endian
 * writers, from the ASPRS LAS 1.4 specification's tables (R15, sections 2.4 and 2.6-2.16):
 * the public header (227 bytes in 1.0-1.2, 235 in 1.3, 375 in 1.4), one variable length record
 * before the points (so the offset to point data is not the header size), and point records
 * whose fields the reader does not use are random bytes, so a field read at the wrong place
 * shows. Expected coordinates are X * scale + offset computed here in double. */

/* Record length and RGB position (0: none) of each point format, from the specification. */
static const struct { unsigned len, rgb; } spec_formats[11] = {
    {20, 0}, {28, 0}, {26, 20}, {34, 28}, {57, 0}, {63, 28},
    {30, 0}, {36, 30}, {38, 30}, {59, 0}, {67, 30},
};

typedef struct las_pt {
    int32_t X[3];
    uint16_t intensity;
    uint8_t cls;       /* 0-31 for formats 0-5, 0-255 for 6-10 */
    uint16_t rgb[3];
} las_pt;

typedef struct las_spec {
    unsigned minor, fmt, extra; /* version 1.minor, point format, extra bytes per record */
    double scale[3], offset[3];
} las_spec;

/* Puts the low size bytes of v at t, least significant first (LAS is little-endian). */
static void le_at(uint8_t *t, uint64_t v, unsigned size)
{
    for (unsigned i = 0; i < size; i++) t[i] = (uint8_t)(v >> (8 * i));
}

/* Writes the file of spec s with the n points p to g_tmp/name; returns the path in path. */
static const char *las_write(const char *name, const las_spec *s, const las_pt *p, size_t n,
                             rng *r, char *path, size_t len)
{
    io_buf b = {0};
    unsigned hsize = s->minor == 4 ? 375 : s->minor == 3 ? 235 : 227;
    unsigned vlr_payload = 10, rec = spec_formats[s->fmt].len + s->extra;
    unsigned data_off = hsize + 54 + vlr_payload;
    double lo[3], hi[3];
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
        for (size_t i = 0; i < n; i++) {
            double v = p[i].X[k] * s->scale[k] + s->offset[k];
            lo[k] = fmin(lo[k], v);
            hi[k] = fmax(hi[k], v);
        }
    }
    io_put(&b, "LASF", 4);
    io_put_uint(&b, 7, 2, 0);                         /* 4: file source id */
    io_put_uint(&b, 0, 2, 0);                         /* 6: global encoding */
    io_put(&b, "0123456789abcdef", 16);               /* 8: project GUID */
    io_put_uint(&b, 1, 1, 0);                         /* 24: version major */
    io_put_uint(&b, s->minor, 1, 0);                  /* 25: version minor */
    io_put(&b, "splatd test_io_las system id....", 32);   /* 26: system identifier */
    io_put(&b, "test_io_las.c las_write.........", 32);   /* 58: generating software */
    io_put_uint(&b, 42, 2, 0);                        /* 90: creation day */
    io_put_uint(&b, 2024, 2, 0);                      /* 92: creation year */
    io_put_uint(&b, hsize, 2, 0);                     /* 94: header size */
    io_put_uint(&b, data_off, 4, 0);                  /* 96: offset to point data */
    io_put_uint(&b, 1, 4, 0);                         /* 100: number of VLRs */
    io_put_uint(&b, s->fmt, 1, 0);                    /* 104: point data format */
    io_put_uint(&b, rec, 2, 0);                       /* 105: point record length */
    io_put_uint(&b, s->fmt >= 6 ? 0 : n, 4, 0);       /* 107: legacy point count */
    for (int k = 0; k < 5; k++) io_put_uint(&b, 0, 4, 0); /* 111: legacy count by return */
    for (int k = 0; k < 3; k++) io_put_f64(&b, s->scale[k], 0);  /* 131 */
    for (int k = 0; k < 3; k++) io_put_f64(&b, s->offset[k], 0); /* 155 */
    for (int k = 0; k < 3; k++) {                     /* 179: max x, min x, ... */
        io_put_f64(&b, hi[k], 0);
        io_put_f64(&b, lo[k], 0);
    }
    assert_int_equal(b.n, 227);
    if (s->minor >= 3) io_put_uint(&b, 0, 8, 0);      /* 227: start of waveform data */
    if (s->minor == 4) {
        io_put_uint(&b, 0, 8, 0);                     /* 235: start of first EVLR */
        io_put_uint(&b, 0, 4, 0);                     /* 243: number of EVLRs */
        io_put_uint(&b, n, 8, 0);                     /* 247: number of point records */
        for (int k = 0; k < 15; k++) io_put_uint(&b, 0, 8, 0); /* 255: by return */
    }
    assert_int_equal(b.n, hsize);
    io_put_uint(&b, 0, 2, 0);                         /* VLR: reserved */
    io_put(&b, "splatd_test\0\0\0\0\0", 16);          /* user id */
    io_put_uint(&b, 1234, 2, 0);                      /* record id */
    io_put_uint(&b, vlr_payload, 2, 0);               /* record length after header */
    io_put(&b, "payload that no reader needs....", 32); /* description */
    io_put(&b, "\xde\xad\xbe\xef\x01\x02\x03\x04\x05\x06", vlr_payload);
    assert_int_equal(b.n, data_off);
    for (size_t i = 0; i < n; i++) {
        uint8_t t[80];
        assert_true(rec <= sizeof t);
        for (unsigned k = 0; k < rec; k++) t[k] = (uint8_t)next64(r); /* unused fields */
        for (int k = 0; k < 3; k++) le_at(t + 4 * k, (uint32_t)p[i].X[k], 4);
        le_at(t + 12, p[i].intensity, 2);
        if (s->fmt <= 5) {
            t[15] = (uint8_t)((t[15] & 0xE0) | p[i].cls); /* synthetic/key-point/withheld */
        } else {
            t[16] = p[i].cls;
        }
        for (int k = 0; spec_formats[s->fmt].rgb && k < 3; k++)
            le_at(t + spec_formats[s->fmt].rgb + 2 * k, p[i].rgb[k], 2);
        io_put(&b, t, rec);
    }
    io_save(&b, g_tmp, name, path, len);
    io_free(&b);
    return path;
}

/* The version each format is written in: the oldest that has it, except format 3, written as
 * LAS 1.4 (legacy formats stay valid there, with both the 32- and the 64-bit count set). */
static const unsigned las_minor_of[11] = {0, 1, 2, 4, 3, 3, 4, 4, 4, 4, 4};

/* Scales and offsets: different on every axis, none a power of two, every offset non-zero and
 * large enough that the coordinates need double precision (a float keeps 7 digits). */
static const struct { double scale[3], offset[3]; } las_frames[3] = {
    {{0.001, 0.0025, 0.0001}, {637012.125, 4512345.75, -123.5}},
    {{0.01, 0.003, 0.0005}, {-2445000.5, 603000.25, 1500.75}},
    {{1e-7, 2e-7, 0.001}, {-122.5, 44.25, 100.5}}, /* geographic degrees */
};

/* Checks one synthetic file: raw coordinates against X * scale + offset in double (within a
 * thousandth of the scale: far below the file's half-step precision, far above double
 * rounding), intensity, class and colour of every point; after pc_load, pos + offset within
 * float rounding (wide) or, for the compact files, within half the scale as well. */
static void las_check(const char *path, const las_spec *s, const las_pt *p, size_t n, int compact)
{
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    double smin = INFINITY;
    for (int k = 0; k < 3; k++) smin = fmin(smin, s->scale[k]);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) want[3 * i + k] = p[i].X[k] * s->scale[k] + s->offset[k];
    pc_raw raw;
    io_read_ok(pc_read_las, path, &raw);
    char fmt[32];
    snprintf(fmt, sizeof fmt, "LAS 1.%u format %u", s->minor, s->fmt);
    assert_string_equal(raw.format, fmt);
    int has_rgb = spec_formats[s->fmt].rgb != 0;
    assert_int_equal(raw.attrs, PC_ATTR_INTENSITY | PC_ATTR_CLASS | (has_rgb ? PC_ATTR_RGB : 0));
    assert_int_equal(raw.n, n);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double got = raw.xyz[3 * i + k], w = want[3 * i + k];
            if (!(fabs(got - w) <= 1e-3 * s->scale[k]))
                fail_msg("%s: point %zu axis %c: read %.17g, X * scale + offset = %d * %g + %.17g "
                         "= %.17g", path, i, "xyz"[k], got, p[i].X[k], s->scale[k], s->offset[k],
                         w);
        }
    unsigned cmax = 0;
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) cmax = p[i].rgb[k] > cmax ? p[i].rgb[k] : cmax;
    for (size_t i = 0; i < n; i++) {
        if (raw.intensity[i] != (float)p[i].intensity)
            fail_msg("%s: point %zu intensity %g, written %u", path, i, raw.intensity[i],
                     p[i].intensity);
        if (raw.cls[i] != p[i].cls)
            fail_msg("%s: point %zu class %u, written %u", path, i, raw.cls[i], p[i].cls);
        for (int k = 0; has_rgb && k < 3; k++) {
            int w = cmax > 255 ? (int)floor(p[i].rgb[k] / 257.0 + 0.5) : p[i].rgb[k];
            if (raw.rgba[4 * i + k] != w)
                fail_msg("%s: point %zu channel %d: %d, want %d (written %u)", path, i, k,
                         raw.rgba[4 * i + k], w, p[i].rgb[k]);
        }
    }
    pc_raw_free(&raw);
    pc_cloud c;
    tu_load_ok(path, &c);
    if (compact) {
        /* Float rounding of pos here stays below half the scale, so the bound below is the
         * file's own precision or better. */
        for (int k = 0; k < 3; k++)
            assert_true((c.bmax[k] - c.bmin[k]) * 0x1p-24 < 0.25 * s->scale[k]);
    }
    io_check_cloud_xyz(&c, want, n, 0, path);
    pc_cloud_free(&c);
    free(want);
}

#define LAS_N 64

/* Every point format 0-10, each with non-zero offsets and distinct non-trivial scales on all
 * three axes, a VLR before the points and extra bytes after some records, in two files:
 * "wide" with raw integers over the whole int32 range (coordinates of millions of units whose
 * low digits a float, or an X converted to float, loses) and 16-bit colours, and "compact"
 * with integers within +-200,000 and 8-bit colours, checked after pc_load to half the scale.
 * A dropped or swapped offset or scale on any axis, float arithmetic anywhere in the
 * coordinates, the class or colour taken from the wrong byte, or the 64-bit count of LAS 1.4
 * ignored, fails here with the point named. */
static void test_all_formats_offsets_scales(void **state)
{
    (void)state;
    for (unsigned fmt = 0; fmt <= 10; fmt++)
        for (int compact = 0; compact < 2; compact++) {
            rng r = {0x1a5u * (fmt + 1) + (unsigned)compact};
            las_spec s = {las_minor_of[fmt], fmt, (fmt % 3) * 3, {0}, {0}};
            const int fr = (int)((fmt + (unsigned)compact) % 3);
            memcpy(s.scale, las_frames[fr].scale, sizeof s.scale);
            memcpy(s.offset, las_frames[fr].offset, sizeof s.offset);
            las_pt p[LAS_N];
            for (size_t i = 0; i < LAS_N; i++) {
                for (int k = 0; k < 3; k++) {
                    int64_t x;
                    if (compact) x = (int64_t)(next64(&r) % 400001) - 200000;
                    else if (i < 2) x = i == 0 ? INT32_MAX : INT32_MIN + 1; /* the extremes */
                    else x = (int32_t)(uint32_t)next64(&r);
                    p[i].X[k] = (int32_t)x;
                }
                p[i].intensity = (uint16_t)next64(&r);
                p[i].cls = (uint8_t)(next64(&r) % (fmt <= 5 ? 32 : 256));
                for (int k = 0; k < 3; k++)
                    p[i].rgb[k] = (uint16_t)(compact ? next64(&r) % 256 : next64(&r));
            }
            char name[64], path[1024];
            snprintf(name, sizeof name, "f%u_%s.las", fmt, compact ? "compact" : "wide");
            las_write(name, &s, p, LAS_N, &r, path, sizeof path);
            las_check(path, &s, p, LAS_N, compact);
        }
}

/* ---- real files, every point ---- */

/* Reads every record of a real LAS file directly (header fields at their specification
 * offsets, records at offset-to-point-data with the record length) and compares every point:
 * coordinates X * scale + offset (raw: within a thousandth of the scale; after pc_load:
 * within float rounding, which for these files is below half the scale), intensity, class
 * (low 5 bits of byte 15 in formats 0-5, byte 16 in 6-10) and, for format 3, the colours. */
static void check_real_las(const char *file, size_t want_n)
{
    char p[1024];
    tu_data(file, p, sizeof p);
    size_t len;
    uint8_t *b = tu_read_data(file, &len);
    unsigned minor = b[25], fmt = b[104];
    size_t off = io_get_uint(b + 96, 4, 0), rl = io_get_uint(b + 105, 2, 0);
    size_t n = io_get_uint(b + 107, 4, 0);
    if (n == 0 && minor == 4) n = io_get_uint(b + 247, 8, 0);
    assert_int_equal(n, want_n);
    assert_true(off + n * rl <= len);
    double scale[3], offset[3];
    for (int k = 0; k < 3; k++) {
        scale[k] = io_get_f64(b + 131 + 8 * k, 0);
        offset[k] = io_get_f64(b + 155 + 8 * k, 0);
    }
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    pc_raw raw;
    io_read_ok(pc_read_las, p, &raw);
    assert_int_equal(raw.n, n);
    for (size_t i = 0; i < n; i++) {
        const uint8_t *r = b + off + i * rl;
        for (int k = 0; k < 3; k++) {
            want[3 * i + k] = (double)io_get_int(r + 4 * k, 4, 0) * scale[k] + offset[k];
            if (!(fabs(raw.xyz[3 * i + k] - want[3 * i + k]) <= 1e-3 * scale[k]))
                fail_msg("%s: point %zu axis %c: read %.17g, file %.17g", file, i, "xyz"[k],
                         raw.xyz[3 * i + k], want[3 * i + k]);
        }
        if (raw.intensity[i] != (float)io_get_uint(r + 12, 2, 0))
            fail_msg("%s: point %zu intensity differs", file, i);
        unsigned cls = fmt <= 5 ? (r[15] & 31u) : r[16];
        if (raw.cls[i] != cls)
            fail_msg("%s: point %zu class %u, file %u", file, i, raw.cls[i], cls);
        if (fmt == 3)
            for (int k = 0; k < 3; k++) /* autzen_trim's colours all fit in 8 bits: kept */
                assert_int_equal(raw.rgba[4 * i + k], io_get_uint(r + 28 + 2 * k, 2, 0));
    }
    pc_raw_free(&raw);
    pc_cloud c;
    tu_load_ok(p, &c);
    for (int k = 0; k < 3; k++) assert_true((c.bmax[k] - c.bmin[k]) * 0x1p-24 < 0.25 * scale[k]);
    io_check_cloud_xyz(&c, want, n, 0, file);
    pc_cloud_free(&c);
    free(want);
    free(b);
}

/* autzen_trim.las (LAS 1.2 format 3, scale 0.01): all 110,000 points. */
static void test_autzen_every_point(void **state)
{
    (void)state;
    check_real_las("autzen_trim.las", 110000);
}

/* file_with_both_wkt_and_geotiff_vlrs.las (LAS 1.4 format 6, offsets 2,445,000 / 603,000):
 * all 25,408 points. */
static void test_las14_every_point(void **state)
{
    (void)state;
    check_real_las("file_with_both_wkt_and_geotiff_vlrs.las", 25408);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_autzen_trim),
        cmocka_unit_test(test_las14_format6),
        cmocka_unit_test(test_format7_extra_bytes_16bit_rgb),
        cmocka_unit_test(test_legacy_formats),
        cmocka_unit_test(test_truncated),
        cmocka_unit_test(test_header_errors),
        cmocka_unit_test(test_all_formats_offsets_scales),
        cmocka_unit_test(test_autzen_every_point),
        cmocka_unit_test(test_las14_every_point),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
