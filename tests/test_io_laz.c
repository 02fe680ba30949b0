/* test_io_laz.c — the LAZ decoder (server/io/laz*.c), the LAZ reader (io_laz.c) and COPC
 * (copc.c).
 *
 * Independent references: the uncompressed .las twins that LASzip/laz-perf wrote from the
 * same points (tests/data/SOURCES.md): every record of every file with a twin must decode to
 * the twin's bytes, all fields, not only xyz. The ellipsoid exists in three encodings (format
 * 3 pointwise, format 7 layered, COPC in octree order): the same points must come out of each.
 * Broken files are made here from the real ones by cutting and overwriting bytes; each must
 * fail with the right code and a message naming the file and the chunk (or offset). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cloud.h"
#include "common/testutil.h"
#include "copc.h"
#include "laz.h"
#include "laz_arith.h"
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

static uint8_t *load(const char *name, size_t *len)
{
    char p[1024];
    uint8_t *d = tu_read_file(tu_data(name, p, sizeof p), len);
    if (!d) fail_msg("cannot read %s", p);
    return d;
}

/* open_laz: the test file name read and opened as LAZ into lf (kept in memory: returned). */
static uint8_t *open_laz(const char *name, size_t *len, laz_file *lf)
{
    uint8_t *d = load(name, len);
    sd_err e = {0};
    if (laz_open(lf, name, d, *len, &e)) fail_msg("%s: %s", name, e.msg);
    return d;
}

/* decode_all: every record of the LAZ file in d (chunk by chunk) into one malloc'd buffer. */
static uint8_t *decode_all(const char *name, const uint8_t *d, size_t len, laz_file *lf)
{
    sd_err e = {0};
    if (laz_open(lf, name, d, len, &e)) fail_msg("%s: %s", name, e.msg);
    size_t rl = lf->h.rec_len;
    uint8_t *all = malloc((size_t)lf->h.count * rl), *buf = NULL;
    assert_non_null(all);
    size_t cap = 0;
    laz_chunk_dec *cd = laz_chunk_dec_create(lf->items, lf->nitems);
    assert_non_null(cd);
    for (size_t c = 0; c < lf->nchunks; c++) {
        if (laz_read_chunk(lf, cd, c, &buf, &cap, &e)) fail_msg("%s: %s", name, e.msg);
        size_t n = (size_t)(lf->chunk_first[c + 1] - lf->chunk_first[c]);
        memcpy(all + lf->chunk_first[c] * rl, buf, n * rl);
    }
    free(buf);
    laz_chunk_dec_free(cd);
    return all;
}

/* twin: the LAZ file decodes to the records of the LAS file, byte for byte. */
static void twin(const char *laz, const char *las, unsigned want_fmt, uint64_t want_n)
{
    size_t zl, sl;
    uint8_t *z = load(laz, &zl), *s = load(las, &sl);
    laz_file lf;
    uint8_t *recs = decode_all(laz, z, zl, &lf);
    uint32_t off = 0;
    memcpy(&off, s + 96, 4);
    uint16_t rl = 0;
    memcpy(&rl, s + 105, 2);
    assert_int_equal(lf.h.format, want_fmt);
    assert_int_equal(lf.h.count, want_n);
    assert_int_equal(lf.h.rec_len, rl);
    assert_true(off + want_n * rl <= sl);
    size_t bad = 0, first_bad = 0;
    for (size_t i = 0; i < want_n; i++)
        if (memcmp(recs + i * rl, s + off + i * rl, rl) != 0 && bad++ == 0) first_bad = i;
    if (bad) fail_msg("%s: %zu of %llu records differ from %s, the first at point %zu", laz, bad,
                      (unsigned long long)want_n, las, first_bad);
    free(recs);
    laz_close(&lf);
    free(z);
    free(s);
}

static void test_twins_formats_0_to_3(void **state)
{
    (void)state;
    twin("point10.las.laz", "point10.las", 0, 1065);
    twin("point-time.las.laz", "point-time.las", 1, 1065);
    twin("point-color.las.laz", "point-color.las", 2, 1065);
    twin("point-color-time.las.laz", "point-color-time.las", 3, 1065);
    twin("1815.laz", "1815.las", 1, 1247);
}

static void test_twin_extra_bytes(void **state)
{
    (void)state;
    twin("extrabytes.laz", "extrabytes.las", 3, 1065); /* 34 + 27 extra bytes, BYTE v2 */
}

