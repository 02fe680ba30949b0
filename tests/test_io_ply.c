/* test_io_ply.c — the PLY reader on real scans (Guanyin.ply binary, bun000.ply ascii with a
 * range_grid list element), on the same synthetic cloud written in every encoding and property
 * layout, and on broken files (truncated, lying counts, bad header, garbage). Every type name
 * in every encoding, and both real files, are checked point by point (type_matrix,
 * mixed_types, guanyin_every_point, bun000_every_point).
 *
 * Expected values come from independent scans of the files written here (memcpy of the float
 * triples at the known layout; sscanf of the text lines) or from the generator of the synthetic
 * cloud, never from the reader under test. */
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

typedef struct ref_box {
    size_t n;
    double lo[3], hi[3];
    double first[3], last[3];
} ref_box;

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

static void box_add(ref_box *b, const double p[3])
{
    if (b->n == 0) {
        for (int k = 0; k < 3; k++) b->lo[k] = b->hi[k] = b->first[k] = p[k];
    }
    for (int k = 0; k < 3; k++) {
        if (p[k] < b->lo[k]) b->lo[k] = p[k];
        if (p[k] > b->hi[k]) b->hi[k] = p[k];
        b->last[k] = p[k];
    }
    b->n++;
}

/* Checks the cloud against an independently computed box: count, bbox, and re-centring
 * (offset = box centre, every |pos| within the half extent). Tolerance for the bbox: 1e-12
 * relative, because both sides hold the same correctly rounded doubles; pos is float, so the
 * half-extent bound gets float rounding (2^-23 relative) on top. */
static void check_box(const pc_cloud *c, const ref_box *b)
{
    assert_int_equal(c->n, b->n);
    for (int k = 0; k < 3; k++) {
        double ext = b->hi[k] - b->lo[k], tol = 1e-12 * (fabs(b->lo[k]) + fabs(b->hi[k]) + 1);
        assert_true(fabs(c->bmin[k] - b->lo[k]) <= tol);
        assert_true(fabs(c->bmax[k] - b->hi[k]) <= tol);
        assert_true(fabs(c->offset[k] - 0.5 * (b->lo[k] + b->hi[k])) <= tol);
        double half = 0.5 * ext * (1 + 1.0 / (1 << 22)) + 1e-30;
        for (size_t i = 0; i < c->n; i++) assert_true(fabs(c->pos[3 * i + k]) <= half);
    }
}

/* pc_load must fail with code, and the message must name the file and a line or byte offset. */
static void expect_fail(const char *path, int code)
{
    pc_cloud c;
    sd_err e = {0};
    int rc = pc_load(path, &c, &e);
    if (rc != code) fail_msg("%s: expected %d (%s), got %d: %s", path, code, sd_strerror(code), rc,
                             e.msg);
    assert_int_equal(e.code, code);
    assert_non_null(strstr(e.msg, path));
    if (!strstr(e.msg, "offset") && !strstr(e.msg, "line"))
        fail_msg("message names neither line nor offset: %s", e.msg);
    assert_null(c.pos);
}

static size_t header_len(const uint8_t *d, size_t n)
{
    const uint8_t *h = memmem(d, n, "end_header", 10);
    assert_non_null(h);
    size_t off = (size_t)(h - d) + 10;
    if (d[off] == '\r') off++;
    assert_int_equal(d[off], '\n');
    return off + 1;
}

/* Writes the first len bytes of data to dir/name and returns the path in buf. */
static const char *write_cut(const char *dir, const char *name, const uint8_t *data, size_t len,
                             char *buf, size_t blen)
{
    snprintf(buf, blen, "%s/%s", dir, name);
    assert_int_equal(tu_write_file(buf, data, len), 0);
    return buf;
}

static const char *write_text(const char *dir, const char *name, const char *text, char *buf,
                              size_t len)
{
    return write_cut(dir, name, (const uint8_t *)text, strlen(text), buf, len);
}

/* Offset of the first byte of the last token in d (for cuts that must remove a whole value). */
static size_t last_token(const uint8_t *d, size_t n)
{
    while (n > 0 && (d[n - 1] == '\n' || d[n - 1] == '\r' || d[n - 1] == ' ')) n--;
    while (n > 0 && d[n - 1] != ' ' && d[n - 1] != '\n') n--;
    return n;
}

/* ------------------------------------------------------------------ real files */

static void guanyin(void **state)
{
    (void)state;
    char path[1024];
    tu_data("Guanyin.ply", path, sizeof path);
    size_t len;
    uint8_t *d = tu_read_file(path, &len);
    assert_non_null(d);
    /* Independent scan: SOURCES.md says float x y z + uchar r g b, 15 bytes a record. */
    size_t h = header_len(d, len);
    assert_int_equal(h, 180);
    ref_box b = {0};
    uint8_t c0[3], c1[3];
    for (size_t i = 0; i < 238154; i++) {
        float f[3];
        memcpy(f, d + h + 15 * i, 12);
        double p[3] = {f[0], f[1], f[2]};
        box_add(&b, p);
    }
    memcpy(c0, d + h + 12, 3);
    memcpy(c1, d + h + 15 * 238153 + 12, 3);
    assert_int_equal(h + 15 * 238154, len);

    pc_cloud c;
    tu_load_ok(path, &c);
    check_box(&c, &b);
    assert_int_equal(c.n, 238154);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, PC_ATTR_RGB);
    assert_string_equal(c.format, "PLY binary_little_endian 1.0");
    /* Spot values read with od while writing this test: first 0.04723 0.133738 0.272699 rgb
     * 82 43 17; last -0.304733 0.679032 -0.011363 rgb 77 39 18. Tolerance: float pos relative
     * to an offset of size ~1 is good to ~1e-7. */
    const double f0[3] = {0.04723000153899193, 0.13373799622058868, 0.2726989984512329};
    const double f1[3] = {-0.304733008146286, 0.679032027721405, -0.011362999677658081};
    tu_check_point(&c, 0, f0, 2e-7);
    tu_check_point(&c, c.n - 1, f1, 2e-7);
    tu_check_point(&c, 0, b.first, 2e-7);
    tu_check_point(&c, c.n - 1, b.last, 2e-7);
    assert_memory_equal(c.rgba, ((uint8_t[]){82, 43, 17, 255}), 4);
    assert_memory_equal(c.rgba + 4 * (c.n - 1), ((uint8_t[]){77, 39, 18, 255}), 4);
    assert_memory_equal(c.rgba, c0, 3);
    assert_memory_equal(c.rgba + 4 * (c.n - 1), c1, 3);
    pc_cloud_free(&c);

    /* Load time: median of 7 runs of the reader alone. */
    double t[7];
    for (int r = 0; r < 7; r++) {
        pc_raw raw = {0};
        sd_err e = {0};
        double t0 = now_ms();
        assert_int_equal(pc_read_ply(path, &raw, &e), 0);
        t[r] = now_ms() - t0;
        assert_int_equal(raw.n, 238154);
        pc_raw_free(&raw);
    }
    for (int i = 0; i < 7; i++)
        for (int j = i + 1; j < 7; j++)
            if (t[j] < t[i]) { double x = t[i]; t[i] = t[j]; t[j] = x; }
    printf("# Guanyin.ply pc_read_ply: median %.2f ms (min %.2f, max %.2f) for 238154 points\n",
           t[3], t[0], t[6]);
    free(d);
}

