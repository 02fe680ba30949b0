/* test_io_xyz.c — the XYZ/PTS text reader on real files (bunnyData.pts with a count line and
 * CRLF; points_agisoft.xyz, georeferenced x y z r g b), on synthetic layouts (separators,
 * comments, intensity, 16-bit and float colours) and on broken files. Both real files and
 * every layout, separator and colour mode are checked row by row (real_every_point,
 * layout_matrix).
 *
 * Expected values come from a separate sscanf scan of each file or from the text the test
 * writes, never from the reader under test. */
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
#include "common/testutil.h"
#include "cloudtest.h"
#include "iotest.h"
#include "rng.h"
#include "testutil.h"

/* ------------------------------------------------------------------ helpers */

typedef struct ref_scan {
    size_t n;
    double lo[3], hi[3];
    double first[6], last[6]; /* x y z and up to three colour values */
} ref_scan;

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

/* Independent scan: sscanf of every line with at least three numbers; a lone first-line
 * integer (the PTS count) is returned in *count. */
static ref_scan scan_text(const char *path, long *count)
{
    ref_scan r = {0};
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char line[512];
    *count = -1;
    int lineno = 0;
    while (fgets(line, sizeof line, f)) {
        double v[6] = {0};
        lineno++;
        int k = sscanf(line, "%lf %lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]);
        if (lineno == 1 && k == 1) {
            *count = (long)v[0];
            continue;
        }
        assert_true(k >= 3);
        if (r.n == 0)
            for (int a = 0; a < 3; a++) r.lo[a] = r.hi[a] = v[a];
        for (int a = 0; a < 3; a++) {
            if (v[a] < r.lo[a]) r.lo[a] = v[a];
            if (v[a] > r.hi[a]) r.hi[a] = v[a];
        }
        if (r.n == 0) memcpy(r.first, v, sizeof v);
        memcpy(r.last, v, sizeof v);
        r.n++;
    }
    fclose(f);
    return r;
}

/* Count, bbox (1e-12 relative: both sides are correctly rounded doubles of the same text),
 * re-centring (offset = centre, |pos| <= half extent up to float rounding). */
static void check_scan(const pc_cloud *c, const ref_scan *r)
{
    assert_int_equal(c->n, r->n);
    for (int k = 0; k < 3; k++) {
        double tol = 1e-12 * (fabs(r->lo[k]) + fabs(r->hi[k]) + 1);
        assert_true(fabs(c->bmin[k] - r->lo[k]) <= tol);
        assert_true(fabs(c->bmax[k] - r->hi[k]) <= tol);
        assert_true(fabs(c->offset[k] - 0.5 * (r->lo[k] + r->hi[k])) <= tol);
        double half = 0.5 * (r->hi[k] - r->lo[k]) * (1 + 1.0 / (1 << 22)) + 1e-30;
        for (size_t i = 0; i < c->n; i++) assert_true(fabs(c->pos[3 * i + k]) <= half);
    }
}

/* pc_load must fail with code and a message naming the file and a line. */
static void expect_fail(const char *path, int code)
{
    pc_cloud c;
    sd_err e = {0};
    int rc = pc_load(path, &c, &e);
    if (rc != code)
        fail_msg("%s: expected %d (%s), got %d: %s", path, code, sd_strerror(code), rc, e.msg);
    assert_non_null(strstr(e.msg, path));
    if (!strstr(e.msg, "line")) fail_msg("message names no line: %s", e.msg);
    assert_null(c.pos);
}

static const char *write_bytes(const char *dir, const char *name, const void *d, size_t len,
                               char *buf, size_t blen)
{
    snprintf(buf, blen, "%s/%s", dir, name);
    assert_int_equal(tu_write_file(buf, d, len), 0);
    return buf;
}

static const char *write_text(const char *dir, const char *name, const char *text, char *buf,
                              size_t blen)
{
    return write_bytes(dir, name, text, strlen(text), buf, blen);
}

/* ------------------------------------------------------------------ real files */

static void bunny_pts(void **state)
{
    (void)state;
    char path[1024];
    tu_data("bunnyData.pts", path, sizeof path);
    long count;
    ref_scan r = scan_text(path, &count);
    assert_int_equal(count, 30571);
    assert_int_equal(r.n, 30571);
    pc_cloud c;
    tu_load_ok(path, &c);
    check_scan(&c, &r);
    assert_int_equal(c.attrs, 0);
    assert_int_equal(c.n_dropped, 0);
    assert_string_equal(c.format, "PTS text (x y z)");
    /* Second and last lines, read with sed/tail: "-0.037829 0.12794 0.004474",
     * "-0.07063 0.04015 0.001226". Float pos near an offset of ~0.1: 1e-8 is a few ulps. */
    tu_check_point(&c, 0, (double[]){-0.037829, 0.12794, 0.004474}, 1e-8);
    tu_check_point(&c, c.n - 1, (double[]){-0.07063, 0.04015, 0.001226}, 1e-8);
    tu_check_point(&c, 0, r.first, 1e-8);
    tu_check_point(&c, c.n - 1, r.last, 1e-8);
    pc_cloud_free(&c);

    double t[9];
    for (int k = 0; k < 9; k++) {
        pc_raw raw = {0};
        sd_err e = {0};
        double t0 = now_ms();
        assert_int_equal(pc_read_xyz(path, &raw, &e), 0);
        t[k] = now_ms() - t0;
        pc_raw_free(&raw);
    }
    for (int i = 0; i < 9; i++)
        for (int j = i + 1; j < 9; j++)
            if (t[j] < t[i]) { double x = t[i]; t[i] = t[j]; t[j] = x; }
    printf("# bunnyData.pts pc_read_xyz: median %.2f ms for 30571 points (880 KB)\n", t[4]);
}

static void agisoft_xyz(void **state)
{
    (void)state;
    char path[1024];
    tu_data("points_agisoft.xyz", path, sizeof path);
    long count;
    ref_scan r = scan_text(path, &count);
    assert_int_equal(count, -1);
    assert_int_equal(r.n, 100);
    pc_cloud c;
    tu_load_ok(path, &c);
    check_scan(&c, &r);
    assert_int_equal(c.attrs, PC_ATTR_RGB);
    assert_string_equal(c.format, "XYZ text (x y z r g b)");
    /* The georeferenced extent from SOURCES.md. */
    assert_true(c.bmin[0] > 665171 && c.bmax[0] < 665189);
    assert_true(c.bmin[1] > 5648340 && c.bmax[1] < 5648383);
    assert_true(c.bmin[2] > 233 && c.bmax[2] < 247);
    /* First and last rows (head/tail): 665187.522077 5648349.895035 241.767693 117 73 49 and
     * 665186.236769 5648351.141146 244.871176 57 59 64. pos is float relative to the centre
     * of a ~42 m box: 4e-6 m is float's step there, 1e-5 leaves room. */
    tu_check_point(&c, 0, (double[]){665187.522077, 5648349.895035, 241.767693}, 1e-5);
    tu_check_point(&c, 99, (double[]){665186.236769, 5648351.141146, 244.871176}, 1e-5);
    tu_check_point(&c, 0, r.first, 1e-5);
    tu_check_point(&c, 99, r.last, 1e-5);
    assert_memory_equal(c.rgba, ((uint8_t[]){117, 73, 49, 255}), 4);
    assert_memory_equal(c.rgba + 4 * 99, ((uint8_t[]){57, 59, 64, 255}), 4);
    for (int k = 0; k < 3; k++) {
        assert_int_equal(c.rgba[k], (int)r.first[3 + k]);
        assert_int_equal(c.rgba[4 * 99 + k], (int)r.last[3 + k]);
    }
    pc_cloud_free(&c);
}

/* The real files cut short. PTS: every cut leaves fewer rows than the count line (or a short
 * last row): SD_ETRUNC. XYZ has no count, so only cuts that leave a short last row are
 * detectable; these cut inside the second, fourth and fifth value of rows 1, 50 and 100. */
static void real_truncated(void **state)
{
    const char *tmp = *state;
    char src[1024], path[1200];
    size_t len;
    uint8_t *d = tu_read_file(tu_data("bunnyData.pts", src, sizeof src), &len);
    assert_non_null(d);
    /* The last row loses its last value (cutting inside it, or only the final CRLF, leaves
     * a complete row, which no reader can tell from an intact file). */
    size_t last = len - 2;
    while (d[last - 1] != ' ') last--;
    size_t cuts[] = {3, 7, 8, 20, len / 2, last, last - 1};
    for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
        char name[64];
        snprintf(name, sizeof name, "cut%zu_bunnyData.pts", cuts[k]);
        expect_fail(write_bytes(tmp, name, d, cuts[k], path, sizeof path), SD_ETRUNC);
    }
    free(d);

    d = tu_read_file(tu_data("points_agisoft.xyz", src, sizeof src), &len);
    assert_non_null(d);
    const int rows[3] = {1, 50, 100}, values[3] = {2, 4, 5};
    for (int k = 0; k < 3; k++) {
        size_t off = 0;
        for (int l = 1; l < rows[k]; l++)
            off = (size_t)((uint8_t *)memchr(d + off, '\n', len - off) - d) + 1;
        for (int v = 1; v < values[k]; v++)
            off = (size_t)((uint8_t *)memchr(d + off, ' ', len - off) - d) + 1;
        off += 1; /* one character into the value */
        char name[64];
        snprintf(name, sizeof name, "cut%zu_points_agisoft.xyz", off);
        expect_fail(write_bytes(tmp, name, d, off, path, sizeof path), SD_ETRUNC);
    }
    free(d);
}

