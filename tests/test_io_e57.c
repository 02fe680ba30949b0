/* test_io_e57.c — the E57 reader (server/io/e57_*.c, io_e57.c) and its LOD stream.
 *
 * Real files (tests/data/e57/, SOURCES.md there) give their documented counts and bounds
 * (libE57Format 3.4), colours and normals (a second reader, tests/tools/e57_ref.py), and the
 * E57 bunny the same points as the PTS bunny of tests/data. Synthetic files come from the
 * writer of tests/common/e57test.c, made apart from the reader: every integer width 1-64, scaled
 * integers, floats, spherical coordinates, poses, invalid states, limits, the normals
 * extension, many packets with fields out of step, index and empty packets; their decoded
 * values are checked against the values put in. Damaged files (checksums, truncation, offsets
 * and lengths past the end, lying counts, a prototype without coordinates) must be refused
 * with a message naming the place, without a crash and without allocating what they claim. */
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
#include "cloudtest.h"
#include "e57_bitpack.h"
#include "e57_pages.h"
#include "e57_stream.h"
#include "e57_xml.h"
#include "e57test.h"
#include "lod_src.h"
#include "rng.h"
#include "testutil.h"

static const char *g_tmp; /* the group's temporary directory (tu_tmpdir_setup) */

static int setup(void **state)
{
    int rc = tu_tmpdir_setup(state);
    g_tmp = *state;
    return rc;
}

static const char *tmp_path(const char *name, char *buf, size_t len)
{
    snprintf(buf, len, "%s/%s", g_tmp, name);
    return buf;
}

/* expect_fail: pc_load of path fails with code and a message holding path and each of the
 * NULL-terminated strings that follow. */
static void expect_fail(const char *path, int code, ...)
{
    pc_cloud c;
    sd_err e = {0};
    int rc = pc_load(path, &c, &e);
    if (rc != code || e.code != code)
        fail_msg("%s: got %d (%s), expected %d (%s); message: %s", path, rc, sd_strerror(rc), code,
                 sd_strerror(code), e.msg);
    if (!strstr(e.msg, path)) fail_msg("the message does not name the file: %s", e.msg);
    va_list ap;
    va_start(ap, code);
    for (const char *w; (w = va_arg(ap, const char *)) != NULL;)
        if (!strstr(e.msg, w)) fail_msg("the message lacks '%s': %s", w, e.msg);
    va_end(ap);
    assert_null(c.pos);
}

static void read_raw_ok(const char *path, pc_raw *raw)
{
    sd_err e = {0};
    memset(raw, 0, sizeof *raw);
    int rc = pc_read_e57(path, raw, &e);
    if (rc) fail_msg("%s: %s", path, e.msg);
}

/* ---- the shared files ---- */

typedef struct shared_file {
    const char *name;
    size_t n;
    double lo[3], hi[3];
    uint32_t attrs;
} shared_file;

/* SOURCES.md: valid points and bounds as libE57Format 3.4 reports them. */
static const shared_file shared[] = {
    {"bunnyDouble.e57", 30571, {-0.094689, 0.040011, -0.061873}, {0.061009, 0.187321, 0.058799}, 0},
    {"ColouredCubeDouble.e57", 7680, {-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}, PC_ATTR_RGB},
    {"ColouredCubeFloat.e57", 7680, {-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}, PC_ATTR_RGB},
    {"ColourRepresentation.e57", 153, {-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}, PC_ATTR_RGB},
    {"testWithNormals.e57", 2, {1, 0, 0}, {2, 0, 0}, PC_ATTR_NORMAL},
    {"translationWithoutRotation.e57", 4, {4, 5, 6}, {5, 6, 6}, 0},
};

static void test_shared_counts_bounds(void **state)
{
    (void)state;
    for (size_t f = 0; f < sizeof shared / sizeof shared[0]; f++) {
        char p[1024], name[256];
        snprintf(name, sizeof name, "e57/%s", shared[f].name);
        pc_cloud c;
        tu_load_ok(tu_data(name, p, sizeof p), &c);
        if (c.n != shared[f].n)
            fail_msg("%s: %zu points, SOURCES.md says %zu", name, c.n, shared[f].n);
        assert_int_equal(c.n_dropped, 0);
        assert_int_equal(c.attrs, shared[f].attrs);
        assert_string_equal(c.format, "E57 1.0, 1 scan");
        for (int k = 0; k < 3; k++)
            if (fabs(c.bmin[k] - shared[f].lo[k]) > 1e-12 ||
                fabs(c.bmax[k] - shared[f].hi[k]) > 1e-12)
                fail_msg("%s axis %d: [%.17g, %.17g], expected [%.17g, %.17g]", name, k, c.bmin[k],
                         c.bmax[k], shared[f].lo[k], shared[f].hi[k]);
        pc_cloud_free(&c);
    }
}

static int cmp_xyz(const void *a, const void *b)
{
    const double *p = a, *q = b;
    for (int k = 0; k < 3; k++)
        if (p[k] != q[k]) return p[k] < q[k] ? -1 : 1;
    return 0;
}

/* The E57 bunny and the PTS bunny of tests/data (Open3D's bunnyData.pts, another writer's copy
 * of the same Stanford scan) hold the same 30,571 points, in another order: sorted, each agrees
 * to the PTS file's six decimals. */
static void test_bunny_matches_pts(void **state)
{
    (void)state;
    char p[1024];
    pc_raw a, b;
    read_raw_ok(tu_data("e57/bunnyDouble.e57", p, sizeof p), &a);
    memset(&b, 0, sizeof b);
    sd_err e = {0};
    if (pc_read_xyz(tu_data("bunnyData.pts", p, sizeof p), &b, &e)) fail_msg("%s", e.msg);
    assert_int_equal(a.n, 30571);
    assert_int_equal(b.n, a.n);
    qsort(a.xyz, a.n, 3 * sizeof(double), cmp_xyz);
    qsort(b.xyz, b.n, 3 * sizeof(double), cmp_xyz);
    for (size_t i = 0; i < 3 * a.n; i++)
        if (fabs(a.xyz[i] - b.xyz[i]) > 5e-7)
            fail_msg("value %zu: %.9f vs %.9f", i, a.xyz[i], b.xyz[i]);
    pc_raw_free(&a);
    pc_raw_free(&b);
}