static void test_twin_autzen_three_chunks(void **state)
{
    (void)state;
    size_t zl;
    laz_file lf;
    uint8_t *z = open_laz("autzen_trim.laz", &zl, &lf);
    assert_int_equal(lf.nchunks, 3); /* 110,000 points in fixed chunks of 50,000 */
    assert_int_equal(lf.chunk_size, 50000);
    assert_int_equal(lf.chunk_first[2], 100000);
    laz_close(&lf);
    free(z);
    twin("autzen_trim.laz", "autzen_trim.las", 3, 110000);
}

/* LAS 1.4 header, point format 1: the same records as point-time.las. */
static void test_las14_format1(void **state)
{
    (void)state;
    twin("point-time-1.4.las.laz", "point-time.las", 1, 1065);
}

/* The fields of a point that all three ellipsoid encodings keep identically. */
typedef struct ekey {
    double x, y, z, gps;
    unsigned ret, nret, cls, r, g, b;
} ekey;

static int ekey_cmp(const void *a, const void *b)
{
    return memcmp(a, b, sizeof(ekey));
}

/* ellipsoid points as keys: xyz in file units, GPS time, returns, class, 8-bit colour. */
static ekey *ellipsoid_keys(const char *name, size_t *n)
{
    size_t len;
    uint8_t *d = load(name, &len);
    laz_file lf;
    uint8_t *r = decode_all(name, d, len, &lf);
    *n = (size_t)lf.h.count;
    ekey *k = calloc(*n, sizeof *k);
    assert_non_null(k);
    int f14 = lf.h.format >= 6;
    unsigned rgb = f14 ? 30 : 28, maxc = 0;
    for (size_t i = 0; i < *n; i++)
        for (int c = 0; c < 3; c++) {
            uint16_t v;
            memcpy(&v, r + i * lf.h.rec_len + rgb + 2 * c, 2);
            if (v > maxc) maxc = v;
        }
    for (size_t i = 0; i < *n; i++) {
        const uint8_t *p = r + i * lf.h.rec_len;
        ekey *q = &k[i];
        memset(q, 0, sizeof *q);
        int32_t X[3];
        memcpy(X, p, 12);
        q->x = X[0] * lf.h.scale[0] + lf.h.offset[0];
        q->y = X[1] * lf.h.scale[1] + lf.h.offset[1];
        q->z = X[2] * lf.h.scale[2] + lf.h.offset[2];
        /* the files use different offsets: round to the 0.01 grid they share */
        q->x = (double)(int64_t)(q->x * 100 + (q->x < 0 ? -0.5 : 0.5));
        q->y = (double)(int64_t)(q->y * 100 + (q->y < 0 ? -0.5 : 0.5));
        q->z = (double)(int64_t)(q->z * 100 + (q->z < 0 ? -0.5 : 0.5));
        memcpy(&q->gps, p + (f14 ? 22 : 20), 8);
        q->ret = f14 ? p[14] & 15 : p[14] & 7;
        q->nret = f14 ? p[14] >> 4 : (p[14] >> 3) & 7;
        q->cls = f14 ? p[16] : p[15] & 31;
        uint16_t c[3];
        memcpy(c, p + rgb, 6);
        q->r = maxc > 255 ? (c[0] + 128u) / 257 : c[0];
        q->g = maxc > 255 ? (c[1] + 128u) / 257 : c[1];
        q->b = maxc > 255 ? (c[2] + 128u) / 257 : c[2];
    }
    free(r);
    laz_close(&lf);
    free(d);
    qsort(k, *n, sizeof *k, ekey_cmp);
    return k;
}

static void test_ellipsoid_three_encodings(void **state)
{
    (void)state;
    size_t n3, n7, nc;
    ekey *a = ellipsoid_keys("ellipsoid.laz", &n3);
    ekey *b = ellipsoid_keys("ellipsoid-1.4.laz", &n7);
    ekey *c = ellipsoid_keys("ellipsoid.copc.laz", &nc);
    assert_int_equal(n3, 100000);
    assert_int_equal(n7, 100000);
    assert_int_equal(nc, 100000);
    size_t d37 = 0, d7c = 0;
    for (size_t i = 0; i < n3; i++) {
        d37 += memcmp(&a[i], &b[i], sizeof *a) != 0;
        d7c += memcmp(&b[i], &c[i], sizeof *a) != 0;
    }
    assert_int_equal(d37, 0);
    assert_int_equal(d7c, 0);
    /* not trivially equal: the set has many distinct positions and times */
    size_t distinct = 1;
    for (size_t i = 1; i < n3; i++) distinct += memcmp(&a[i], &a[i - 1], sizeof *a) != 0;
    assert_true(distinct > 90000);
    free(a);
    free(b);
    free(c);
}