static void bun000(void **state)
{
    (void)state;
    char path[1024];
    tu_data("bun000.ply", path, sizeof path);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char line[256];
    while (fgets(line, sizeof line, f) && strcmp(line, "end_header\n") != 0) {}
    ref_box b = {0};
    for (int i = 0; i < 40256; i++) {
        double p[3];
        assert_non_null(fgets(line, sizeof line, f));
        assert_int_equal(sscanf(line, "%lf %lf %lf", &p[0], &p[1], &p[2]), 3);
        box_add(&b, p);
    }
    size_t grid = 0;
    while (fgets(line, sizeof line, f)) grid++;
    fclose(f);
    assert_int_equal(grid, 204800); /* the range_grid rows the reader must skip */

    pc_cloud c;
    tu_load_ok(path, &c);
    check_box(&c, &b);
    assert_int_equal(c.n, 40256);
    assert_int_equal(c.n_dropped, 0);
    assert_int_equal(c.attrs, 0);
    assert_string_equal(c.format, "PLY ascii 1.0");
    /* First and last vertex lines, read with awk: "-0.06325 0.0359793 0.0420873" and
     * "-0.018 0.18794 -0.0197253". Float pos near offsets ~0.1: 1e-8 is a few ulps. */
    tu_check_point(&c, 0, (double[]){-0.06325, 0.0359793, 0.0420873}, 1e-8);
    tu_check_point(&c, c.n - 1, (double[]){-0.018, 0.18794, -0.0197253}, 1e-8);
    tu_check_point(&c, 0, b.first, 1e-8);
    tu_check_point(&c, c.n - 1, b.last, 1e-8);
    pc_cloud_free(&c);
}

/* Every real file cut at several places: inside the header, just after it, inside the data,
 * and at the last byte (binary) or the last value (ascii: cutting only the final newline
 * leaves a valid file, so the cut removes the last value instead). */
static void real_truncated(void **state)
{
    const char *tmp = *state;
    char src[1024], path[1200];
    const char *names[] = {"Guanyin.ply", "bun000.ply"};
    for (int f = 0; f < 2; f++) {
        size_t len;
        uint8_t *d = tu_read_file(tu_data(names[f], src, sizeof src), &len);
        assert_non_null(d);
        size_t h = header_len(d, len);
        size_t cuts[] = {h / 2, h - 1, h, h + 1, h + 15 * 1000 + 7, h + (len - h) / 2,
                         f == 0 ? len - 1 : last_token(d, len)};
        for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
            char name[64];
            snprintf(name, sizeof name, "cut%zu_%s", cuts[k], names[f]);
            expect_fail(write_cut(tmp, name, d, cuts[k], path, sizeof path), SD_ETRUNC);
        }
        free(d);
    }
}

/* The vertex count in the header larger than the data. */
static void real_count_too_big(void **state)
{
    const char *tmp = *state;
    char src[1024], path[1200];
    size_t len;
    uint8_t *d = tu_read_file(tu_data("Guanyin.ply", src, sizeof src), &len);
    assert_non_null(d);
    uint8_t *v = memmem(d, len, "vertex 238154", 13);
    assert_non_null(v);
    memcpy(v, "vertex 238155", 13);
    expect_fail(write_cut(tmp, "plus1.ply", d, len, path, sizeof path), SD_ETRUNC);
    memcpy(v, "vertex 999999", 13);
    expect_fail(write_cut(tmp, "big.ply", d, len, path, sizeof path), SD_ETRUNC);
    free(d);

    d = tu_read_file(tu_data("bun000.ply", src, sizeof src), &len);
    assert_non_null(d);
    v = memmem(d, len, "vertex 40256", 12);
    assert_non_null(v);
    /* One more vertex: the first range_grid row ("0") is then read as a vertex and has too few
     * values, which is a format error on that line. */
    memcpy(v, "vertex 40257", 12);
    expect_fail(write_cut(tmp, "bun_plus1.ply", d, len, path, sizeof path), SD_EFORMAT);
    /* A count the remaining bytes cannot hold is refused before anything is allocated. */
    uint8_t *big = malloc(len + 8);
    assert_non_null(big);
    size_t at = (size_t)(v - d);
    memcpy(big, d, at);
    memcpy(big + at, "vertex 999999999", 16);
    memcpy(big + at + 16, v + 12, len - at - 12);
    expect_fail(write_cut(tmp, "bun_big.ply", big, len + 4, path, sizeof path), SD_ETRUNC);
    free(big);
    free(d);
}

/* ------------------------------------------------------------------ synthetic clouds */

#define SYN_N 40

/* The synthetic cloud: coordinates are multiples of 1/8 so float and double hold them
 * exactly and every encoding must give bit-identical positions. */
static void syn_point(int i, double p[3])
{
    p[0] = 1000 + 0.25 * i - 3.5;
    p[1] = -20 + 0.125 * ((i * 7) % SYN_N);
    p[2] = 0.5 * (i % 9) - 1.0;
}

static void syn_colour(int i, int c[3])
{
    c[0] = (i * 53) % 256;
    c[1] = (i * 97 + 11) % 256;
    c[2] = 255 - (i * 31) % 256;
}

static void syn_normal(int i, double n[3])
{
    double a = 0.3 * i;
    n[0] = cos(a) * 0.6;
    n[1] = sin(a) * 0.6;
    n[2] = 0.8;
}

typedef struct ptype {
    const char *name;
    int size;
    int flt; /* 1 for float types */
} ptype;

static const ptype ptypes[] = {
    {"char", 1, 0},   {"int8", 1, 0},   {"uchar", 1, 0},    {"uint8", 1, 0},
    {"short", 2, 0},  {"int16", 2, 0},  {"ushort", 2, 0},   {"uint16", 2, 0},
    {"int", 4, 0},    {"int32", 4, 0},  {"uint", 4, 0},     {"uint32", 4, 0},
    {"float", 4, 1},  {"float32", 4, 1}, {"double", 8, 1},  {"float64", 8, 1},
};

static const ptype *ptype_of(const char *name)
{
    for (size_t i = 0; i < sizeof ptypes / sizeof ptypes[0]; i++)
        if (!strcmp(ptypes[i].name, name)) return &ptypes[i];
    fail_msg("test bug: type %s", name);
    return NULL;
}

enum { ASC, LE, BE };

/* Writes one value of type t in format fmt. */
static void put_val(FILE *f, int fmt, const ptype *t, double v, int first)
{
    if (fmt == ASC) {
        if (!first) fputc(' ', f);
        if (t->flt && t->size == 4) fprintf(f, "%.9g", (double)(float)v);
        else if (t->flt) fprintf(f, "%.17g", v);
        else fprintf(f, "%lld", (long long)v);
        return;
    }
    uint8_t b[8];
    if (t->flt && t->size == 4) { float x = (float)v; memcpy(b, &x, 4); }
    else if (t->flt) memcpy(b, &v, 8);
    else {
        int64_t x = (int64_t)v;
        memcpy(b, &x, 8); /* little-endian host: the low bytes come first */
    }
    if (fmt == BE)
        for (int i = 0; i < t->size / 2; i++) {
            uint8_t s = b[i];
            b[i] = b[t->size - 1 - i];
            b[t->size - 1 - i] = s;
        }
    fwrite(b, 1, (size_t)t->size, f);
}