/* Colours: tests/tools/e57_ref.py's sums (SOURCES.md). The cubes' limits are 0-255 (the
 * values as they are); ColourRepresentation's 16-bit values (255 * 256 in las2e57's style) map
 * by the prototype's 0-65535 to 254. */
static void test_shared_colours(void **state)
{
    (void)state;
    const struct {
        const char *name;
        uint64_t sum[3];
    } want[] = {
        {"e57/ColouredCubeDouble.e57", {652800, 652800, 652800}},
        {"e57/ColouredCubeFloat.e57", {652800, 652800, 652800}},
        {"e57/ColourRepresentation.e57", {12700, 13208, 12954}},
    };
    for (size_t f = 0; f < 3; f++) {
        char p[1024];
        pc_cloud c;
        tu_load_ok(tu_data(want[f].name, p, sizeof p), &c);
        uint64_t sum[3] = {0, 0, 0};
        for (size_t i = 0; i < c.n; i++) {
            for (int k = 0; k < 3; k++) sum[k] += c.rgba[4 * i + k];
            assert_int_equal(c.rgba[4 * i + 3], 255);
        }
        for (int k = 0; k < 3; k++)
            if (sum[k] != want[f].sum[k])
                fail_msg("%s channel %d: sum %llu, expected %llu", want[f].name, k,
                         (unsigned long long)sum[k], (unsigned long long)want[f].sum[k]);
        pc_cloud_free(&c);
    }
}

/* testWithNormals: the normals e57_ref.py decodes (float32 values, identity pose). */
static void test_shared_normals_and_translation(void **state)
{
    (void)state;
    char p[1024];
    pc_raw r;
    read_raw_ok(tu_data("e57/testWithNormals.e57", p, sizeof p), &r);
    assert_int_equal(r.n, 2);
    const double n0[3] = {0.0009775161743164062, 0.0009775161743164062, 0.9999990463256836};
    const double n1[3] = {0.0009775161743164062, 0.9999990463256836, 0.0009775161743164062};
    const double xyz[6] = {1, 0, 0, 2, 0, 0};
    for (int k = 0; k < 3; k++) {
        /* normalised: the stored vectors are unit to float precision */
        assert_float_equal(r.normal[k], n0[k], 1e-6);
        assert_float_equal(r.normal[3 + k], n1[k], 1e-6);
    }
    for (int k = 0; k < 6; k++) assert_float_equal(r.xyz[k], xyz[k], 0);
    pc_raw_free(&r);
    /* a pose with a translation and no rotation: (0..1, 0..1, 0) + (4, 5, 6) */
    read_raw_ok(tu_data("e57/translationWithoutRotation.e57", p, sizeof p), &r);
    const double t[12] = {4, 5, 6, 5, 5, 6, 4, 6, 6, 5, 6, 6};
    assert_int_equal(r.n, 4);
    for (int k = 0; k < 12; k++) assert_float_equal(r.xyz[k], t[k], 0);
    pc_raw_free(&r);
}

static void test_shared_refused(void **state)
{
    (void)state;
    char p[1024];
    /* bad-crc.e57: page 0's checksum is wrong (libE57Format: "E57 exception") */
    expect_fail(tu_data("e57/bad-crc.e57", p, sizeof p), SD_EFORMAT, "bad checksum",
                "page at physical offset 0 ", NULL);
    /* InvalidCVHeader.e57: its compressed vector section has id 182, not 1 */
    expect_fail(tu_data("e57/InvalidCVHeader.e57", p, sizeof p), SD_EFORMAT, "section id 182",
                "physical offset 48", NULL);
    /* ZeroPoints.e57: one scan, 0 records; empty.e57: no scan at all */
    expect_fail(tu_data("e57/ZeroPoints.e57", p, sizeof p), SD_EEMPTY, "1 scan", "0 records", NULL);
    expect_fail(tu_data("e57/empty.e57", p, sizeof p), SD_EEMPTY, "no scans", NULL);
}

/* A file whose name says nothing is recognised by its signature. */
static void test_magic(void **state)
{
    (void)state;
    char src[1024], dst[1024];
    tu_data("e57/ColouredCubeFloat.e57", src, sizeof src);
    assert_int_equal(tu_copy_file(src, tmp_path("cube.scan", dst, sizeof dst)), 0);
    pc_cloud c;
    tu_load_ok(dst, &c);
    assert_int_equal(c.n, 7680);
    pc_cloud_free(&c);
    assert_int_equal(pc_supported_ext("a/b.E57"), 1);
}

/* ---- the layers alone ---- */

static void test_crc32c(void **state)
{
    (void)state;
    uint32_t t[256];
    e57__crc32c_init(t);
    /* the CRC-32C check value (RFC 3720 appendix B.4: "123456789") */
    assert_int_equal(e57__crc32c_table(t, (const uint8_t *)"123456789", 9), 0xE3069283u);
    e57_file f = {0};
    memcpy(f.crc_table, t, sizeof t);
    uint8_t buf[1021];
    rng r = {7};
    for (size_t i = 0; i < sizeof buf; i++) buf[i] = (uint8_t)next64(&r);
    for (size_t n = 0; n <= sizeof buf; n += 29) {
        f.hw_crc = 1; /* the instruction where this CPU has it, checked against the table */
#if defined(__x86_64__)
        f.hw_crc = __builtin_cpu_supports("sse4.2");
#endif
        uint32_t a = e57_crc32c(&f, buf, n);
        f.hw_crc = 0;
        assert_int_equal(a, e57_crc32c(&f, buf, n));
        assert_int_equal(a, e57w_crc32c(buf, n));
    }
}

/* The bit-pack decoder on a stream of every width 1-64 back to back (each value straddles
 * bytes somewhere), appended in pieces of every size, against the values put in. */