/* The reader: pc_load of a .laz equals pc_load of its twin; one thread equals two. */
static void test_pc_load_equals_twin(void **state)
{
    (void)state;
    char p1[1024], p2[1024];
    pc_cloud a, b;
    sd_err e = {0};
    assert_int_equal(pc_load(tu_data("autzen_trim.laz", p1, sizeof p1), &a, &e), 0);
    assert_int_equal(pc_load(tu_data("autzen_trim.las", p2, sizeof p2), &b, &e), 0);
    assert_int_equal(a.n, 110000);
    assert_int_equal(a.n, b.n);
    assert_int_equal(a.attrs, b.attrs);
    assert_memory_equal(a.pos, b.pos, 3 * sizeof(float) * a.n);
    assert_memory_equal(a.rgba, b.rgba, 4 * a.n);
    assert_memory_equal(a.intensity, b.intensity, sizeof(float) * a.n);
    assert_memory_equal(a.cls, b.cls, a.n);
    assert_memory_equal(a.offset, b.offset, sizeof a.offset);
    assert_non_null(strstr(a.format, "LAZ 1.2 format 3"));
    pc_cloud_free(&b);
    /* the loader with an explicit thread count (what the prep cache passes) gives the same */
    assert_int_equal(pc_load_threads(p1, 1, &b, &e), 0);
    assert_int_equal(b.n, a.n);
    assert_memory_equal(a.pos, b.pos, 3 * sizeof(float) * a.n);
    pc_cloud_free(&a);
    pc_cloud_free(&b);

    pc_raw r1 = {0}, r2 = {0};
    assert_int_equal(pc_read_laz_threads(p1, &r1, 1, &e), 0);
    assert_int_equal(pc_read_laz_threads(p1, &r2, 2, &e), 0);
    assert_int_equal(r1.n, 110000);
    assert_int_equal(r2.n, 110000);
    assert_memory_equal(r1.xyz, r2.xyz, 3 * sizeof(double) * r1.n);
    assert_memory_equal(r1.rgba, r2.rgba, 4 * r1.n);
    pc_raw_free(&r1);
    pc_raw_free(&r2);

    /* COPC through the loader: all points, format named */
    assert_int_equal(pc_load(tu_data("ellipsoid.copc.laz", p1, sizeof p1), &a, &e), 0);
    assert_int_equal(a.n, 100000);
    assert_non_null(strstr(a.format, "COPC LAZ 1.4 format 7"));
    pc_cloud_free(&a);

    /* five chunks (octree nodes of 66272 .. a few thousand points) on three threads: chunks
     * finish out of order, record buffers are reused, idle threads convert what others
     * decoded; the cloud equals the one-thread read in every array */
    assert_int_equal(pc_read_laz_threads(p1, &r1, 1, &e), 0);
    assert_int_equal(pc_read_laz_threads(p1, &r2, 3, &e), 0);
    assert_int_equal(r1.n, 100000);
    assert_int_equal(r2.n, r1.n);
    assert_memory_equal(r1.xyz, r2.xyz, 3 * sizeof(double) * r1.n);
    assert_memory_equal(r1.rgba, r2.rgba, 4 * r1.n);
    assert_memory_equal(r1.intensity, r2.intensity, sizeof *r1.intensity * r1.n);
    assert_memory_equal(r1.cls, r2.cls, sizeof *r1.cls * r1.n);
    pc_raw_free(&r1);
    pc_raw_free(&r2);
}