/* The value of vertex property name (of type t) for point i. */
static double syn_value(const char *name, const ptype *t, int i)
{
    double p[3], n[3];
    int c[3];
    syn_point(i, p);
    syn_normal(i, n);
    syn_colour(i, c);
    if (!strcmp(name, "x")) return p[0];
    if (!strcmp(name, "y")) return p[1];
    if (!strcmp(name, "z")) return p[2];
    if (!strcmp(name, "nx")) return n[0];
    if (!strcmp(name, "ny")) return n[1];
    if (!strcmp(name, "nz")) return n[2];
    int ci = -1;
    if (!strcmp(name, "red") || !strcmp(name, "r") || !strcmp(name, "diffuse_red")) ci = 0;
    if (!strcmp(name, "green") || !strcmp(name, "g") || !strcmp(name, "diffuse_green")) ci = 1;
    if (!strcmp(name, "blue") || !strcmp(name, "b") || !strcmp(name, "diffuse_blue")) ci = 2;
    if (!strcmp(name, "alpha")) return t->flt ? 1.0 : t->size == 2 ? 65535 : 255;
    if (!strcmp(name, "quality")) return 0.5 * i;
    if (!strcmp(name, "confidence")) return 100 + i;
    if (!strcmp(name, "scalar_a")) return 200 + i;
    if (!strcmp(name, "intensity")) return 3 * i;
    if (!strcmp(name, "radius")) return 0.01 * (i + 1);
    if (ci >= 0) return t->flt ? c[ci] / 255.0 : t->size == 2 ? c[ci] * 257.0 : c[ci];
    return i % 100; /* properties the reader ignores */
}

/* Writes a list element: count rows of 3 or 4 indices with count type ct, item type it. */
static void put_faces(FILE *f, int fmt, const char *ct, const char *it, int count, const char *eol)
{
    const ptype *tc = ptype_of(ct), *ti = ptype_of(it);
    for (int j = 0; j < count; j++) {
        int m = 3 + j % 2;
        put_val(f, fmt, tc, m, 1);
        for (int k = 0; k < m; k++) put_val(f, fmt, ti, (j + k) % SYN_N, 0);
        if (fmt == ASC) fputs(eol, f);
    }
}

typedef struct variant {
    const char *file;
    int fmt, crlf;
    const char *props[16]; /* "type name" */
    int face_before, face_after;
} variant;