static void test_bitpack_widths(void **state)
{
    (void)state;
    rng r = {11};
    enum { PER = 37 };
    for (int w = 1; w <= 64; w++) {
        uint64_t vals[PER];
        uint8_t bytes[PER * 8 + 1] = {0};
        for (int i = 0; i < PER; i++) {
            vals[i] = w == 64 ? next64(&r) : next64(&r) & ((UINT64_C(1) << w) - 1);
            if (i == 0) vals[i] = w == 64 ? UINT64_MAX : (UINT64_C(1) << w) - 1; /* the limit */
            for (int b = 0; b < w; b++) {
                uint64_t bit = (uint64_t)i * w + b;
                bytes[bit / 8] |= (uint8_t)(((vals[i] >> b) & 1) << (bit % 8));
            }
        }
        size_t nbytes = ((size_t)PER * w + 7) / 8;
        e57_field f = {.kind = E57_INTEGER, .bits = w, .min = INT64_MIN, .max = INT64_MAX};
        if (w < 64) f.min = -5, f.max = (int64_t)((UINT64_C(1) << w) - 1) - 5;
        for (size_t piece = 1; piece <= 9; piece += 4) {
            e57_bp b = {0};
            size_t fed = 0;
            int got = 0;
            double out[PER];
            while (got < PER) {
                size_t a = e57_bp_avail(&b, w);
                if (a == 0) {
                    size_t m = nbytes - fed < piece ? nbytes - fed : piece;
                    assert_true(m > 0);
                    assert_int_equal(e57_bp_append(&b, bytes + fed, m), 0);
                    fed += m;
                    continue;
                }
                if (a > (size_t)(PER - got)) a = (size_t)(PER - got);
                assert_int_equal(e57_bp_decode(&b, &f, out + got, a), -1);
                got += (int)a;
            }
            for (int i = 0; i < PER; i++) {
                double want = (double)(int64_t)((uint64_t)f.min + vals[i]);
                if (out[i] != want)
                    fail_msg("width %d piece %zu value %d: %.17g, want %.17g", w, piece, i, out[i],
                             want);
            }
            assert_true(b.len <= piece + 8); /* only the bytes of a cut value stay */
            e57_bp_free(&b);
        }
        /* one past the maximum is refused, naming its index */
        if (w < 64 && w > 1) {
            e57_field g = f;
            g.max = g.min + (int64_t)vals[0] - 1;
            e57_bp b = {0};
            assert_int_equal(e57_bp_append(&b, bytes, nbytes), 0);
            double out[PER];
            assert_int_equal(e57_bp_decode(&b, &g, out, PER), 0);
            e57_bp_free(&b);
        }
    }
}

static void test_xml_tree(void **state)
{
    (void)state;
    static const char doc[] =
        "<?xml version=\"1.0\"?><e57Root type=\"Structure\" "
        "xmlns=\"http://www.astm.org/COMMIT/E57/2010-e57-v1.0\" xmlns:nor=\"urn:x\" "
        "xmlns:las=\"urn:las\"><a type=\"Integer\" minimum=\"3\">  7 </a><las:a type=\"Float\"/>"
        "<nor:normalX type=\"Float\"/><b type=\"String\"><![CDATA[x<y]]></b></e57Root>";
    for (size_t piece = 1; piece <= sizeof doc; piece *= 3) {
        e57_xml *x = e57_xml_new();
        sd_err e = {0};
        for (size_t i = 0; i < sizeof doc - 1; i += piece) {
            size_t m = sizeof doc - 1 - i < piece ? sizeof doc - 1 - i : piece;
            int last = i + m == sizeof doc - 1;
            if (e57_xml_feed(x, doc + i, m, last, "doc", &e)) fail_msg("%s", e.msg);
        }
        const e57_node *r = e57_xml_root(x);
        assert_non_null(r);
        assert_string_equal(r->name, "e57Root");
        const e57_node *a = e57_child(r, "a");
        assert_non_null(a);
        assert_string_equal(a->type, "Integer");
        assert_string_equal(a->text, "  7 ");
        assert_string_equal(e57_attr(a, "minimum"), "3");
        assert_int_equal(a->next->ns, E57_NS_OTHER); /* las:a is not <a> */
        assert_int_equal(a->next->next->ns, E57_NS_NOR); /* bound to the prefix nor */
        assert_string_equal(e57_child(r, "b")->text, "x<y");
        e57_xml_free(x);
    }
    /* a DOCTYPE (the way into entity expansion) and broken XML are refused with the line */
    const char *bad[] = {"<!DOCTYPE e [<!ENTITY a \"aaaa\">]><e57Root/>", "<e57Root>\n<a></b>"};
    const char *why[] = {"document type", "line 2"};
    for (int i = 0; i < 2; i++) {
        e57_xml *x = e57_xml_new();
        sd_err e = {0};
        assert_int_equal(e57_xml_feed(x, bad[i], strlen(bad[i]), 1, "doc", &e), SD_EFORMAT);
        if (!strstr(e.msg, why[i])) fail_msg("%s", e.msg);
        assert_null(e57_xml_root(x));
        e57_xml_free(x);
    }
    /* depth limit: 64 levels parse, 65 do not */
    for (int depth = 64; depth <= 65; depth++) {
        char d[2048] = "";
        for (int i = 0; i < depth; i++) strcat(d, "<a>");
        for (int i = 0; i < depth; i++) strcat(d, "</a>");
        e57_xml *x = e57_xml_new();
        sd_err e = {0};
        int rc = e57_xml_feed(x, d, strlen(d), 1, "doc", &e);
        assert_int_equal(rc, depth == 64 ? 0 : SD_ELIMIT);
        e57_xml_free(x);
    }
}

/* ---- synthetic files ---- */

/* The generators: each record's values from (scan, index). */
typedef struct gen_ctx {
    int kind;
    uint64_t seed;
    int64_t min[8];
    int bits[8];
} gen_ctx;

/* raw_int: the pseudo-random raw value of field f of record i in [min, min + 2^bits - 1]. */
static int64_t raw_int(const gen_ctx *g, uint32_t scan, uint64_t i, int f)
{
    rng r = {g->seed ^ (i * 0x9E3779B97F4A7C15ull) ^ ((uint64_t)f << 56) ^ ((uint64_t)scan << 48)};
    uint64_t v = next64(&r);
    if (g->bits[f] < 64) v &= (UINT64_C(1) << g->bits[f]) - 1;
    if (i == 0) v = g->bits[f] < 64 ? (UINT64_C(1) << g->bits[f]) - 1 : UINT64_MAX;
    return (int64_t)((uint64_t)g->min[f] + v);
}

static void gen_ints(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    const gen_ctx *g = ctx;
    for (int f = 0; f < 3; f++) ints[f] = raw_int(g, scan, i, f);
    dbls[3] = (double)i * 0.25 - 3.0; /* a double field after them */
}

/* Every integer width: cartesianX Integer of width w, cartesianY ScaledInteger of width w,
 * cartesianZ Integer of width 64 - w + 1, then a double; 300 records in packets of 7 records
 * for field 0 and 7 + 5 f for field f (the fields' buffers end in different records). */