/* ------------------------------------------------------------------ synthetic layouts */

/* The same five points written with spaces, tabs, commas, CRLF, comments and blank lines. */
static void separators_and_comments(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const char *texts[] = {
        "1 2 3\n4 5 6\n-7 8.5 9e1\n0.125 -0.25 1e-3\n10 20 30\n",
        "# header comment\r\n1\t2\t3\r\n\r\n4 5 6\r\n// another comment\r\n-7 8.5 9e1\r\n"
        "0.125 -0.25 1e-3\r\n   10 20 30   \r\n",
        "1,2,3\n4, 5, 6\n-7,8.5,90\n+0.125,-0.25,0.001\n10,20,30",
        "5\n1 2 3\n4 5 6\n-7 8.5 9E+1\n.125 -.25 1E-3\n10 20 30\n",
    };
    const double want[5][3] = {{1, 2, 3}, {4, 5, 6}, {-7, 8.5, 90}, {0.125, -0.25, 0.001},
                               {10, 20, 30}};
    for (size_t t = 0; t < sizeof texts / sizeof texts[0]; t++) {
        char name[32];
        snprintf(name, sizeof name, "sep%zu.%s", t, t == 3 ? "pts" : t == 2 ? "txt" : "xyz");
        pc_cloud c;
        tu_load_ok(write_text(tmp, name, texts[t], path, sizeof path), &c);
        assert_int_equal(c.n, 5);
        assert_int_equal(c.attrs, 0);
        /* Offset (1.5, 9.875, 45.0005): pos is float, whose step near 45 is 4e-6. */
        for (int i = 0; i < 5; i++) tu_check_point(&c, (size_t)i, want[i], 4e-6);
        assert_true(c.bmin[2] == 0.001 && c.bmax[2] == 90);
        pc_cloud_free(&c);
    }
}