/* Writes the synthetic cloud as variant v into dir; returns the path in buf. */
static const char *write_variant(const char *dir, const variant *v, char *buf, size_t len)
{
    static const char *fmts[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    const char *eol = v->crlf ? "\r\n" : "\n";
    snprintf(buf, len, "%s/%s", dir, v->file);
    FILE *f = fopen(buf, "wb");
    assert_non_null(f);
    fprintf(f, "ply%sformat %s 1.0%scomment synthetic test cloud%sobj_info made by test_io_ply%s",
            eol, fmts[v->fmt], eol, eol, eol);
    if (v->face_before)
        fprintf(f, "element face 7%sproperty list uchar int vertex_indices%s", eol, eol);
    fprintf(f, "element vertex %d%s", SYN_N, eol);
    char tn[16][2][32];
    int np = 0;
    for (; np < 16 && v->props[np]; np++) {
        assert_int_equal(sscanf(v->props[np], "%31s %31s", tn[np][0], tn[np][1]), 2);
        fprintf(f, "property %s %s%s", tn[np][0], tn[np][1], eol);
    }
    if (v->face_after)
        fprintf(f, "element edge 5%sproperty uchar flags%sproperty list ushort uint32 idx%s"
                   "property float weight%s", eol, eol, eol, eol);
    fprintf(f, "end_header%s", eol);
    if (v->face_before) put_faces(f, v->fmt, "uchar", "int", 7, eol);
    for (int i = 0; i < SYN_N; i++) {
        for (int k = 0; k < np; k++) {
            const ptype *t = ptype_of(tn[k][0]);
            put_val(f, v->fmt, t, syn_value(tn[k][1], t, i), k == 0);
        }
        if (v->fmt == ASC) fputs(eol, f);
    }
    if (v->face_after) {
        for (int j = 0; j < 5; j++) {
            int m = 3 + j % 2;
            put_val(f, v->fmt, ptype_of("uchar"), j, 1);
            put_val(f, v->fmt, ptype_of("ushort"), m, 0);
            for (int k = 0; k < m; k++) put_val(f, v->fmt, ptype_of("uint32"), j + k, 0);
            put_val(f, v->fmt, ptype_of("float"), 0.5 * j, 0);
            if (v->fmt == ASC) fputs(eol, f);
        }
    }
    assert_int_equal(fclose(f), 0);
    return buf;
}

static const variant variants[] = {
    {"v0_ascii.ply", ASC, 0,
     {"float x", "float y", "float z", "uchar red", "uchar green", "uchar blue", "float nx",
      "float ny", "float nz"}, 1, 0},
    {"v1_le_double_ushort.ply", LE, 0,
     {"float nz", "ushort blue", "double x", "float ny", "ushort green", "double z", "float nx",
      "ushort red", "double y"}, 0, 1},
    {"v2_be_floatcolour.ply", BE, 0,
     {"float32 y", "float red", "float64 z", "float green", "float32 nx", "float64 x",
      "float blue", "float ny", "float nz"}, 1, 1},
    {"v3_ascii_crlf_alpha.ply", ASC, 1,
     {"double z", "uchar r", "uchar g", "uchar b", "uchar alpha", "double x", "double y",
      "float nz", "float ny", "float nx"}, 0, 1},
    {"v4_be_extras.ply", BE, 0,
     {"int8 dummy", "uint8 red", "uint16 unused", "uint8 green", "uint8 blue", "double x",
      "double y", "double z", "float nx", "float ny", "float nz", "int32 other"}, 1, 0},
    {"v5_le_diffuse.ply", LE, 0,
     {"float x", "float y", "float z", "uchar diffuse_red", "uchar diffuse_green",
      "uchar diffuse_blue", "double nx", "double ny", "double nz", "short s16"}, 1, 1},
    {"v6_ascii_ushort_double.ply", ASC, 0,
     {"double x", "ushort red", "double y", "ushort green", "ushort blue", "double z",
      "double nx", "double ny", "double nz"}, 1, 1},
};
#define NVARIANTS (sizeof variants / sizeof variants[0])

/* Every variant loads to the generator's numbers: exact positions (all multiples of 1/8),
 * exact colours, normals within 1e-6 (float storage of unit vectors). */
static void synthetic_same(void **state)
{
    const char *tmp = *state;
    char path[1024];
    for (size_t v = 0; v < NVARIANTS; v++) {
        pc_cloud c;
        tu_load_ok(write_variant(tmp, &variants[v], path, sizeof path), &c);
        assert_int_equal(c.n, SYN_N);
        assert_int_equal(c.n_dropped, 0);
        assert_int_equal(c.attrs, PC_ATTR_RGB | PC_ATTR_NORMAL);
        ref_box b = {0};
        for (int i = 0; i < SYN_N; i++) {
            double p[3], n[3];
            int col[3];
            syn_point(i, p);
            syn_normal(i, n);
            syn_colour(i, col);
            box_add(&b, p);
            tu_check_point(&c, (size_t)i, p, 0.0);
            for (int k = 0; k < 3; k++) {
                if (c.rgba[4 * i + k] != col[k])
                    fail_msg("%s point %d colour %d: %d != %d", variants[v].file, i, k,
                             c.rgba[4 * i + k], col[k]);
                assert_true(fabs(c.normal[3 * i + k] - n[k]) < 1e-6);
            }
            assert_int_equal(c.rgba[4 * i + 3], 255);
        }
        check_box(&c, &b);
        pc_cloud_free(&c);
    }
}

/* Georeferenced double coordinates survive in every encoding: the reader keeps double until
 * re-centring, so pos + offset is within float rounding of a ~10 m extent (1e-6 m). */
static void synthetic_georef(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const int fmts[3] = {ASC, LE, BE};
    for (int v = 0; v < 3; v++) {
        snprintf(path, sizeof path, "%s/geo%d.ply", tmp, v);
        FILE *f = fopen(path, "wb");
        assert_non_null(f);
        fprintf(f, "ply\nformat %s 1.0\nelement vertex 25\nproperty double x\nproperty double y\n"
                   "property double z\nend_header\n",
                v == 0 ? "ascii" : v == 1 ? "binary_little_endian" : "binary_big_endian");
        for (int i = 0; i < 25; i++) {
            double p[3] = {665171.123456789 + 0.37 * i, 5648340.987654321 + 0.41 * i,
                           233.5 + 0.05 * i};
            for (int k = 0; k < 3; k++) put_val(f, fmts[v], ptype_of("double"), p[k], k == 0);
            if (v == 0) fputc('\n', f);
        }
        fclose(f);
        pc_cloud c;
        tu_load_ok(path, &c);
        assert_int_equal(c.n, 25);
        for (int i = 0; i < 25; i++) {
            double p[3] = {665171.123456789 + 0.37 * i, 5648340.987654321 + 0.41 * i,
                           233.5 + 0.05 * i};
            tu_check_point(&c, (size_t)i, p, 1e-6);
        }
        assert_true(fabs(c.bmin[0] - 665171.123456789) < 1e-9);
        assert_true(fabs(c.bmax[1] - (5648340.987654321 + 0.41 * 24)) < 1e-9);
        pc_cloud_free(&c);
    }
}

/* quality/confidence/scalar_* go to scalar with quality first; intensity and radius to their
 * own arrays; 'scale' is a radius too. */
static void synthetic_attrs(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const variant a = {"attrs.ply", BE, 0,
                       {"float x", "float y", "float z", "float scalar_a", "float confidence",
                        "float quality", "ushort intensity", "float radius"}, 0, 0};
    const variant b = {"attrs2.ply", ASC, 0,
                       {"float x", "float y", "float z", "int scalar_a", "double confidence",
                        "float radius", "float red"}, 0, 0};
    pc_cloud c;
    tu_load_ok(write_variant(tmp, &a, path, sizeof path), &c);
    assert_int_equal(c.attrs, PC_ATTR_SCALAR | PC_ATTR_INTENSITY | PC_ATTR_RADIUS);
    assert_string_equal(c.scalar_name, "quality");
    for (int i = 0; i < SYN_N; i++) {
        assert_true(c.scalar[i] == (float)(0.5 * i));
        assert_true(c.intensity[i] == 3.0f * i);
        assert_true(c.radius[i] == (float)(0.01 * (i + 1)));
    }
    pc_cloud_free(&c);
    /* Colour scaling rounds to nearest: ushort 32767 -> 127.498 -> 127, 32768 -> 127.504 -> 128;
     * float 0.5 -> 127.5 -> 128, 0.498 -> 126.99 -> 127; out of range clamps to 0 and 255. */
    write_text(tmp, "round.ply",
               "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
               "property float z\nproperty ushort red\nproperty ushort green\n"
               "property ushort blue\nproperty float diffuse_red\nend_header\n"
               "0 0 0 32767 32768 65535 0\n1 1 1 0 257 514 0\n", path, sizeof path);
    tu_load_ok(path, &c);
    assert_memory_equal(c.rgba, ((uint8_t[]){127, 128, 255, 255, 0, 1, 2, 255}), 8);
    pc_cloud_free(&c);
    write_text(tmp, "roundf.ply",
               "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
               "property float z\nproperty double r\nproperty float g\nproperty float b\n"
               "end_header\n0 0 0 0.5 0.498 1.5\n1 1 1 -0.2 0.00196 1\n", path, sizeof path);
    tu_load_ok(path, &c);
    assert_memory_equal(c.rgba, ((uint8_t[]){128, 127, 255, 255, 0, 0, 255, 255}), 8);
    pc_cloud_free(&c);

    /* Without quality, confidence wins over scalar_a; a lone 'red' is not a colour. */
    tu_load_ok(write_variant(tmp, &b, path, sizeof path), &c);
    assert_int_equal(c.attrs, PC_ATTR_SCALAR | PC_ATTR_RADIUS);
    assert_string_equal(c.scalar_name, "confidence");
    assert_true(c.scalar[7] == 107.0f);
    pc_cloud_free(&c);
}

/* Every synthetic variant cut inside the header, at its end, inside the data and at the last
 * byte (ascii: at the last value). */
static void synthetic_truncated(void **state)
{
    const char *tmp = *state;
    char path[1024], cut[1200];
    for (size_t v = 0; v < NVARIANTS; v++) {
        size_t len;
        uint8_t *d = tu_read_file(write_variant(tmp, &variants[v], path, sizeof path), &len);
        assert_non_null(d);
        size_t h = header_len(d, len);
        size_t last = variants[v].fmt == ASC ? last_token(d, len) : len - 1;
        size_t cuts[] = {3, h / 2, h - 1, h, h + 5, h + (len - h) / 2, last};
        for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
            char name[96];
            snprintf(name, sizeof name, "cut%zu_%s", cuts[k], variants[v].file);
            int want = cuts[k] == 3 ? SD_EFORMAT : SD_ETRUNC; /* "ply" without its newline */
            expect_fail(write_cut(tmp, name, d, cuts[k], cut, sizeof cut), want);
        }
        free(d);
    }
}

/* ------------------------------------------------------------------ broken headers and data */