static void test_widths_end_to_end(void **state)
{
    (void)state;
    for (int w = 1; w <= 64; w++) {
        gen_ctx g = {.seed = (uint64_t)w * 77, .bits = {w, w, 65 - w, 64}};
        g.min[0] = w == 64 ? INT64_MIN : -((int64_t)1 << (w - 1));
        g.min[1] = w >= 63 ? INT64_MIN : 1000;
        g.min[2] = 65 - w >= 63 ? INT64_MIN : -3;
        e57w_field fl[4] = {
            {"cartesianX", E57W_INT, g.min[0],
             (int64_t)((uint64_t)g.min[0] + (w == 64 ? UINT64_MAX : (UINT64_C(1) << w) - 1)), 0, 0,
             0},
            {"cartesianY", E57W_SCALED, g.min[1],
             (int64_t)((uint64_t)g.min[1] + (w == 64 ? UINT64_MAX : (UINT64_C(1) << w) - 1)), 0.001,
             12.5, 0},
            {"cartesianZ", E57W_INT, g.min[2],
             (int64_t)((uint64_t)g.min[2] +
                       (65 - w == 64 ? UINT64_MAX : (UINT64_C(1) << (65 - w)) - 1)),
             0, 0, 0},
            {"intensity", E57W_F64, 0, 0, 0, 0, 0},
        };
        e57w_scan s = {.nfields = 4,
                       .fields = fl,
                       .records = 300,
                       .per_packet = 7,
                       .stagger = 5,
                       .empty_packet = w % 2,
                       .index_packet = w % 3 == 0};
        char p[1024];
        tmp_path("widths.e57", p, sizeof p);
        assert_int_equal(e57w_write(p, &s, 1, NULL, gen_ints, &g), 0);
        pc_raw r;
        read_raw_ok(p, &r);
        assert_int_equal(r.n, 300);
        assert_int_equal(r.attrs, PC_ATTR_INTENSITY);
        for (uint64_t i = 0; i < 300; i++) {
            double want[3] = {(double)raw_int(&g, 0, i, 0),
                              (double)raw_int(&g, 0, i, 1) * 0.001 + 12.5,
                              (double)raw_int(&g, 0, i, 2)};
            for (int k = 0; k < 3; k++)
                if (r.xyz[3 * i + k] != want[k])
                    fail_msg("width %d record %llu axis %d: %.17g, want %.17g", w,
                             (unsigned long long)i, k, r.xyz[3 * i + k], want[k]);
            /* no intensity limits and an unbounded double: kept as it is */
            assert_float_equal(r.intensity[i], (float)((double)i * 0.25 - 3.0), 0);
        }
        pc_raw_free(&r);
    }
}

/* poses and spherical coordinates */
static void gen_sph(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx;
    dbls[0] = 1.0 + (double)i; /* range */
    dbls[1] = (double)i * 0.3 + scan; /* azimuth */
    dbls[2] = -1.2 + (double)i * 0.1; /* elevation */
    ints[3] = (int64_t)(i % 3); /* sphericalInvalidState 0, 1, 2 */
    ints[4] = (int64_t)(i * 7 % 256); /* colorRed */
    ints[5] = 100;
    ints[6] = 200;
}

/* spherical coordinates, their invalid state and colours (gen_sph's values) */
static const e57w_field sph_fields[7] = {
    {"sphericalRange", E57W_F64, 0, 0, 0, 0, 0},
    {"sphericalAzimuth", E57W_F32, 0, 0, 0, 0, 0},
    {"sphericalElevation", E57W_F64, 0, 0, 0, 0, 0},
    {"sphericalInvalidState", E57W_INT, 0, 2, 0, 0, 0},
    {"colorRed", E57W_INT, 0, 255, 0, 0, 0},
    {"colorGreen", E57W_INT, 0, 255, 0, 0, 0},
    {"colorBlue", E57W_INT, 0, 511, 0, 0, 0},
};

static void rotate(const double q[4], const double p[3], double out[3])
{
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    double w = q[0] / n, v[3] = {q[1] / n, q[2] / n, q[3] / n};
    /* p + 2 w (v x p) + 2 v x (v x p): a form other than the reader's matrix */
    double c1[3] = {v[1] * p[2] - v[2] * p[1], v[2] * p[0] - v[0] * p[2],
                    v[0] * p[1] - v[1] * p[0]};
    double c2[3] = {v[1] * c1[2] - v[2] * c1[1], v[2] * c1[0] - v[0] * c1[2],
                    v[0] * c1[1] - v[1] * c1[0]};
    for (int k = 0; k < 3; k++) out[k] = p[k] + 2 * w * c1[k] + 2 * c2[k];
}

/* Three spherical scans with poses: points (1 + i, az, el) -> cartesian, rotated, translated;
 * sphericalInvalidState 1 and 2 dropped (two of every three records); colours by
 * colorLimits 0-255 (red) and the scan index. */