static void intensity_and_colour(void **state)
{
    const char *tmp = *state;
    char path[1024];
    pc_cloud c;
    /* x y z i */
    tu_load_ok(write_text(tmp, "i.xyz", "1 2 3 0.5\n4 5 6 -1200\n", path, sizeof path), &c);
    assert_int_equal(c.attrs, PC_ATTR_INTENSITY);
    assert_true(c.intensity[0] == 0.5f && c.intensity[1] == -1200.0f);
    pc_cloud_free(&c);
    /* PTS with intensity then colour (7 columns). */
    tu_load_ok(write_text(tmp, "irgb.pts", "2\r\n1 2 3 -5 10 20 30\r\n4 5 6 7 255 0 128\r\n", path,
                       sizeof path), &c);
    assert_int_equal(c.attrs, PC_ATTR_INTENSITY | PC_ATTR_RGB);
    assert_true(c.intensity[0] == -5.0f && c.intensity[1] == 7.0f);
    assert_memory_equal(c.rgba, ((uint8_t[]){10, 20, 30, 255, 255, 0, 128, 255}), 8);
    assert_string_equal(c.format, "PTS text (x y z i r g b)");
    pc_cloud_free(&c);
    /* 16-bit colour: one value over 255 scales all by 255/65535 (65535 -> 255, 257k -> k). */
    tu_load_ok(write_text(tmp, "rgb16.xyz", "1 2 3 65535 0 257\n4 5 6 32896 100 25700\n", path,
                       sizeof path), &c);
    assert_memory_equal(c.rgba, ((uint8_t[]){255, 0, 1, 255, 128, 0, 100, 255}), 8);
    pc_cloud_free(&c);
    /* 8-bit colour stays as is even when small. */
    tu_load_ok(write_text(tmp, "rgb8.xyz", "1 2 3 1 0 1\n4 5 6 0 1 0\n", path, sizeof path), &c);
    assert_memory_equal(c.rgba, ((uint8_t[]){1, 0, 1, 255, 0, 1, 0, 255}), 8);
    pc_cloud_free(&c);
    /* Float colour in [0,1] with fractions: scaled by 255. */
    tu_load_ok(write_text(tmp, "rgbf.xyz", "1 2 3 1.0 0.5 0\n4 5 6 0.2 0.8 1\n", path, sizeof path),
            &c);
    assert_memory_equal(c.rgba, ((uint8_t[]){255, 128, 0, 255, 51, 204, 255, 255}), 8);
    pc_cloud_free(&c);
}