static void broken(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const char *hdr = "format ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                      "property float z\nend_header\n";
    char text[1024];

    snprintf(text, sizeof text, "plx\n%s1 2 3\n4 5 6\n", hdr);
    expect_fail(write_text(tmp, "magic.ply", text, path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "empty.ply", "", path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "format.ply",
                           "ply\nformat binary_middle_endian 1.0\nelement vertex 1\n"
                           "property float x\nproperty float y\nproperty float z\nend_header\n",
                           path, sizeof path), SD_EUNSUP);
    expect_fail(write_text(tmp, "version.ply",
                           "ply\nformat ascii 2.0\nelement vertex 1\nproperty float x\n"
                           "property float y\nproperty float z\nend_header\n1 2 3\n",
                           path, sizeof path), SD_EUNSUP);
    expect_fail(write_text(tmp, "type.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty flt x\n"
                           "property float y\nproperty float z\nend_header\n1 2 3\n",
                           path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "listtype.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                           "property float y\nproperty float z\nelement face 0\n"
                           "property list float int vertex_indices\nend_header\n1 2 3\n",
                           path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "noend.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                           "property float y\nproperty float z\n",
                           path, sizeof path), SD_ETRUNC);
    expect_fail(write_text(tmp, "nox.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\n"
                           "property float z\nend_header\n1 2\n", path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "novertex.ply",
                           "ply\nformat ascii 1.0\nelement face 0\n"
                           "property list uchar int vertex_indices\nend_header\n",
                           path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "keyword.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                           "property float y\nproperty float z\nbogus line\nend_header\n1 2 3\n",
                           path, sizeof path), SD_EFORMAT);
    snprintf(text, sizeof text, "ply\n%s1 2 3\n4 abc 6\n", hdr);
    expect_fail(write_text(tmp, "nan_token.ply", text, path, sizeof path), SD_EFORMAT);
    snprintf(text, sizeof text, "ply\n%s1 2 3\n4 5\n7 8 9\n", hdr);
    expect_fail(write_text(tmp, "few.ply", text, path, sizeof path), SD_EFORMAT);
    snprintf(text, sizeof text, "ply\n%s1 2 3\n4 5 6 7\n", hdr);
    expect_fail(write_text(tmp, "many.ply", text, path, sizeof path), SD_EFORMAT);
    snprintf(text, sizeof text, "ply\n%s1 2 3\n", hdr);
    expect_fail(write_text(tmp, "count.ply", text, path, sizeof path), SD_ETRUNC);
    expect_fail(write_text(tmp, "count_huge.ply",
                           "ply\nformat ascii 1.0\nelement vertex 281474976710656\n"
                           "property float x\nproperty float y\nproperty float z\nend_header\n"
                           "1 2 3\n", path, sizeof path), SD_ETRUNC);
    expect_fail(write_text(tmp, "count_overflow.ply",
                           "ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\n"
                           "property float x\nproperty float y\nproperty float z\nend_header\n",
                           path, sizeof path), SD_EFORMAT);
    expect_fail(write_text(tmp, "bin_huge.ply",
                           "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n"
                           "property double x\nproperty double y\nproperty double z\n"
                           "end_header\n0123456789abcdef01234567", path, sizeof path),
                SD_ETRUNC);

    /* Comment lines may be long; other header lines may not. */
    char longc[3000];
    memset(longc, 'c', sizeof longc);
    memcpy(longc, "ply\nformat ascii 1.0\ncomment ", 29);
    snprintf(longc + 2000, sizeof longc - 2000, "\nelement vertex 1\nproperty float x\n"
             "property float y\nproperty float z\nend_header\n1 2 3\n");
    pc_cloud c1;
    tu_load_ok(write_text(tmp, "longcomment.ply", longc, path, sizeof path), &c1);
    assert_int_equal(c1.n, 1);
    pc_cloud_free(&c1);
    memcpy(longc + 21, "element", 7);
    expect_fail(write_text(tmp, "longline.ply", longc, path, sizeof path), SD_EFORMAT);

    /* Binary list elements before the vertex: a negative count, and a count past the end. */
    static const uint8_t neg[] = "ply\nformat binary_little_endian 1.0\nelement face 1\n"
                                 "property list char int vertex_indices\nelement vertex 1\n"
                                 "property float x\nproperty float y\nproperty float z\n"
                                 "end_header\n\xff";
    uint8_t buf[256];
    memcpy(buf, neg, sizeof neg - 1);
    memset(buf + sizeof neg - 1, 0, 12);
    expect_fail(write_cut(tmp, "negcount.ply", buf, sizeof neg - 1 + 12, path, sizeof path),
                SD_EFORMAT);
    buf[sizeof neg - 2] = 100; /* 100 ints = 400 bytes, only 12 follow */
    expect_fail(write_cut(tmp, "listlong.ply", buf, sizeof neg - 1 + 12, path, sizeof path),
                SD_ETRUNC);
    buf[sizeof neg - 2] = 0; /* an empty list, then the 12-byte vertex: valid */
    pc_cloud c;
    tu_load_ok(write_cut(tmp, "listok.ply", buf, sizeof neg - 1 + 12, path, sizeof path), &c);
    assert_int_equal(c.n, 1);
    pc_cloud_free(&c);
}

/* A list property inside the vertex element (variable-size binary records) is skipped. */
static void vertex_with_list(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const char *h = "ply\nformat %s 1.0\nelement vertex 3\nproperty float x\n"
                    "property list uchar int idx\nproperty float y\nproperty float z\n"
                    "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
    char text[1024];
    snprintf(text, sizeof text, h, "ascii");
    strcat(text, "1 2 7 8 2 3 10 20 30\n4 0 5 6 40 50 60\n7 3 1 2 3 8 9 70 80 90\n");
    pc_cloud c;
    tu_load_ok(write_text(tmp, "vlist.ply", text, path, sizeof path), &c);
    assert_int_equal(c.n, 3);
    tu_check_point(&c, 2, (double[]){7, 8, 9}, 0);
    assert_memory_equal(c.rgba + 4, ((uint8_t[]){40, 50, 60, 255}), 4);
    pc_cloud_free(&c);

    uint8_t bin[1024];
    snprintf((char *)bin, sizeof bin, h, "binary_big_endian");
    size_t n = strlen((char *)bin);
    const int counts[3] = {2, 0, 3};
    for (int i = 0; i < 3; i++) {
        float p[3] = {1.0f + 3 * i, 2.0f + 3 * i, 3.0f + 3 * i};
        uint8_t be[4];
        for (int k = 0; k < 3; k++) {
            if (k == 1) {
                bin[n++] = (uint8_t)counts[i];
                for (int j = 0; j < counts[i]; j++) {
                    memcpy(bin + n, "\0\0\0\x07", 4);
                    n += 4;
                }
            }
            uint32_t u;
            memcpy(&u, &p[k], 4);
            be[0] = (uint8_t)(u >> 24), be[1] = (uint8_t)(u >> 16), be[2] = (uint8_t)(u >> 8);
            be[3] = (uint8_t)u;
            memcpy(bin + n, be, 4);
            n += 4;
        }
        for (int k = 0; k < 3; k++) bin[n++] = (uint8_t)(10 * (3 * i + k + 1));
    }
    tu_load_ok(write_cut(tmp, "vlist_be.ply", bin, n, path, sizeof path), &c);
    assert_int_equal(c.n, 3);
    tu_check_point(&c, 1, (double[]){4, 5, 6}, 0);
    tu_check_point(&c, 2, (double[]){7, 8, 9}, 0);
    assert_memory_equal(c.rgba + 8, ((uint8_t[]){70, 80, 90, 255}), 4);
    pc_cloud_free(&c);
    expect_fail(write_cut(tmp, "vlist_be_cut.ply", bin, n - 1, path, sizeof path), SD_ETRUNC);
}

/* 10 MB of header: comment lines without end_header (absurd size), and random bytes. */
static void absurd_header(void **state)
{
    const char *tmp = *state;
    char path[1024];
    size_t n = 10u << 20;
    char *g = malloc(n);
    assert_non_null(g);
    memcpy(g, "ply\nformat ascii 1.0\n", 21);
    for (size_t i = 21; i < n; i++) { /* lines of "comment xxx...x" */
        size_t col = (i - 21) % 64;
        g[i] = col == 63 ? '\n' : col < 8 ? "comment "[col] : 'x';
    }
    expect_fail(write_cut(tmp, "comments.ply", (uint8_t *)g, n, path, sizeof path), SD_ELIMIT);
    uint64_t s = 88172645463325252ull;
    for (size_t i = 4; i < n; i++) {
        s ^= s << 13, s ^= s >> 7, s ^= s << 17;
        g[i] = (char)(s >> 24);
    }
    int rc;
    pc_cloud c;
    sd_err e = {0};
    write_cut(tmp, "garbage.ply", (uint8_t *)g, n, path, sizeof path);
    rc = pc_load(path, &c, &e);
    assert_true(rc == SD_EFORMAT || rc == SD_ELIMIT);
    assert_non_null(strstr(e.msg, "line"));
    free(g);
}