static void test_spherical_multi_scan_poses(void **state)
{
    (void)state;
    const e57w_field *fl = sph_fields;
    const char *limits =
        "<colorLimits type=\"Structure\"><colorRedMaximum type=\"Integer\">255"
        "</colorRedMaximum><colorGreenMaximum type=\"Integer\">255</colorGreenMaximum>"
        "<colorBlueMinimum type=\"Integer\">100</colorBlueMinimum>"
        "<colorBlueMaximum type=\"Integer\">300</colorBlueMaximum></colorLimits>";
    e57w_scan s[3] = {
        {.nfields = 7, .fields = fl, .records = 30, .extra_xml = limits},
        {.nfields = 7,
         .fields = fl,
         .records = 31,
         .pose = 1,
         .quat = {0.7071067811865476, 0, 0, 0.7071067811865476},
         .trans = {1000, -2000, 3},
         .extra_xml = limits,
         .per_packet = 4},
        {.nfields = 7,
         .fields = fl,
         .records = 32,
         .pose = 1,
         .quat = {2, 1, -1, 0.5}, /* not unit */
         .trans = {-5, 0, 1e6},
         .extra_xml = limits,
         .per_packet = 3,
         .stagger = 2},
    };
    char p[1024];
    tmp_path("sph.e57", p, sizeof p);
    /* an image beside the scans: skipped */
    e57w_opts opts = {.root_extra = "<images2D type=\"Vector\" allowHeterogeneousChildren=\"1\">"
                                 "<vectorChild type=\"Structure\"><pinholeRepresentation "
                                 "type=\"Structure\"><jpegImage type=\"Blob\" fileOffset=\"9999999\" "
                                 "length=\"100\"/></pinholeRepresentation></vectorChild></images2D>\n"};
    assert_int_equal(e57w_write(p, s, 3, &opts, gen_sph, NULL), 0);
    pc_raw r;
    read_raw_ok(p, &r);
    assert_int_equal(r.attrs, PC_ATTR_RGB | PC_ATTR_SCAN);
    assert_string_equal(r.format, "E57 1.0, 3 scans");
    size_t j = 0;
    for (uint32_t sc = 0; sc < 3; sc++)
        for (uint64_t i = 0; i < s[sc].records; i++) {
            if (i % 3) continue; /* states 1 and 2 */
            double az = (double)(float)((double)i * 0.3 + sc), el = -1.2 + (double)i * 0.1,
                   rg = 1.0 + (double)i;
            double q[3] = {rg * cos(el) * cos(az), rg * cos(el) * sin(az), rg * sin(el)}, w[3];
            if (s[sc].pose)
                rotate(s[sc].quat, q, w);
            else
                memcpy(w, q, sizeof w);
            for (int k = 0; k < 3; k++) {
                double want = w[k] + s[sc].trans[k];
                if (fabs(r.xyz[3 * j + k] - want) > 1e-9 * (1 + fabs(want)))
                    fail_msg("scan %u record %llu axis %d: %.17g, want %.17g", sc,
                             (unsigned long long)i, k, r.xyz[3 * j + k], want);
            }
            assert_int_equal(r.rgba[4 * j], i * 7 % 256);
            assert_int_equal(r.rgba[4 * j + 1], 100);
            assert_int_equal(r.rgba[4 * j + 2], 128); /* (200 - 100) * 255 / 200 = 127.5 */
            assert_int_equal(r.rgba[4 * j + 3], 255);
            assert_int_equal(r.scan[j], sc);
            j++;
        }
    assert_int_equal(r.n, j);
    assert_int_equal(j, 10 + 11 + 11);
    pc_raw_free(&r);
    /* the known point: scan 1 turns (1, 0, 0) a quarter turn about z: (0, 1, 0) + t */
    double q[4] = {0.7071067811865476, 0, 0, 0.7071067811865476}, pt[3] = {1, 0, 0}, o[3];
    rotate(q, pt, o);
    assert_float_equal(o[0], 0, 1e-15);
    assert_float_equal(o[1], 1, 1e-15);
}

/* cartesian invalid states, intensity limits, isColorInvalid and isIntensityInvalid, normals
 * turned by the pose */
static void gen_cart(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx, (void)scan;
    dbls[0] = (double)i;
    dbls[1] = 2.0 * (double)i;
    dbls[2] = -1.0;
    ints[3] = i % 4 == 3 ? 1 : i % 4 == 2 ? 2 : 0; /* cartesianInvalidState */
    ints[4] = (int64_t)(i % 1000); /* intensity, limits 0-999 */
    ints[5] = i % 5 == 0; /* isIntensityInvalid */
    ints[6] = 9, ints[7] = 9, ints[8] = 9; /* colours 9 of 0-255 */
    ints[9] = i % 7 == 0; /* isColorInvalid */
    dbls[10] = 0, dbls[11] = 2, dbls[12] = 0; /* nor:normal (0, 2, 0): not unit */
    ints[13] = (int64_t)i; /* rowIndex: never read */
}

static void test_invalid_states_limits_normals(void **state)
{
    (void)state;
    e57w_field fl[14] = {
        {"cartesianX", E57W_F64, 0, 0, 0, 0, 0},
        {"cartesianY", E57W_F64, 0, 0, 0, 0, 0},
        {"cartesianZ", E57W_F32, 0, 0, 0, 0, 0},
        {"cartesianInvalidState", E57W_INT, 0, 2, 0, 0, 0},
        {"intensity", E57W_INT, 0, 4095, 0, 0, 0},
        {"isIntensityInvalid", E57W_INT, 0, 1, 0, 0, 0},
        {"colorRed", E57W_INT, 0, 255, 0, 0, 0},
        {"colorGreen", E57W_INT, 0, 255, 0, 0, 0},
        {"colorBlue", E57W_INT, 0, 255, 0, 0, 0},
        {"isColorInvalid", E57W_INT, 0, 1, 0, 0, 0},
        {"nor:normalX", E57W_F32, 0, 0, 0, 0, 0},
        {"nor:normalY", E57W_F32, 0, 0, 0, 0, 0},
        {"nor:normalZ", E57W_F32, 0, 0, 0, 0, 0},
        {"rowIndex", E57W_INT, 0, 1 << 20, 0, 0, 0},
    };
    e57w_scan s = {.nfields = 14,
                   .fields = fl,
                   .records = 2000,
                   .per_packet = 61,
                   .stagger = 13,
                   .pose = 1,
                   .quat = {0.7071067811865476, 0.7071067811865476, 0, 0},
                   .extra_xml = "<intensityLimits type=\"Structure\"><intensityMinimum "
                                "type=\"Integer\">0</intensityMinimum><intensityMaximum "
                                "type=\"Integer\">999</intensityMaximum></intensityLimits>"};
    char p[1024];
    tmp_path("cart.e57", p, sizeof p);
    assert_int_equal(e57w_write(p, &s, 1, NULL, gen_cart, NULL), 0);
    pc_raw r;
    read_raw_ok(p, &r);
    assert_int_equal(r.attrs, PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_NORMAL);
    assert_int_equal(r.n, 1000); /* states 1 and 2 dropped: half */
    size_t j = 0;
    for (uint64_t i = 0; i < 2000; i++) {
        if (i % 4 >= 2) continue;
        /* a quarter turn about x: (x, y, z) -> (x, -z, y) */
        assert_float_equal(r.xyz[3 * j], (double)i, 1e-12);
        assert_float_equal(r.xyz[3 * j + 1], 1.0, 1e-12);
        assert_float_equal(r.xyz[3 * j + 2], 2.0 * (double)i, 1e-9);
        float want_i = i % 5 == 0 ? 0.0f : (float)((double)(i % 1000) / 999.0);
        assert_float_equal(r.intensity[j], want_i, 1e-7);
        for (int k = 0; k < 3; k++) assert_int_equal(r.rgba[4 * j + k], i % 7 == 0 ? 255 : 9);
        /* the normal turned as the points, (0, 1, 0) -> (0, 0, 1), and made unit */
        assert_float_equal(r.normal[3 * j], 0.0f, 1e-7);
        assert_float_equal(r.normal[3 * j + 1], 0.0f, 1e-7);
        assert_float_equal(r.normal[3 * j + 2], 1.0f, 1e-7);
        j++;
    }
    pc_raw_free(&r);
}