/* NaN/inf rows are read and then dropped by finalize, counted in n_dropped. */
static void nan_rows(void **state)
{
    const char *tmp = *state;
    char path[1024];
    pc_cloud c;
    tu_load_ok(write_text(tmp, "nan.pts",
                       "5\n1 2 3 10 20 30\nnan 0 0 0 0 0\n0 inf 0 0 0 0\n0 0 -Infinity 0 0 0\n"
                       "7 8 9 40 50 60\n", path, sizeof path), &c);
    assert_int_equal(c.n, 2);
    assert_int_equal(c.n_dropped, 3);
    tu_check_point(&c, 1, (double[]){7, 8, 9}, 0);
    assert_memory_equal(c.rgba + 4, ((uint8_t[]){40, 50, 60, 255}), 4);
    pc_cloud_free(&c);
}

/* The reader's doubles are bit-identical to strtod's for short, long (over 19 digits), tiny,
 * huge and exponent-heavy numbers: the fast path must round correctly or step aside. */
static void precise_numbers(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const char *nums[] = {
        "665171.123456789", "5648340.98765432101234567", "0.1", "0.30000000000000004",
        "9007199254740993", "123456789012345678901234567890", "1e-320", "2.2250738585072014e-308",
        "1.7976931348623157e308", "4.9406564584124654e-324", "-0.000001234567890123456789",
        "1e22", "1e23", "8.589973e9", "0.0359793", "-0", "3.14159265358979323846264338327950288",
        "7.0e-10", "1E+5", "0.000000000000000000000000000001", "9007199254740993.0000000001",
        "9007199254740993e-10", "1.00000000000000011102230246251565404236316680908203125",
        "1.00000000000000011102230246251565404236316680908203124",
    };
    size_t nn = sizeof nums / sizeof nums[0];
    char text[4096] = "";
    for (size_t i = 0; i < nn; i++) {
        strcat(text, nums[i]);
        strcat(text, i % 3 == 2 ? "\n" : " ");
    }
    for (size_t i = nn; i % 3; i++) strcat(text, i % 3 == 2 ? "1\n" : "1 "); /* full rows */
    pc_raw raw = {0};
    sd_err e = {0};
    int rc = pc_read_xyz(write_text(tmp, "precise.xyz", text, path, sizeof path), &raw, &e);
    if (rc != 0) fail_msg("%d %s", rc, e.msg);
    assert_int_equal(raw.n, (nn + 2) / 3);
    for (size_t i = 0; i < nn; i++) {
        double want = strtod(nums[i], NULL);
        if (memcmp(&raw.xyz[i], &want, sizeof want) != 0)
            fail_msg("%s: got %.17g, strtod %.17g", nums[i], raw.xyz[i], want);
    }
    pc_raw_free(&raw);
}