/* Zero vertices is SD_EEMPTY from pc_load; NaN/inf points are dropped and counted. */
static void empty_and_nan(void **state)
{
    const char *tmp = *state;
    char path[1024];
    pc_cloud c;
    sd_err e = {0};
    write_text(tmp, "zero.ply",
               "ply\nformat binary_big_endian 1.0\nelement vertex 0\nproperty float x\n"
               "property float y\nproperty float z\nend_header\n", path, sizeof path);
    assert_int_equal(pc_load(path, &c, &e), SD_EEMPTY);
    assert_non_null(strstr(e.msg, path));
    write_text(tmp, "nan.ply",
               "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
               "property float z\nproperty uchar red\nproperty uchar green\n"
               "property uchar blue\nend_header\n"
               "1 2 3 10 20 30\nnan 2 3 0 0 0\n4 inf 6 0 0 0\n7 8 -inf 0 0 0\n-NaN 1 1 0 0 0\n"
               "9 8 7 40 50 60\n", path, sizeof path);
    tu_load_ok(path, &c);
    assert_int_equal(c.n, 2);
    assert_int_equal(c.n_dropped, 4);
    tu_check_point(&c, 1, (double[]){9, 8, 7}, 0);
    assert_memory_equal(c.rgba + 4, ((uint8_t[]){40, 50, 60, 255}), 4);
    pc_cloud_free(&c);
    /* Binary: a float NaN in y of the first of three points. */
    uint8_t bin[512];
    const char *h = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nend_header\n";
    size_t hl = strlen(h);
    memcpy(bin, h, hl);
    float v[9] = {1, NAN, 3, 4, 5, 6, 7, 8, 9};
    memcpy(bin + hl, v, sizeof v);
    tu_load_ok(write_cut(tmp, "nan_bin.ply", bin, hl + sizeof v, path, sizeof path), &c);
    assert_int_equal(c.n, 2);
    assert_int_equal(c.n_dropped, 1);
    tu_check_point(&c, 0, (double[]){4, 5, 6}, 0);
    pc_cloud_free(&c);
}

/* A 1M-point binary PLY (float xyz + uchar rgb, 15 MB): checks the count and two points and
 * prints the read time (the goal is well under 100 ms in the optimised build). */
static void million(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const size_t n = 1000000;
    const char *h = "ply\nformat binary_little_endian 1.0\nelement vertex 1000000\n"
                    "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
                    "property uchar green\nproperty uchar blue\nend_header\n";
    size_t hl = strlen(h), len = hl + 15 * n;
    uint8_t *d = malloc(len);
    assert_non_null(d);
    memcpy(d, h, hl);
    for (size_t i = 0; i < n; i++) {
        float p[3] = {(float)(i % 1000), (float)(i / 1000), (float)(i % 7) * 0.5f};
        memcpy(d + hl + 15 * i, p, 12);
        d[hl + 15 * i + 12] = (uint8_t)i;
        d[hl + 15 * i + 13] = (uint8_t)(i >> 8);
        d[hl + 15 * i + 14] = 7;
    }
    write_cut(tmp, "million.ply", d, len, path, sizeof path);
    free(d);
    double best = 1e9;
    for (int r = 0; r < 3; r++) {
        pc_raw raw = {0};
        sd_err e = {0};
        double t0 = now_ms();
        assert_int_equal(pc_read_ply(path, &raw, &e), 0);
        double t = now_ms() - t0;
        if (t < best) best = t;
        assert_int_equal(raw.n, n);
        assert_true(raw.xyz[3 * 123456] == 456 && raw.xyz[3 * 123456 + 1] == 123);
        assert_true(raw.xyz[3 * 123456 + 2] == 0.5 * (123456 % 7));
        assert_int_equal(raw.rgba[4 * 999999], (uint8_t)999999);
        assert_int_equal(raw.rgba[4 * 999999 + 1], (uint8_t)(999999 >> 8));
        pc_raw_free(&raw);
    }
    printf("# 1M-point binary PLY pc_read_ply: best of 3 %.1f ms\n", best);
}

/* ------------------------------------------------------------------ every type and byte order */

/* The type matrix: one file per (encoding, type name, record shape) in which every vertex
 * property the reader uses -- x y z, red green blue alpha, nx ny nz, quality (the scalar),
 * intensity and radius -- has that one type. The values are random over the type's whole range
 * (so every byte of a multi-byte value matters and a missing or wrong byte swap changes it),
 * written byte by byte by iotest.h's writers, and every point is compared with what was
 * written. The record shapes are fixed-size records (the reader's column decoder) and records
 * with a list property in the vertex element (its record-by-record decoder). */

#define MX_N 48

typedef struct mx_type {
    const char *name; /* as written in the header */
    unsigned size;
    int flt;          /* a float type */
    int sgn;          /* a signed integer type */
} mx_type;

static const mx_type mx_types[] = {
    {"char", 1, 0, 1},  {"int8", 1, 0, 1},   {"uchar", 1, 0, 0},  {"uint8", 1, 0, 0},
    {"short", 2, 0, 1}, {"int16", 2, 0, 1},  {"ushort", 2, 0, 0}, {"uint16", 2, 0, 0},
    {"int", 4, 0, 1},   {"int32", 4, 0, 1},  {"uint", 4, 0, 0},   {"uint32", 4, 0, 0},
    {"float", 4, 1, 0}, {"float32", 4, 1, 0}, {"double", 8, 1, 0}, {"float64", 8, 1, 0},
};
#define MX_NTYPES (sizeof mx_types / sizeof mx_types[0])

enum { MP_X, MP_Y, MP_Z, MP_R, MP_G, MP_B, MP_A, MP_NX, MP_NY, MP_NZ, MP_Q, MP_I, MP_RAD, MP_N };
static const char *const mx_prop[MP_N] = {"x",  "y",  "z",  "red",     "green",     "blue",
                                          "alpha", "nx", "ny", "nz", "quality", "intensity",
                                          "radius"};

/* A random value of type t: integers over their whole range; floats of random sign with
 * magnitudes from 1e-3 to 1e5 (float, rounded to float) or 1e-3 to 1e7 (double, all 53 bits,
 * so a double read as float or through float loses digits). */
static double mx_any(rng *r, const mx_type *t)
{
    if (t->flt) {
        double v = (2 * uni(r) - 1) * pow(10, (int)(next64(r) % (t->size == 4 ? 9 : 11)) - 3);
        return t->size == 4 ? (double)(float)v : v;
    }
    unsigned bits = 8 * t->size;
    uint64_t m = next64(r) & ((1ull << bits) - 1);
    return t->sgn ? (double)((int64_t)m - (int64_t)(1ull << (bits - 1))) : (double)m;
}

/* A colour channel of type t. 8- and 16-bit integers: any value. 32-bit integers: 1..254, so
 * that a value read with the wrong byte order or width (a multiple of 2^8) clamps to 0 or 255
 * and differs. Floats: -0.2..1.2, which covers both clamps. */
static double mx_colour(rng *r, const mx_type *t)
{
    if (t->flt) {
        double v = 1.4 * uni(r) - 0.2;
        return t->size == 4 ? (double)(float)v : v;
    }
    if (t->size == 4) return (double)(1 + next64(r) % 254);
    return mx_any(r, t);
}