/* A LAZ file named .las: the LAS reader sees the compression bits and hands it over. */
static void test_laz_named_las(void **state)
{
    (void)state;
    char src[1024], dst[1200], twin_path[1024];
    snprintf(dst, sizeof dst, "%s/renamed.las", g_tmp);
    assert_int_equal(tu_copy_file(tu_data("point-color.las.laz", src, sizeof src), dst), 0);
    pc_cloud a, b;
    sd_err e = {0};
    assert_int_equal(pc_load(dst, &a, &e), 0);
    assert_int_equal(pc_load(tu_data("point-color.las", twin_path, sizeof twin_path), &b, &e), 0);
    assert_int_equal(a.n, 1065);
    assert_int_equal(a.n, b.n);
    assert_memory_equal(a.pos, b.pos, 3 * sizeof(float) * a.n);
    assert_memory_equal(a.rgba, b.rgba, 4 * a.n);
    assert_non_null(strstr(a.format, "LAZ 1.2 format 2"));
    pc_cloud_free(&a);
    pc_cloud_free(&b);
}

static void test_empty(void **state)
{
    (void)state;
    char p[1024];
    pc_cloud c;
    sd_err e = {0};
    assert_int_equal(pc_load(tu_data("no-points-1.3.laz", p, sizeof p), &c, &e), SD_EEMPTY);
    assert_non_null(strstr(e.msg, "no-points-1.3.laz"));
}

/* ---- malformed input ---- */

/* Writes len bytes to name in the temp dir and expects code from pc_load, with a message
 * naming the file and containing want. */
static void expect_fail(const char *name, const void *data, size_t len, int code,
                        const char *want)
{
    char p[1024];
    snprintf(p, sizeof p, "%s/%s", g_tmp, name);
    assert_int_equal(tu_write_file(p, data, len), 0);
    pc_cloud c;
    sd_err e = {0};
    int rc = pc_load(p, &c, &e);
    if (rc != code || !strstr(e.msg, p) || !strstr(e.msg, want))
        fail_msg("%s: got %d (%s), expected %d with '%s'; message: %s", name, rc,
                 sd_strerror(rc), code, want, e.msg);
}

static void test_malformed(void **state)
{
    (void)state;
    size_t len;
    uint8_t *orig = load("autzen_trim.laz", &len);
    uint8_t *b = malloc(len);
    assert_non_null(b);
    laz_file lf;
    sd_err e = {0};
    assert_int_equal(laz_open(&lf, "a", orig, len, &e), 0);
    uint64_t c1 = lf.chunk_start[1], c2 = lf.chunk_start[2], table = lf.chunk_start[3];
    uint32_t data_off = lf.h.data_off;
    laz_close(&lf);

    /* a chunk cut short: the bytes of chunk 1 zeroed after its first 100 (the table says
     * the chunk is longer, the coder runs into garbage): must fail or decode, never crash;
     * cutting the file inside chunk 1 moves the table out of the file */
    memcpy(b, orig, len);
    expect_fail("cut.laz", b, (size_t)(c1 + 1000), SD_EFORMAT, "chunk table offset");

    /* the table offset rewritten to -1 with no copy at the end of the file */
    memcpy(b, orig, len);
    memset(b + data_off, 0xFF, 8);
    expect_fail("tableoff.laz", b, len, SD_EFORMAT, "chunk table");

    /* wrong chunk table: chunk 1's byte size made larger (the coded table re-encoded is not
     * possible here, so move the table start instead: chunk 0 then claims the wrong bytes) */
    memcpy(b, orig, len);
    uint64_t wrong = c2; /* the table offset now points into chunk 2's data */
    memcpy(b + data_off, &wrong, 8);
    expect_fail("wrongtable.laz", b, len, SD_EUNSUP, "chunk table version");

    /* a chunk table that declares more chunks than the bytes can hold */
    memcpy(b, orig, len);
    uint32_t many = 1000000;
    memcpy(b + table + 4, &many, 4);
    expect_fail("manychunks.laz", b, len, SD_EFORMAT, "declares 1000000 chunks");

    /* the header's count disagrees with the table: impossible count */
    memcpy(b, orig, len);
    uint32_t huge = 0xFFFFFFF0u;
    memcpy(b + 107, &huge, 4);
    expect_fail("count.laz", b, len, SD_EFORMAT, "chunk");

    /* chunk 1's compressed bytes overwritten: decoding runs off the end or the table sums
     * differ; either way an error naming chunk 1 */
    memcpy(b, orig, len);
    memset(b + c1 + 40, 0xFF, (size_t)(c2 - c1 - 40));
    char p[1024];
    snprintf(p, sizeof p, "%s/garbage.laz", g_tmp);
    assert_int_equal(tu_write_file(p, b, len), 0);
    pc_cloud c;
    int rc = pc_load(p, &c, &e);
    if (rc == 0) pc_cloud_free(&c); /* garbage may decode to garbage points: no crash */
    else assert_non_null(strstr(e.msg, "chunk 1 of 3"));

    /* a truncated chunk: the table kept, chunk 2's bytes cut to 10 (table entries edited by
     * re-pointing the table at a copy placed after a shortened chunk 2 is not possible
     * without re-encoding, so cut the file right after the table's header instead) */
    memcpy(b, orig, len);
    expect_fail("tablecut.laz", b, (size_t)(table + 8), SD_ETRUNC, "chunk table");

    /* waveform format 4: not supported */
    memcpy(b, orig, len);
    b[104] = 0x84;
    uint16_t wl = 57; /* format 4's record length, so the header itself is valid */
    memcpy(b + 105, &wl, 2);
    expect_fail("wave.laz", b, len, SD_EUNSUP, "not supported");
    b[104] = 0x89;
    wl = 59;
    memcpy(b + 105, &wl, 2);
    expect_fail("wave9.laz", b, len, SD_EUNSUP, "waveform");

    /* the laszip VLR renamed: no decoder description */
    memcpy(b, orig, len);
    uint8_t *v = memmem(b, data_off, "laszip encoded", 14);
    assert_non_null(v);
    v[0] = 'X';
    expect_fail("novlr.laz", b, len, SD_EFORMAT, "laszip encoded");

    /* a coder other than arithmetic */
    memcpy(b, orig, len);
    v = memmem(b, data_off, "laszip encoded", 14);
    v[54 - 2 + 2] = 7; /* payload offset 2: coder */
    expect_fail("coder.laz", b, len, SD_EUNSUP, "coder 7");

    free(b);
    free(orig);
}