static void gen_line(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx, (void)scan, (void)ints;
    dbls[0] = (double)i;
    dbls[1] = 2.0 * (double)i;
    dbls[2] = -1.0;
}

/* the stream reads each page once while the fields stay within the packet cache of each other
 * (here 5 packets apart at the end) */
static void test_pages_read_once(void **state)
{
    (void)state;
    char p[1024];
    tmp_path("cart.e57", p, sizeof p);
    e57w_field fl[3] = {{"cartesianX", E57W_F64, 0, 0, 0, 0, 0},
                        {"cartesianY", E57W_F64, 0, 0, 0, 0, 0},
                        {"cartesianZ", E57W_F32, 0, 0, 0, 0, 0}};
    e57w_scan s = {
        .nfields = 3, .fields = fl, .records = 100000, .per_packet = 2000, .stagger = 100};
    assert_int_equal(e57w_write(p, &s, 1, NULL, gen_line, NULL), 0);
    pc_e57_stream *st;
    sd_err e = {0};
    assert_int_equal(pc_e57_stream_open(p, &st, &e), 1);
    double *xyz = malloc(3 * 100000 * sizeof *xyz);
    pc_e57_points o = {.xyz = xyz};
    int64_t got = 0, m;
    while ((m = pc_e57_stream_next(st, &o, 1000, &e)) > 0) {
        got += m;
        o.xyz = xyz + 3 * got;
    }
    assert_int_equal(m, 0);
    assert_int_equal(got, 100000);
    for (int64_t i = 0; i < got; i += 999) assert_float_equal(xyz[3 * i + 1], 2.0 * (double)i, 0);
    size_t len;
    uint8_t *d = tu_read_file(p, &len);
    free(d);
    uint64_t pages = len / 1024, checked = pc_e57_stream_pages_checked(st);
    /* header, XML and the packets' boundary pages may be read twice; nothing more */
    if (checked > pages + pages / 10 + 8)
        fail_msg("%llu page checks for %llu pages", (unsigned long long)checked,
                 (unsigned long long)pages);
    pc_e57_stream_close(st);
    free(xyz);
}

/* ---- damaged files ---- */

static void gen_small(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx, (void)scan;
    for (int k = 0; k < 3; k++) dbls[k] = (double)i + k;
    (void)ints;
}

static const e57w_field small_fields[3] = {{"cartesianX", E57W_F64, 0, 0, 0, 0, 0},
                                           {"cartesianY", E57W_F64, 0, 0, 0, 0, 0},
                                           {"cartesianZ", E57W_F64, 0, 0, 0, 0, 0}};

/* small_file: a 500-record scan in 5 packets; its bytes (malloc'd) and length. */
static uint8_t *small_file(size_t *len)
{
    char p[1024];
    e57w_scan s = {.nfields = 3, .fields = small_fields, .records = 500, .per_packet = 100};
    assert_int_equal(e57w_write(tmp_path("small.e57", p, sizeof p), &s, 1, NULL, gen_small, NULL),
                     0);
    return tu_read_file(p, len);
}

static const char *save(const char *name, const uint8_t *d, size_t n, char *p, size_t len)
{
    tmp_path(name, p, len);
    assert_int_equal(tu_write_file(p, d, n), 0);
    return p;
}

static uint64_t get64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

static void put64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* replace_xml: the file d with its XML text's first `from` replaced by `to` (same length, or
 * the XML length in the header adjusted), checksums fixed. */
static uint8_t *replace_xml(const uint8_t *d, size_t n, const char *from, const char *to,
                            size_t *out_len)
{
    uint64_t xo = get64(d + 24), xl = get64(d + 32);
    /* the XML section of the writer's small files lies in its last pages: rebuild it logically */
    size_t pages = n / 1024;
    uint8_t *lg = malloc(pages * 1020 + 4096);
    for (size_t p = 0; p < pages; p++) memcpy(lg + p * 1020, d + p * 1024, 1020);
    uint64_t xlo = xo / 1024 * 1020 + xo % 1024;
    char *x = calloc(1, xl + 4096);
    memcpy(x, lg + xlo, xl);
    char *at = strstr(x, from);
    if (!at) fail_msg("no '%s' in the XML", from);
    char *nx = calloc(1, xl + 4096);
    memcpy(nx, x, (size_t)(at - x));
    strcat(nx, to);
    strcat(nx, at + strlen(from));
    size_t nl = strlen(nx);
    memcpy(lg + xlo, nx, nl);
    uint64_t total = xlo + nl, np = (total + 1019) / 1020;
    memset(lg + total, 0, np * 1020 - total);
    uint8_t *o = calloc(np, 1024);
    for (size_t p = 0; p < np; p++) memcpy(o + p * 1024, lg + p * 1020, 1020);
    put64(o + 16, np * 1024);
    put64(o + 32, nl);
    e57w_fix_crcs(o, np * 1024, 1024);
    *out_len = np * 1024;
    free(lg), free(x), free(nx);
    return o;
}