/* Leica-style PTS with several scans: each block has its own count line. */
static void pts_blocks(void **state)
{
    const char *tmp = *state;
    char path[1024];
    pc_cloud c;
    tu_load_ok(write_text(tmp, "blocks.pts", "2\n1 2 3\n4 5 6\n3\n7 8 9\n1 1 1\n2 2 2\n0\n", path,
                       sizeof path), &c);
    assert_int_equal(c.n, 5);
    tu_check_point(&c, 4, (double[]){2, 2, 2}, 0);
    pc_cloud_free(&c);
    /* The first block is one row short: the error names its count line (line 1). */
    expect_fail(write_text(tmp, "blocks_short.pts", "2\n1 2 3\n1\n4 5 6\n", path, sizeof path),
                SD_ETRUNC);
    sd_err e = {0};
    assert_int_equal(pc_load(path, &c, &e), SD_ETRUNC);
    assert_non_null(strstr(e.msg, "line 1:"));
    /* Without a count line at the top, a lone value later is a short row. */
    expect_fail(write_text(tmp, "lone.xyz", "1 2 3\n4 5 6\n7\n", path, sizeof path), SD_EFORMAT);
}

static void broken(void **state)
{
    const char *tmp = *state;
    char path[1024];
    /* The count line disagrees: too few rows is a cut file, too many a bad one. */
    expect_fail(write_text(tmp, "few.pts", "5\n1 2 3\n4 5 6\n7 8 9\n1 1 1\n", path, sizeof path),
                SD_ETRUNC);
    expect_fail(write_text(tmp, "many.pts", "3\n1 2 3\n4 5 6\n7 8 9\n1 1 1\n", path, sizeof path),
                SD_EFORMAT);
    /* A huge count is not trusted for the allocation (ASan would abort on the request). */
    expect_fail(write_text(tmp, "huge.pts", "999999999999999\n1 2 3\n4 5 6\n", path, sizeof path),
                SD_ETRUNC);
    /* Rows must match the first one. */
    expect_fail(write_text(tmp, "cols.xyz", "1 2 3\n4 5 6\n7 8 9 10\n", path, sizeof path),
                SD_EFORMAT);
    expect_fail(write_text(tmp, "cols2.xyz", "1 2 3 4 5 6\n4 5 6\n7 8 9 1 2 3\n", path,
                           sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "token.xyz", "1 2 3\n4 five 6\n", path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "token2.xyz", "1 2 3\n4 5 6x\n", path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "five.xyz", "1 2 3 4 5\n", path, sizeof path), SD_EUNSUP);
    expect_fail(write_text(tmp, "eight.xyz", "1 2 3 4 5 6 7 8\n", path, sizeof path), SD_EUNSUP);
    expect_fail(write_text(tmp, "two.xyz", "1 2\n3 4\n", path, sizeof path), SD_EUNSUP);
    expect_fail(write_text(tmp, "single.xyz", "1.5\n1 2 3\n", path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "binary.xyz", "1 2 3\n\x01\x02\x03 4 5\n", path, sizeof path),
                SD_EFORMAT);

    /* Nothing to read: SD_EEMPTY from pc_load. */
    const char *empties[] = {"", "# only a comment\n\n", "0\n"};
    for (int k = 0; k < 3; k++) {
        char name[32];
        snprintf(name, sizeof name, "empty%d.pts", k);
        pc_cloud c;
        sd_err e = {0};
        assert_int_equal(pc_load(write_text(tmp, name, empties[k], path, sizeof path), &c, &e),
                         SD_EEMPTY);
        assert_non_null(strstr(e.msg, path));
    }
}

/* A 200k-row file grows the arrays geometrically (no count line) and reads every row. */
static void growth(void **state)
{
    const char *tmp = *state;
    char path[1024];
    snprintf(path, sizeof path, "%s/big.xyz", tmp);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    for (int i = 0; i < 200000; i++)
        fprintf(f, "%d %d.5 %d %d %d %d\n", i % 1000, i / 1000, -i, i % 256, (i / 256) % 256, 9);
    fclose(f);
    pc_cloud c;
    tu_load_ok(path, &c);
    assert_int_equal(c.n, 200000);
    assert_true(c.bmin[0] == 0 && c.bmax[0] == 999 && c.bmin[1] == 0.5 && c.bmax[1] == 199.5);
    assert_true(c.bmin[2] == -199999 && c.bmax[2] == 0);
    tu_check_point(&c, 123456, (double[]){456, 123.5, -123456}, 0);
    assert_memory_equal(c.rgba + 4 * 123456,
                        ((uint8_t[]){123456 % 256, 123456 / 256 % 256, 9, 255}), 4);
    pc_cloud_free(&c);
}