/* A chunk whose bytes end early, or whose coded bytes start impossibly: decoded directly so
 * the chunk table stays valid. */
static void test_truncated_chunk(void **state)
{
    (void)state;
    size_t len;
    laz_file lf;
    uint8_t *d = open_laz("point-color-time.las.laz", &len, &lf);
    sd_err e = {0};
    laz_chunk_dec *cd = laz_chunk_dec_create(lf.items, lf.nitems);
    uint8_t *buf = NULL;
    size_t cap = 0;
    uint64_t bytes = lf.chunk_start[1] - lf.chunk_start[0];
    int rc = laz_read_span(&lf, cd, lf.chunk_start[0], bytes / 2, lf.h.count, "chunk 0 of 1",
                           &buf, &cap, &e);
    assert_int_equal(rc, SD_EFORMAT);
    assert_non_null(strstr(e.msg, "point-color-time.las.laz: chunk 0 of 1"));
    assert_non_null(strstr(e.msg, "end before"));
    /* the buffer grew only in 64Ki-point steps up to what the chunk holds */
    assert_true(cap <= (size_t)lf.h.count * lf.h.rec_len);
    /* a claim beyond the coder's density is refused before any decoding */
    rc = laz_read_span(&lf, cd, lf.chunk_start[0], 10, 1000000, "chunk 0 of 1", &buf, &cap, &e);
    assert_int_equal(rc, SD_EFORMAT);
    assert_non_null(strstr(e.msg, "more than the coder can hold"));

    /* A coded stream starting with 4 bytes of 0xFF: no encoder writes it (its code lies below
     * the initial interval 2^32 - 1), and it is the one start that would let the decoder's
     * value reach its interval (and a decoder table be read past its end). The intact chunk
     * decodes; the same chunk with its coded bytes starting FF FF FF FF is reported corrupt. */
    assert_int_equal(laz_read_span(&lf, cd, lf.chunk_start[0], bytes, lf.h.count, "chunk 0 of 1",
                                   &buf, &cap, &e), 0);
    memset(d + lf.chunk_start[0] + lf.h.rec_len, 0xFF, 4);
    rc = laz_read_span(&lf, cd, lf.chunk_start[0], bytes, lf.h.count, "chunk 0 of 1", &buf, &cap,
                       &e);
    assert_int_equal(rc, SD_EFORMAT);
    assert_non_null(strstr(e.msg, "corrupt"));
    /* the decoder itself: flagged at the start, with bytes to spare, and value < length */
    uint8_t s[64];
    memset(s, 0xFF, sizeof s);
    laz_dec dec;
    laz_dec_init(&dec, s, s + sizeof s);
    assert_int_equal(dec.overrun, 1);
    assert_true(dec.value < dec.length);
    s[0] = 0xFE; /* one less: a possible code, not flagged */
    laz_dec_init(&dec, s, s + sizeof s);
    assert_int_equal(dec.overrun, 0);
    assert_int_equal(dec.value, 0xFEFFFFFFu);
    free(buf);
    laz_chunk_dec_free(cd);
    laz_close(&lf);
    free(d);
}