static void test_damaged_pages(void **state)
{
    (void)state;
    size_t n;
    uint8_t *d = small_file(&n);
    char p[1024];
    pc_cloud c;
    tu_load_ok(save("ok.e57", d, n, p, sizeof p), &c);
    assert_int_equal(c.n, 500);
    pc_cloud_free(&c);
    /* one flipped bit in page 3: the checksum names that page */
    uint8_t *b = malloc(n);
    memcpy(b, d, n);
    b[3 * 1024 + 100] ^= 4;
    expect_fail(save("crc.e57", b, n, p, sizeof p), SD_EFORMAT, "bad checksum",
                "physical offset 3072 ", NULL);
    /* cut in the middle of the last page: the header's length no longer holds */
    expect_fail(save("cut.e57", d, n - 300, p, sizeof p), SD_ETRUNC, "offset 16", NULL);
    /* the header's length adjusted to the cut: the page itself is truncated */
    memcpy(b, d, n);
    put64(b + 16, n - 300);
    e57w_fix_crcs(b, 1024, 1024);
    expect_fail(save("cut2.e57", b, n - 300, p, sizeof p), SD_ETRUNC, "truncated",
                "physical offset", NULL);
    /* a whole page short, the header's length matching: the XML runs past the end */
    memcpy(b, d, n);
    put64(b + 16, n - 1024);
    e57w_fix_crcs(b, 1024, 1024);
    expect_fail(save("cut3.e57", b, n - 1024, p, sizeof p), SD_EFORMAT, "XML section",
                "not inside the file", NULL);
    /* the XML length lies (longer than the file) */
    memcpy(b, d, n);
    put64(b + 32, (uint64_t)1 << 40);
    e57w_fix_crcs(b, 1024, 1024);
    expect_fail(save("xmllen.e57", b, n, p, sizeof p), SD_EFORMAT, "XML section", NULL);
    /* another page size or version, a foreign file */
    memcpy(b, d, n);
    put64(b + 40, 1001);
    expect_fail(save("ps.e57", b, n, p, sizeof p), SD_EFORMAT, "page size 1001", NULL);
    memcpy(b, d, n);
    b[8] = 2;
    e57w_fix_crcs(b, 1024, 1024);
    expect_fail(save("v2.e57", b, n, p, sizeof p), SD_EUNSUP, "version 2.0", NULL);
    expect_fail(save("short.e57", d, 40, p, sizeof p), SD_EFORMAT, "not an E57 file", NULL);
    /* the section header: its length past the end of the file, its data offset outside it */
    uint64_t cvl = 48; /* the first section follows the header */
    memcpy(b, d, n);
    put64(b + cvl + 8, (uint64_t)1 << 50);
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("seclen.e57", b, n, p, sizeof p), SD_ETRUNC, "physical offset 48",
                "logical bytes", NULL);
    memcpy(b, d, n);
    put64(b + cvl + 16, 8);
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("dataoff.e57", b, n, p, sizeof p), SD_EFORMAT, "outside the section", NULL);
    /* a packet whose length runs past its section; a packet of an unknown type */
    memcpy(b, d, n);
    b[80 + 2] = 0xFF, b[80 + 3] = 0xFF;
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("pktlen.e57", b, n, p, sizeof p), SD_EFORMAT, "packet at physical offset 80",
                NULL);
    memcpy(b, d, n);
    b[80] = 7;
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("pkttype.e57", b, n, p, sizeof p), SD_EFORMAT, "unknown type", NULL);
    /* a bytestream count that is not the prototype's; buffer lengths past the packet */
    memcpy(b, d, n);
    b[84] = 2;
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("nstreams.e57", b, n, p, sizeof p), SD_EFORMAT, "2 bytestreams for 3", NULL);
    memcpy(b, d, n);
    b[86] = 0xFF, b[87] = 0xF0;
    e57w_fix_crcs(b, n, 1024);
    expect_fail(save("buflen.e57", b, n, p, sizeof p), SD_EFORMAT,
                "data packet at physical offset 80", NULL);
    free(b);
    free(d);
}

static void test_damaged_xml(void **state)
{
    (void)state;
    size_t n, m;
    uint8_t *d = small_file(&n), *b;
    char p[1024];
    /* a recordCount that lies: the streams end first, naming the field and the record */
    b = replace_xml(d, n, "recordCount=\"500\"", "recordCount=\"501\"", &m);
    expect_fail(save("count.e57", b, m, p, sizeof p), SD_EFORMAT, "field cartesianX",
                "after 500 of the 501", NULL);
    free(b);
    /* a huge recordCount: refused when the bytes end, without reserving 10^18 points (the
     * reservation is bounded by the section's bits; an allocation of the claim fails ASan) */
    b = replace_xml(d, n, "recordCount=\"500\"", "recordCount=\"999999999999999999\"", &m);
    pc_e57_stream *st;
    sd_err e = {0};
    assert_int_equal(pc_e57_stream_open(save("huge.e57", b, m, p, sizeof p), &st, &e), 1);
    /* the section: a 32-byte header and 5 packets of 12 + 3 * 800 bytes, 12,092 bytes; a record
     * takes 192 bits: at most 503 records fit */
    assert_int_equal(pc_e57_stream_bound(st), 12092 * 8 / 192);
    pc_e57_stream_close(st);
    expect_fail(p, SD_EFORMAT, "after 500 of the 999999999999999999", NULL);
    free(b);
    /* fileOffset past the end of the file */
    b = replace_xml(d, n, "fileOffset=\"48\"", "fileOffset=\"4800000\"", &m);
    expect_fail(save("off.e57", b, m, p, sizeof p), SD_EFORMAT, "fileOffset 4800000",
                "past the end", NULL);
    free(b);
    /* two scans reading the same bytes: refused (a file's points come from bytes of their own) */
    b = replace_xml(d, n, "</data3D>",
                    "<vectorChild type=\"Structure\"><points type=\"CompressedVector\" "
                    "fileOffset=\"48\" recordCount=\"500\"><prototype type=\"Structure\">"
                    "<cartesianX type=\"Float\"/><cartesianY type=\"Float\"/><cartesianZ "
                    "type=\"Float\"/></prototype></points></vectorChild></data3D>", &m);
    expect_fail(save("twice.e57", b, m, p, sizeof p), SD_EFORMAT, "scans 0", "and 1", "overlap",
                NULL);
    free(b);
    /* fileOffset in a checksum */
    b = replace_xml(d, n, "fileOffset=\"48\"", "fileOffset=\"1022\"", &m);
    expect_fail(save("off2.e57", b, m, p, sizeof p), SD_EFORMAT, "into a page checksum", NULL);
    free(b);
    /* a prototype without coordinates */
    b = replace_xml(d, n, "<cartesianY", "<cartesianQ", &m);
    expect_fail(save("nocoord.e57", b, m, p, sizeof p), SD_EFORMAT, "neither cartesianX/Y/Z",
                "line", NULL);
    free(b);
    /* a String field, a foreign codec, a bad number, a zero quaternion, broken XML */
    b = replace_xml(d, n, "<cartesianZ type=\"Float\" precision=\"double\"/>",
                    "<cartesianZ type=\"Float\" precision=\"double\"/><s type=\"String\"/>", &m);
    expect_fail(save("str.e57", b, m, p, sizeof p), SD_EUNSUP, "String", NULL);
    free(b);
    b = replace_xml(
        d, n, "</codecs>",
        "<vectorChild type=\"Structure\"><zlib type=\"Structure\"/></vectorChild></codecs>", &m);
    expect_fail(save("codec.e57", b, m, p, sizeof p), SD_EUNSUP, "bit-pack", NULL);
    free(b);
    b = replace_xml(d, n, "recordCount=\"500\"", "recordCount=\"-5\"", &m);
    expect_fail(save("neg.e57", b, m, p, sizeof p), SD_EFORMAT, "recordCount '-5'", NULL);
    free(b);
    b = replace_xml(d, n, "<guid type=\"String\">scan 0</guid>",
                    "<pose type=\"Structure\"><rotation type=\"Structure\"><w type=\"Float\">0</w>"
                    "</rotation></pose>",
                    &m);
    expect_fail(save("quat.e57", b, m, p, sizeof p), SD_EFORMAT, "quaternion", NULL);
    free(b);
    b = replace_xml(d, n, "</data3D>", "</data3X>", &m);
    expect_fail(save("broken.e57", b, m, p, sizeof p), SD_EFORMAT, "XML section at physical offset",
                "line", NULL);
    free(b);
    free(d);
}