/* ------------------------------------------------------------------ every point, every layout */

/* Parses every data row of a real text file here with strtod (a row of one value is the PTS
 * count), returning the rows' values (ncol per row) and the row count. */
static double *ref_rows(const char *path, int ncol, size_t *rows, long *count)
{
    size_t len;
    uint8_t *d = tu_read_file(path, &len);
    assert_non_null(d);
    size_t cap = 1024, n = 0;
    double *v = malloc(cap * ncol * sizeof *v);
    assert_non_null(v);
    *count = -1;
    char *s = (char *)d, *end = s + len;
    while (s < end) {
        char *nl = memchr(s, '\n', (size_t)(end - s));
        char *le = nl ? nl : end;
        double row[8];
        int k = 0;
        char *p = s;
        while (k < 8) {
            char *e;
            double x = strtod(p, &e);
            if (e == p || e > le) break;
            row[k++] = x;
            p = e;
        }
        if (k == 1 && n == 0 && *count < 0) {
            *count = (long)row[0];
        } else if (k > 0) {
            assert_int_equal(k, ncol);
            if (n == cap) {
                cap *= 2;
                v = realloc(v, cap * ncol * sizeof *v);
                assert_non_null(v);
            }
            memcpy(v + n * ncol, row, ncol * sizeof *v);
            n++;
        }
        s = le + 1;
    }
    free(d);
    *rows = n;
    return v;
}

/* bunnyData.pts (count line, CRLF) and points_agisoft.xyz (georeferenced x y z r g b): every
 * row parsed here with strtod. The reader promises correctly rounded numbers, so every raw
 * coordinate must be strtod's double exactly; after pc_load pos + offset must be within float
 * rounding of it; agisoft's colours must be the integers written. */
static void real_every_point(void **state)
{
    (void)state;
    const struct { const char *name; int ncol; long count; size_t n; } files[2] = {
        {"bunnyData.pts", 3, 30571, 30571}, {"points_agisoft.xyz", 6, -1, 100}};
    for (int f = 0; f < 2; f++) {
        char path[1024];
        tu_data(files[f].name, path, sizeof path);
        size_t n;
        long count;
        double *v = ref_rows(path, files[f].ncol, &n, &count);
        assert_int_equal(n, files[f].n);
        assert_int_equal(count, files[f].count);
        double *want = malloc(3 * n * sizeof *want);
        assert_non_null(want);
        for (size_t i = 0; i < n; i++)
            for (int k = 0; k < 3; k++) want[3 * i + k] = v[i * files[f].ncol + k];
        pc_raw raw;
        io_read_ok(pc_read_xyz, path, &raw);
        io_check_raw_xyz(&raw, want, n, 0, files[f].name);
        for (size_t i = 0; files[f].ncol == 6 && i < n; i++)
            for (int k = 0; k < 3; k++)
                if (raw.rgba[4 * i + k] != v[i * 6 + 3 + k])
                    fail_msg("%s: row %zu colour %d: %d, file %g", files[f].name, i, k,
                             raw.rgba[4 * i + k], v[i * 6 + 3 + k]);
        pc_raw_free(&raw);
        pc_cloud c;
        tu_load_ok(path, &c);
        io_check_cloud_xyz(&c, want, n, 0, files[f].name);
        pc_cloud_free(&c);
        free(want);
        free(v);
    }
}

/* The layouts x y z, x y z i, x y z r g b and x y z i r g b, each colour layout with 8-bit,
 * 16-bit and 0..1 float colours, written with every separator (space, tab, comma, semicolon,
 * comma and space), LF or CRLF, with and without a PTS count line, from georeferenced values
 * printed with 17 significant digits (which a float, or a parser that is not correctly
 * rounded, changes). Every row is checked: coordinates exactly strtod's double of the token
 * written, intensity that as float, colours by the rule of the mode (8-bit kept, 16-bit scaled
 * by 255/65535, 0..1 scaled by 255, all rounded to nearest). */