/* ---- COPC ---- */

typedef struct node_acc {
    size_t nodes;
    uint64_t points;
    copc_entry e[64];
} node_acc;

static int collect(void *ctx, const copc_entry *e)
{
    node_acc *a = ctx;
    if (a->nodes < 64) a->e[a->nodes] = *e;
    a->nodes++;
    a->points += (uint64_t)e->count;
    return 0;
}

static void test_copc_hierarchy_and_nodes(void **state)
{
    (void)state;
    size_t len;
    laz_file lf;
    uint8_t *d = open_laz("ellipsoid.copc.laz", &len, &lf);
    sd_err e = {0};
    copc_info info;
    assert_int_equal(copc_info_read(&lf, &info, &e), 0);
    assert_true(info.halfsize > 0 && info.spacing > 0);
    assert_int_equal(info.root_size % 32, 0);

    /* the root page as stored: entries read straight from the file's bytes here */
    copc_entry *pg;
    size_t n;
    assert_int_equal(copc_page_read(&lf, info.root_off, info.root_size, &pg, &n, &e), 0);
    assert_int_equal(n, info.root_size / 32);
    for (size_t i = 0; i < n; i++) {
        int32_t raw[4];
        uint64_t off;
        int32_t bc[2];
        memcpy(raw, d + info.root_off + 32 * i, 16);
        memcpy(&off, d + info.root_off + 32 * i + 16, 8);
        memcpy(bc, d + info.root_off + 32 * i + 24, 8);
        assert_int_equal(pg[i].level, raw[0]);
        assert_int_equal(pg[i].x, raw[1]);
        assert_int_equal(pg[i].off, off);
        assert_int_equal(pg[i].bytes, bc[0]);
        assert_int_equal(pg[i].count, bc[1]);
    }
    assert_int_equal(pg[0].level, 0); /* the root node */
    free(pg);

    /* the counts add up to the header's, and the nodes are the chunk table's chunks */
    node_acc acc = {0};
    assert_int_equal(copc_visit(&lf, INT32_MAX, collect, &acc, &e), 0);
    assert_int_equal(acc.points, lf.h.count);
    assert_int_equal(acc.points, 100000);
    size_t nonempty = 0;
    for (size_t i = 0; i < acc.nodes && i < 64; i++) nonempty += acc.e[i].count > 0;
    assert_int_equal(nonempty, lf.nchunks);

    /* each node read on its own equals the same points of the full decode */
    laz_close(&lf);
    uint8_t *all = decode_all("ellipsoid.copc.laz", d, len, &lf);
    laz_chunk_dec *cd = laz_chunk_dec_create(lf.items, lf.nitems);
    uint8_t *buf = NULL;
    size_t cap = 0;
    for (size_t i = 0; i < acc.nodes && i < 64; i++) {
        const copc_entry *q = &acc.e[i];
        if (q->count <= 0) continue;
        size_t c = 0;
        while (c < lf.nchunks && lf.chunk_start[c] != q->off) c++;
        assert_true(c < lf.nchunks);
        assert_int_equal(lf.chunk_first[c + 1] - lf.chunk_first[c], (uint64_t)q->count);
        assert_int_equal(copc_node_read(&lf, cd, q, &buf, &cap, &e), 0);
        assert_memory_equal(buf, all + lf.chunk_first[c] * lf.h.rec_len,
                            (size_t)q->count * lf.h.rec_len);
    }
    free(buf);
    free(all);
    laz_chunk_dec_free(cd);

    /* a broken page: an entry's key outside its level */
    uint8_t *b = malloc(len);
    memcpy(b, d, len);
    int32_t bad = 5;
    memcpy(b + info.root_off + 4, &bad, 4); /* x = 5 at level 0 */
    laz_file lb;
    assert_int_equal(laz_open(&lb, "bad.copc.laz", b, len, &e), 0);
    assert_int_equal(copc_page_read(&lb, info.root_off, info.root_size, &pg, &n, &e),
                     SD_EFORMAT);
    assert_non_null(strstr(e.msg, "bad.copc.laz: COPC hierarchy page"));
    assert_non_null(strstr(e.msg, "entry 0"));
    laz_close(&lb);
    free(b);

    /* not COPC */
    size_t l2;
    laz_file l14;
    uint8_t *d2 = open_laz("ellipsoid-1.4.laz", &l2, &l14);
    assert_int_equal(copc_info_read(&l14, &info, &e), SD_EFORMAT);
    laz_close(&l14);
    free(d2);
    laz_close(&lf);
    free(d);
}