/* A normal component of type t: integers over their range, floats in -3..3 (not unit length,
 * so the reader must normalise). */
static double mx_normal(rng *r, const mx_type *t)
{
    if (!t->flt) return mx_any(r, t);
    double v = 6 * uni(r) - 3;
    return t->size == 4 ? (double)(float)v : v;
}

/* The colour PLY promises for channel value v of type t: 16-bit integers scale by 255/65535,
 * floats by 255, other integers are taken as 0..255; then clamp and round to nearest. The
 * 16-bit quotient is never within 1/514 of a half, so the two ways of dividing agree. */
static int mx_col8(double v, const mx_type *t)
{
    double x = t->flt ? v * 255.0 : t->size == 2 ? v / 257.0 : v;
    if (!(x > 0)) return 0;
    if (x >= 255) return 255;
    return (int)floor(x + 0.5);
}

/* Appends value v of type t in encoding fmt and returns what a correct reader must make of it:
 * v itself in binary, the correctly rounded double of the written token in ascii. */
static double mx_put(io_buf *b, int fmt, const mx_type *t, double v)
{
    if (fmt == ASC) {
        char tok[48];
        if (t->flt) snprintf(tok, sizeof tok, t->size == 4 ? "%.9g" : "%.17g", v);
        else snprintf(tok, sizeof tok, "%lld", (long long)v);
        io_printf(b, " %s", tok);
        return strtod(tok, NULL);
    }
    if (t->flt && t->size == 4) io_put_f32(b, (float)v, fmt == BE);
    else if (t->flt) io_put_f64(b, v, fmt == BE);
    else io_put_uint(b, (uint64_t)(int64_t)v, t->size, fmt == BE);
    return v;
}

/* Writes the matrix file for (fmt, t, list) into dir; want[MX_N][MP_N] gets what each
 * property of each point must read as. */
static const char *mx_write(const char *dir, int fmt, const mx_type *t, int list,
                            double want[MX_N][MP_N], char *path, size_t len)
{
    static const char *fmts[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    io_buf b = {0};
    rng r = {0x5eed0000u + 97u * (unsigned)fmt + 7u * t->size + (unsigned)list + 1000u * t->flt};
    io_printf(&b, "ply\nformat %s 1.0\ncomment type matrix %s\nelement vertex %d\n"
                  "property uchar flags\n", fmts[fmt], t->name, MX_N);
    for (int p = 0; p < MP_N; p++) {
        io_printf(&b, "property %s %s\n", t->name, mx_prop[p]);
        if (p == MP_Z && list) io_printf(&b, "property list uchar %s idx\n", t->name);
    }
    io_printf(&b, "property double trailer\nend_header\n");
    const mx_type *uchar = &mx_types[2], *dbl = &mx_types[14];
    for (int i = 0; i < MX_N; i++) {
        mx_put(&b, fmt, uchar, (double)(next64(&r) % 256));
        for (int p = 0; p < MP_N; p++) {
            double v = p >= MP_R && p <= MP_A     ? mx_colour(&r, t)
                       : p >= MP_NX && p <= MP_NZ ? mx_normal(&r, t)
                                                  : mx_any(&r, t);
            want[i][p] = mx_put(&b, fmt, t, v);
            if (p == MP_Z && list) {
                int m = i % 4;
                mx_put(&b, fmt, uchar, m);
                for (int j = 0; j < m; j++) mx_put(&b, fmt, t, mx_any(&r, t));
            }
        }
        mx_put(&b, fmt, dbl, mx_any(&r, dbl));
        if (fmt == ASC) io_printf(&b, "\n");
    }
    char name[96];
    snprintf(name, sizeof name, "mx_%s_%s%s.ply", fmts[fmt], t->name, list ? "_list" : "");
    io_save(&b, dir, name, path, len);
    io_free(&b);
    return path;
}

/* Checks the reader's output for one matrix file against want, point by point: positions
 * exactly (raw doubles, and pos + offset after pc_load within float rounding), colours and
 * alpha exactly, normals as the unit vector of what was written (within float rounding),
 * quality/intensity/radius exactly as float. */
static void mx_check(const char *path, const mx_type *t, double want[MX_N][MP_N])
{
    double xyz[3 * MX_N];
    for (int i = 0; i < MX_N; i++)
        for (int k = 0; k < 3; k++) xyz[3 * i + k] = want[i][MP_X + k];
    pc_raw raw;
    io_read_ok(pc_read_ply, path, &raw);
    assert_int_equal(raw.attrs, PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_SCALAR |
                                    PC_ATTR_INTENSITY | PC_ATTR_RADIUS);
    assert_string_equal(raw.scalar_name, "quality");
    io_check_raw_xyz(&raw, xyz, MX_N, 0, path);
    for (int i = 0; i < MX_N; i++) {
        for (int k = 0; k < 4; k++) {
            int w = mx_col8(want[i][MP_R + k], t);
            if (raw.rgba[4 * i + k] != w)
                fail_msg("%s: point %d channel %d: read %d, want %d (written %.17g)", path, i, k,
                         raw.rgba[4 * i + k], w, want[i][MP_R + k]);
        }
        double l = 0;
        for (int k = 0; k < 3; k++) l += want[i][MP_NX + k] * want[i][MP_NX + k];
        l = sqrt(l);
        for (int k = 0; k < 3; k++) {
            double w = l > 0 ? want[i][MP_NX + k] / l : 0;
            if (!(fabs(raw.normal[3 * i + k] - w) <= 2e-6))
                fail_msg("%s: point %d normal %d: read %.9g, want %.9g", path, i, k,
                         raw.normal[3 * i + k], w);
        }
        const float sc[3] = {raw.scalar[i], raw.intensity[i], raw.radius[i]};
        for (int k = 0; k < 3; k++)
            if (sc[k] != (float)want[i][MP_Q + k])
                fail_msg("%s: point %d %s: read %.9g, want %.9g", path, i, mx_prop[MP_Q + k],
                         sc[k], (float)want[i][MP_Q + k]);
    }
    pc_raw_free(&raw);
    pc_cloud c;
    tu_load_ok(path, &c);
    io_check_cloud_xyz(&c, xyz, MX_N, 0, path);
    pc_cloud_free(&c);
}

/* Every type name the reader accepts (int8..float64 and the aliases char..double), in ascii,
 * binary_little_endian and binary_big_endian, with fixed-size and list-bearing records, for
 * positions, colours, normals and the scalar properties. A byte swap missing or applied to
 * the wrong type, a type read at the wrong width or signedness, a colour scaled for the wrong
 * type or a property decoded into the wrong array fails here, naming file, point and field. */
static void type_matrix(void **state)
{
    const char *tmp = *state;
    char path[1024];
    static double want[MX_N][MP_N];
    for (int fmt = ASC; fmt <= BE; fmt++)
        for (size_t ti = 0; ti < MX_NTYPES; ti++)
            for (int list = 0; list < 2; list++) {
                mx_write(tmp, fmt, &mx_types[ti], list, want, path, sizeof path);
                mx_check(path, &mx_types[ti], want);
            }
}

/* The same cloud as one file mixing every type, in each byte order: positions in int16, int32
 * and double, colours in uchar/ushort/float, normals in char/short/int: the per-slot offsets
 * within a record of mixed widths are right and each slot uses its own type. */
static void mixed_types(void **state)
{
    const char *tmp = *state;
    char path[1024];
    const char *types[MP_N] = {"int16", "int32", "double", "uchar", "ushort", "float",
                               "uint16", "char",  "short", "int",   "uint",   "float64",
                               "int8"};
    for (int fmt = ASC; fmt <= BE; fmt++) {
        io_buf b = {0};
        rng r = {0xabcdefu + (unsigned)fmt};
        static const char *fmts[] = {"ascii", "binary_little_endian", "binary_big_endian"};
        io_printf(&b, "ply\nformat %s 1.0\nelement vertex %d\n", fmts[fmt], MX_N);
        const mx_type *t[MP_N];
        for (int p = 0; p < MP_N; p++) {
            t[p] = NULL;
            for (size_t k = 0; k < MX_NTYPES; k++)
                if (!strcmp(mx_types[k].name, types[p])) t[p] = &mx_types[k];
            assert_non_null(t[p]);
            io_printf(&b, "property %s %s\n", types[p], mx_prop[p]);
        }
        io_printf(&b, "end_header\n");
        double want[MX_N][MP_N], xyz[3 * MX_N];
        for (int i = 0; i < MX_N; i++) {
            for (int p = 0; p < MP_N; p++) {
                double v = p >= MP_R && p <= MP_A     ? mx_colour(&r, t[p])
                           : p >= MP_NX && p <= MP_NZ ? mx_normal(&r, t[p])
                                                      : mx_any(&r, t[p]);
                want[i][p] = mx_put(&b, fmt, t[p], v);
            }
            if (fmt == ASC) io_printf(&b, "\n");
            for (int k = 0; k < 3; k++) xyz[3 * i + k] = want[i][k];
        }
        char name[64];
        snprintf(name, sizeof name, "mixed_%d.ply", fmt);
        io_save(&b, tmp, name, path, sizeof path);
        io_free(&b);
        pc_raw raw;
        io_read_ok(pc_read_ply, path, &raw);
        io_check_raw_xyz(&raw, xyz, MX_N, 0, path);
        for (int i = 0; i < MX_N; i++) {
            for (int k = 0; k < 4; k++)
                if (raw.rgba[4 * i + k] != mx_col8(want[i][MP_R + k], t[MP_R + k]))
                    fail_msg("%s: point %d channel %d: read %d, want %d", path, i, k,
                             raw.rgba[4 * i + k], mx_col8(want[i][MP_R + k], t[MP_R + k]));
            double l = sqrt(want[i][MP_NX] * want[i][MP_NX] + want[i][MP_NY] * want[i][MP_NY] +
                            want[i][MP_NZ] * want[i][MP_NZ]);
            for (int k = 0; k < 3; k++)
                assert_true(fabs(raw.normal[3 * i + k] - (l > 0 ? want[i][MP_NX + k] / l : 0)) <=
                            2e-6);
            assert_true(raw.scalar[i] == (float)want[i][MP_Q]);
            assert_true(raw.intensity[i] == (float)want[i][MP_I]);
            assert_true(raw.radius[i] == (float)want[i][MP_RAD]);
        }
        pc_raw_free(&raw);
    }
}

/* ------------------------------------------------------------------ real files, every point */

/* Guanyin.ply, all 238,154 records decoded here from the bytes (float x y z, uchar r g b,
 * 15 bytes a record, little-endian, per its header): the raw doubles must equal the floats
 * exactly, the colours the bytes, and after pc_load pos + offset must be within float rounding
 * of each point. */
static void guanyin_every_point(void **state)
{
    (void)state;
    char path[1024];
    tu_data("Guanyin.ply", path, sizeof path);
    size_t len;
    uint8_t *d = tu_read_file(path, &len);
    assert_non_null(d);
    size_t h = header_len(d, len);
    static const char layout[] = "format binary_little_endian 1.0\nelement vertex 238154\n"
                                 "property float x\nproperty float y\nproperty float z\n"
                                 "property uchar red\nproperty uchar green\n"
                                 "property uchar blue\nend_header\n";
    assert_non_null(memmem(d, h, layout, sizeof layout - 1));
    const size_t n = 238154;
    assert_int_equal(h + 15 * n, len);
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) want[3 * i + k] = io_get_f32(d + h + 15 * i + 4 * k, 0);
    pc_raw raw;
    io_read_ok(pc_read_ply, path, &raw);
    io_check_raw_xyz(&raw, want, n, 0, "Guanyin.ply");
    for (size_t i = 0; i < n; i++)
        if (memcmp(raw.rgba + 4 * i, d + h + 15 * i + 12, 3) != 0 || raw.rgba[4 * i + 3] != 255)
            fail_msg("Guanyin.ply: point %zu colour differs", i);
    pc_raw_free(&raw);
    pc_cloud c;
    tu_load_ok(path, &c);
    io_check_cloud_xyz(&c, want, n, 0, "Guanyin.ply");
    pc_cloud_free(&c);
    free(want);
    free(d);
}