static void layout_matrix(void **state)
{
    const char *tmp = *state;
    static const char *const seps[] = {" ", "\t", ",", ";", ", "};
    const int layouts[4] = {3, 4, 6, 7};
    int file = 0;
    for (int li = 0; li < 4; li++)
        for (int mode = 0; mode < (layouts[li] >= 6 ? 3 : 1); mode++, file++) {
            enum { N = 50 };
            int ncol = layouts[li], inten = ncol == 4 || ncol == 7;
            const char *sep = seps[file % 5], *eol = file % 2 ? "\r\n" : "\n";
            int pts = file % 3 == 1;
            rng r = {0x7e57u + 131u * (unsigned)file};
            char buf[256];
            io_buf b = {0};
            if (pts) io_printf(&b, "%d%s", N, eol);
            else io_printf(&b, "# written by test_io_xyz layout_matrix%s", eol);
            double want[3 * N], it[N], col[N][3];
            for (int i = 0; i < N; i++) {
                const double base[3] = {665171.0, 5648340.0, 233.0};
                for (int k = 0; k < 3; k++) {
                    snprintf(buf, sizeof buf, "%.17g", base[k] + 40 * uni(&r));
                    want[3 * i + k] = strtod(buf, NULL);
                    io_printf(&b, "%s%s", k ? sep : "", buf);
                }
                if (inten) {
                    snprintf(buf, sizeof buf, "%.9g", (uni(&r) - 0.3) * 3000);
                    it[i] = strtod(buf, NULL);
                    io_printf(&b, "%s%s", sep, buf);
                }
                for (int k = 0; ncol >= 6 && k < 3; k++) {
                    if (mode == 0) snprintf(buf, sizeof buf, "%d", (int)(next64(&r) % 256));
                    else if (mode == 1) snprintf(buf, sizeof buf, "%d", (int)(next64(&r) % 65536));
                    else if (i == 0 && k == 0) snprintf(buf, sizeof buf, "1"); /* the top */
                    else snprintf(buf, sizeof buf, "%.6f", uni(&r));
                    col[i][k] = strtod(buf, NULL);
                    io_printf(&b, "%s%s", sep, buf);
                }
                io_printf(&b, "%s", eol);
            }
            char name[64], path[1024];
            snprintf(name, sizeof name, "layout%d.%s", file,
                     pts ? "pts" : file % 2 ? "txt" : "xyz");
            io_save(&b, tmp, name, path, sizeof path);
            io_free(&b);

            pc_raw raw;
            io_read_ok(pc_read_xyz, path, &raw);
            assert_int_equal(raw.attrs, (inten ? PC_ATTR_INTENSITY : 0u) |
                                            (ncol >= 6 ? PC_ATTR_RGB : 0u));
            io_check_raw_xyz(&raw, want, N, 0, path);
            for (int i = 0; i < N; i++) {
                if (inten && raw.intensity[i] != (float)it[i])
                    fail_msg("%s: row %d intensity %.9g, written %.9g", path, i, raw.intensity[i],
                             it[i]);
                for (int k = 0; ncol >= 6 && k < 3; k++) {
                    double x = mode == 0 ? col[i][k]
                               : mode == 1 ? col[i][k] / 257.0
                                           : (double)(float)col[i][k] * 255.0;
                    int w = !(x > 0) ? 0 : x >= 255 ? 255 : (int)floor(x + 0.5);
                    if (raw.rgba[4 * i + k] != w)
                        fail_msg("%s: row %d channel %d: %d, want %d (written %g)", path, i, k,
                                 raw.rgba[4 * i + k], w, col[i][k]);
                }
            }
            pc_raw_free(&raw);
            pc_cloud c;
            tu_load_ok(path, &c);
            io_check_cloud_xyz(&c, want, N, 0, path);
            pc_cloud_free(&c);
        }
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
#define TMP_TEST(f) cmocka_unit_test_setup_teardown(f, tu_tmpdir_setup, tu_tmpdir_teardown)
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(bunny_pts),
        cmocka_unit_test(agisoft_xyz),
        TMP_TEST(real_truncated),
        TMP_TEST(separators_and_comments),
        TMP_TEST(intensity_and_colour),
        TMP_TEST(nan_rows),
        TMP_TEST(pts_blocks),
        TMP_TEST(precise_numbers),
        TMP_TEST(broken),
        TMP_TEST(growth),
        cmocka_unit_test(real_every_point),
        TMP_TEST(layout_matrix),
    };
#undef TMP_TEST
    return cmocka_run_group_tests(tests, NULL, NULL);
}