/* The top levels alone: the counts of exactly those nodes, read without the deeper pages,
 * spread over the whole extent (a COPC level is a subsample of all of it). */
static void test_copc_top_levels(void **state)
{
    (void)state;
    size_t len;
    laz_file lf;
    uint8_t *d = open_laz("ellipsoid.copc.laz", &len, &lf);
    sd_err e = {0};
    node_acc acc = {0};
    assert_int_equal(copc_visit(&lf, INT32_MAX, collect, &acc, &e), 0);
    int32_t deepest = 0;
    for (size_t i = 0; i < acc.nodes; i++)
        if (acc.e[i].level > deepest) deepest = acc.e[i].level;
    assert_true(deepest >= 1); /* the file has more than a root */
    char p[1024];
    tu_data("ellipsoid.copc.laz", p, sizeof p);
    pc_raw full = {0};
    assert_int_equal(pc_read_laz(p, &full, &e), 0);
    double fmin[3], fmax[3];
    for (int k = 0; k < 3; k++) fmin[k] = 1e300, fmax[k] = -1e300;
    for (size_t i = 0; i < full.n; i++)
        for (int k = 0; k < 3; k++) {
            double v = full.xyz[3 * i + k];
            if (v < fmin[k]) fmin[k] = v;
            if (v > fmax[k]) fmax[k] = v;
        }
    for (int32_t L = 0; L <= deepest; L++) {
        uint64_t want = 0;
        for (size_t i = 0; i < acc.nodes; i++)
            if (acc.e[i].level <= L) want += (uint64_t)acc.e[i].count;
        pc_raw r = {0};
        assert_int_equal(pc_read_copc_levels(p, L, &r, &e), 0);
        assert_int_equal(r.n, want);
        assert_non_null(strstr(r.format, "COPC LAZ 1.4 format 7, levels 0-"));
        if (L == 0) {
            assert_true(r.n < full.n);
            for (int k = 0; k < 3; k++) {
                double lo = 1e300, hi = -1e300;
                for (size_t i = 0; i < r.n; i++) {
                    double v = r.xyz[3 * i + k];
                    if (v < lo) lo = v;
                    if (v > hi) hi = v;
                }
                assert_true(lo >= fmin[k] && hi <= fmax[k]);
                assert_true(hi - lo >= 0.5 * (fmax[k] - fmin[k]));
            }
        }
        pc_raw_free(&r);
    }
    /* all levels: the whole cloud */
    pc_raw r = {0};
    assert_int_equal(pc_read_copc_levels(p, INT32_MAX, &r, &e), 0);
    assert_int_equal(r.n, 100000);
    pc_raw_free(&r);
    pc_raw_free(&full);
    /* not COPC */
    assert_int_equal(pc_read_copc_levels(tu_data("ellipsoid-1.4.laz", p, sizeof p), 0, &r, &e),
                     SD_EFORMAT);
    assert_non_null(strstr(e.msg, "not a COPC file"));
    pc_raw_free(&r);
    laz_close(&lf);
    free(d);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_twins_formats_0_to_3),
        cmocka_unit_test(test_twin_extra_bytes),
        cmocka_unit_test(test_twin_autzen_three_chunks),
        cmocka_unit_test(test_las14_format1),
        cmocka_unit_test(test_ellipsoid_three_encodings),
        cmocka_unit_test(test_pc_load_equals_twin),
        cmocka_unit_test(test_laz_named_las),
        cmocka_unit_test(test_empty),
        cmocka_unit_test(test_malformed),
        cmocka_unit_test(test_truncated_chunk),
        cmocka_unit_test(test_copc_hierarchy_and_nodes),
        cmocka_unit_test(test_copc_top_levels),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