/* bun000.ply, all 40,256 vertex lines parsed here with strtod (float properties in ascii: the
 * reader keeps the double of the text, correctly rounded as io_text.h promises): the raw
 * doubles must be strtod's exactly and pos + offset within float rounding of them. */
static void bun000_every_point(void **state)
{
    (void)state;
    char path[1024];
    tu_data("bun000.ply", path, sizeof path);
    size_t len;
    uint8_t *d = tu_read_file(path, &len);
    assert_non_null(d);
    size_t h = header_len(d, len);
    assert_non_null(memmem(d, h, "\nformat ascii 1.0\n", 18));
    static const char layout[] = "element vertex 40256\nproperty float x\nproperty float y\n"
                                 "property float z\nelement range_grid";
    assert_non_null(memmem(d, h, layout, sizeof layout - 1));
    const size_t n = 40256;
    double *want = malloc(3 * n * sizeof *want);
    assert_non_null(want);
    char *s = (char *)d + h;
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) {
            char *e;
            want[3 * i + k] = strtod(s, &e);
            assert_true(e > s);
            s = e;
        }
        while (*s == ' ') s++; /* the file ends each vertex line with a space */
        assert_true(*s == '\n');
        s++;
    }
    pc_raw raw;
    io_read_ok(pc_read_ply, path, &raw);
    io_check_raw_xyz(&raw, want, n, 0, "bun000.ply");
    pc_raw_free(&raw);
    pc_cloud c;
    tu_load_ok(path, &c);
    io_check_cloud_xyz(&c, want, n, 0, "bun000.ply");
    pc_cloud_free(&c);
    free(want);
    free(d);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
#define TMP_TEST(f) cmocka_unit_test_setup_teardown(f, tu_tmpdir_setup, tu_tmpdir_teardown)
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(guanyin),
        cmocka_unit_test(bun000),
        TMP_TEST(real_truncated),
        TMP_TEST(real_count_too_big),
        TMP_TEST(synthetic_same),
        TMP_TEST(synthetic_georef),
        TMP_TEST(synthetic_attrs),
        TMP_TEST(synthetic_truncated),
        TMP_TEST(broken),
        TMP_TEST(absurd_header),
        TMP_TEST(vertex_with_list),
        TMP_TEST(empty_and_nan),
        TMP_TEST(million),
        TMP_TEST(type_matrix),
        TMP_TEST(mixed_types),
        cmocka_unit_test(guanyin_every_point),
        cmocka_unit_test(bun000_every_point),
    };
#undef TMP_TEST
    return cmocka_run_group_tests(tests, NULL, NULL);
}