/* An Integer field whose stream holds a value over the maximum: refused naming the record. */
static void gen_over(void *ctx, uint32_t scan, uint64_t i, int64_t *ints, double *dbls)
{
    (void)ctx, (void)scan;
    ints[0] = ints[1] = ints[2] = (int64_t)(i % 8);
    (void)dbls;
}

static void test_value_over_maximum(void **state)
{
    (void)state;
    e57w_field fl[3] = {{"cartesianX", E57W_INT, 0, 7, 0, 0, 0},
                        {"cartesianY", E57W_INT, 0, 7, 0, 0, 0},
                        {"cartesianZ", E57W_INT, 0, 7, 0, 0, 0}};
    e57w_scan s = {.nfields = 3, .fields = fl, .records = 20};
    char p[1024];
    assert_int_equal(e57w_write(tmp_path("over.e57", p, sizeof p), &s, 1, NULL, gen_over, NULL), 0);
    size_t n, m;
    uint8_t *d = tu_read_file(p, &n);
    /* the same 3 bits, a maximum of 6: record 7 holds 7 */
    uint8_t *b = replace_xml(d, n, "<cartesianY type=\"Integer\" minimum=\"0\" maximum=\"7\"/>",
                             "<cartesianY type=\"Integer\" minimum=\"0\" maximum=\"6\"/>", &m);
    expect_fail(save("over2.e57", b, m, p, sizeof p), SD_EFORMAT, "record 7", "cartesianY",
                "maximum 6", NULL);
    free(b);
    free(d);
}

/* ---- the LOD build's stream ---- */

static void test_lod_stream(void **state)
{
    (void)state;
    const e57w_field *fl = sph_fields;
    e57w_scan s[2] = {
        {.nfields = 7, .fields = fl, .records = 9000, .per_packet = 500, .stagger = 50},
        {.nfields = 7,
         .fields = fl,
         .records = 7000,
         .pose = 1,
         .quat = {1, 0, 1, 0},
         .trans = {654321.5, 5432109.25, 80},
         .per_packet = 333},
    };
    char p[1024];
    tmp_path("lod.e57", p, sizeof p);
    assert_int_equal(e57w_write(p, s, 2, NULL, gen_sph, NULL), 0);
    pc_cloud c;
    tu_load_ok(p, &c);
    assert_int_equal(c.n, 3000 + 2334);
    lod_src *ls;
    sd_err e = {0};
    if (lod_src_open(p, &ls, &e)) fail_msg("%s", e.msg);
    lod_src_info in;
    lod_src_get_info(ls, &in);
    assert_int_equal(in.streamed, 1);
    assert_int_equal(in.n, c.n);
    assert_int_equal(in.attrs, PC_ATTR_RGB);
    assert_string_equal(in.format, "E57 1.0, 2 scans");
    for (int k = 0; k < 3; k++) {
        assert_true(in.offset[k] == c.offset[k]);
        assert_true(in.bmin[k] == c.bmin[k] && in.bmax[k] == c.bmax[k]);
    }
    float *pos = malloc(c.n * 3 * sizeof *pos);
    uint32_t *rgba = malloc(c.n * sizeof *rgba);
    for (int pass = 0; pass < 2; pass++) {
        assert_int_equal(lod_src_rewind(ls, &e), 0);
        size_t got = 0;
        int64_t m;
        while ((m = lod_src_next(ls, pos + 3 * got, rgba + got, 777, &e)) > 0) got += (size_t)m;
        assert_int_equal(m, 0);
        assert_int_equal(got, c.n);
        for (size_t i = 0; i < c.n; i++) {
            for (int k = 0; k < 3; k++) assert_true(pos[3 * i + k] == c.pos[3 * i + k]);
            uint32_t v;
            memcpy(&v, c.rgba + 4 * i, 4);
            assert_int_equal(rgba[i], v);
        }
    }
    free(pos);
    free(rgba);
    lod_src_close(ls);
    pc_cloud_free(&c);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_shared_counts_bounds),
        cmocka_unit_test(test_bunny_matches_pts),
        cmocka_unit_test(test_shared_colours),
        cmocka_unit_test(test_shared_normals_and_translation),
        cmocka_unit_test(test_shared_refused),
        cmocka_unit_test(test_magic),
        cmocka_unit_test(test_crc32c),
        cmocka_unit_test(test_bitpack_widths),
        cmocka_unit_test(test_xml_tree),
        cmocka_unit_test(test_widths_end_to_end),
        cmocka_unit_test(test_spherical_multi_scan_poses),
        cmocka_unit_test(test_invalid_states_limits_normals),
        cmocka_unit_test(test_pages_read_once),
        cmocka_unit_test(test_damaged_pages),
        cmocka_unit_test(test_damaged_xml),
        cmocka_unit_test(test_value_over_maximum),
        cmocka_unit_test(test_lod_stream),
    };
    return cmocka_run_group_tests(tests, setup, tu_tmpdir_teardown);
}
