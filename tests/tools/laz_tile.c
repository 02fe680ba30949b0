/* laz_tile — a large LAZ file made of copies of a real one, laid side by side, for benchmarks
 * and tests of LAZ input at scale (there is no LAZ encoder in Debian 12, nor in splatd).
 *
 *   laz_tile SRC.laz OUT.laz NX NY
 *
 * OUT holds NX x NY copies of SRC's points, copy (i, j) moved by i times SRC's width along x
 * and j times its depth along y (whole units of the file's scale, so every coordinate stays
 * exact): SRC's chunks, copied byte for byte, except the first point of each chunk, which
 * LASzip stores raw and from which every later point of the chunk is coded as a difference, so
 * moving it moves the chunk. The header's point counts and bounds are updated, the laszip
 * VLR's chunk size made variable (SRC's last chunk is often shorter than the others), and a new
 * chunk table written: its entries, each chunk's point count and byte size predicted from the
 * previous chunk's, through LASzip's integer compressor and arithmetic coder. This file holds
 * the encoder side of that coder (the models and their updates are the decoder's, laz_arith.h).
 *
 * SRC must be a LAZ file with pointwise (compressor 2) chunks, formats 0-3 (the raw first point
 * starts with X and Y), no extended VLRs, and OUT at most 2^32 - 1 points. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "las_header.h"
#include "laz.h"
#include "laz_arith.h"

/* ---- the arithmetic encoder: the exact inverse of laz_arith.h's decoder ---- */

typedef struct enc {
    uint32_t base, length;
    uint8_t *out;
    size_t n, cap;
} enc;

static void put(enc *e, uint8_t b)
{
    if (e->n == e->cap) {
        e->cap = e->cap ? 2 * e->cap : 4096;
        e->out = realloc(e->out, e->cap);
        if (!e->out) {
            fprintf(stderr, "laz_tile: out of memory\n");
            exit(1);
        }
    }
    e->out[e->n++] = b;
}

/* base wrapped past 2^32: add the carry into the bytes already written */
static void carry(enc *e)
{
    size_t i = e->n;
    while (i > 0 && e->out[i - 1] == 0xFF) e->out[--i] = 0;
    if (i > 0) e->out[i - 1]++;
}

static void renorm(enc *e)
{
    while (e->length < LAZ_AC_MIN_LENGTH) {
        put(e, (uint8_t)(e->base >> 24));
        e->base <<= 8;
        e->length <<= 8;
    }
}

/* the interval [x, y) of the current length's scaled range becomes the new interval */
static void narrow(enc *e, uint32_t x, uint32_t y)
{
    uint32_t b = e->base;
    e->base += x;
    e->length = y - x;
    if (e->base < b) carry(e);
    renorm(e);
}

static void enc_symbol(enc *e, laz_model *m, uint32_t sym)
{
    uint32_t top = e->length;
    uint32_t l = e->length >> LAZ_DM_SHIFT;
    uint32_t x = m->dist[sym] * l, y = sym == m->last ? top : m->dist[sym + 1] * l;
    narrow(e, x, y);
    ++m->count[sym];
    if (--m->until == 0) laz__model_update(m);
}

static void enc_bit(enc *e, laz_bitmodel *m, uint32_t bit)
{
    uint32_t x = m->bit0_prob * (e->length >> LAZ_BM_SHIFT);
    if (bit == 0) {
        e->length = x;
        ++m->bit0_count;
        renorm(e);
    } else {
        narrow(e, x, e->length);
    }
    if (--m->until == 0) laz__bitmodel_update(m);
}

static void enc_raw(enc *e, uint32_t v, unsigned bits) /* bits <= 19 */
{
    uint32_t l = e->length >> bits;
    narrow(e, v * l, v * l + l);
}

static void enc_bits(enc *e, uint32_t v, unsigned bits)
{
    if (bits > 19) {
        enc_raw(e, v & 0xFFFFu, 16);
        v >>= 16;
        bits -= 16;
    }
    enc_raw(e, v, bits);
}

/* The last bytes: a value inside the final interval whose bytes after these are all zero, then
 * zeros for the decoder's look-ahead (it holds four bytes). */
static void enc_done(enc *e)
{
    uint32_t b = e->base;
    if (e->length > 2 * LAZ_AC_MIN_LENGTH) {
        e->base += LAZ_AC_MIN_LENGTH;
        e->length = LAZ_AC_MIN_LENGTH >> 1;
    } else {
        e->base += LAZ_AC_MIN_LENGTH >> 1;
        e->length = LAZ_AC_MIN_LENGTH >> 9;
    }
    if (e->base < b) carry(e);
    renorm(e);
    for (int i = 0; i < 4; i++) put(e, 0);
}

/* The integer compressor's inverse: the correction real - pred as its bit count k (a symbol of
 * the context's model) and its value within k bits (laz_ic_decompress's mapping reversed). */
static void ic_compress(enc *e, laz_ic *ic, int32_t pred, int32_t real, unsigned ctx)
{
    int32_t corr = (int32_t)((uint32_t)real - (uint32_t)pred); /* 32-bit: no range wrap */
    uint32_t mag = corr > 0 ? (uint32_t)corr - 1 : (uint32_t)0 - (uint32_t)corr;
    unsigned k = 0;
    while (mag) {
        mag >>= 1;
        k++;
    }
    enc_symbol(e, &ic->mbits[ctx], k);
    if (k == 0) {
        enc_bit(e, &ic->corr0, (uint32_t)corr); /* 0 or 1 */
    } else if (k < 32) {
        uint32_t c = corr > 0 ? (uint32_t)corr - 1 : (uint32_t)corr + (1u << k) - 1;
        if (k <= ic->bits_high) {
            enc_symbol(e, &ic->corr[k], c);
        } else {
            unsigned k1 = k - ic->bits_high;
            enc_symbol(e, &ic->corr[k], c >> k1);
            enc_bits(e, c & ((1u << k1) - 1), k1);
        }
    }
}

/* ---- the tiling ---- */

static uint8_t *read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    uint8_t *d = NULL;
    size_t n = 0, cap = 0, got;
    do {
        if (n == cap) {
            cap = cap ? 2 * cap : 1 << 20;
            uint8_t *nd = realloc(d, cap);
            if (!nd) {
                free(d);
                fclose(f);
                return NULL;
            }
            d = nd;
        }
        got = fread(d + n, 1, cap - n, f);
        n += got;
    } while (got > 0);
    fclose(f);
    *size = n;
    return d;
}

static void wr32(uint8_t *p, uint32_t v) { memcpy(p, &v, 4); }
static void wr64(uint8_t *p, uint64_t v) { memcpy(p, &v, 8); }
static void wrf64(uint8_t *p, double v) { memcpy(p, &v, 8); }

static int die(const char *msg, const char *arg)
{
    fprintf(stderr, "laz_tile: %s%s\n", msg, arg ? arg : "");
    return 1;
}

int main(int argc, char **argv)
{
    if (argc != 5) return die("usage: laz_tile SRC.laz OUT.laz NX NY", NULL);
    int nx = atoi(argv[3]), ny = atoi(argv[4]);
    if (nx < 1 || ny < 1 || nx > 10000 || ny > 10000) return die("NX and NY: 1 to 10000", NULL);
    size_t size;
    uint8_t *d = read_file(argv[1], &size);
    if (!d) return die("cannot read ", argv[1]);
    laz_file lf;
    sd_err err = {0};
    if (laz_open(&lf, argv[1], d, size, &err) != 0) return die(err.msg, NULL);
    const las_header *h = &lf.h;
    if (lf.compressor != 2 || h->format > 3 || h->nevlr)
        return die("needs pointwise chunks (compressor 2), formats 0-3, no extended VLRs: ",
                   argv[1]);
    uint64_t tiles = (uint64_t)nx * (uint64_t)ny, total = h->count * tiles;
    if (total > UINT32_MAX) return die("more than 2^32 - 1 points", NULL);
    /* the copies' steps in whole units of the scale: the file's extent, rounded up */
    double minx = rdf64(d + 187), maxx = rdf64(d + 179), miny = rdf64(d + 203),
           maxy = rdf64(d + 195);
    int64_t sx = (int64_t)((maxx - minx) / h->scale[0]) + 1;
    int64_t sy = (int64_t)((maxy - miny) / h->scale[1]) + 1;

    /* header and VLRs as they are, with the counts, bounds and a variable chunk size */
    uint8_t *head = malloc(h->data_off);
    if (!head) return die("out of memory", NULL);
    memcpy(head, d, h->data_off);
    wr32(head + 107, (uint32_t)total);
    for (int r = 0; r < 5; r++) wr32(head + 111 + 4 * r, (uint32_t)(rd32(d + 111 + 4 * r) * tiles));
    if (h->minor >= 4 && h->header_size >= 375) {
        wr64(head + 247, total);
        for (int r = 0; r < 15; r++) wr64(head + 255 + 8 * r, rd64(d + 255 + 8 * r) * tiles);
    }
    wrf64(head + 179, maxx + (double)(nx - 1) * (double)sx * h->scale[0]);
    wrf64(head + 195, maxy + (double)(ny - 1) * (double)sy * h->scale[1]);
    int found = 0;
    for (size_t o = h->header_size; o + 54 <= h->data_off;) {
        uint16_t rid = rd16(head + o + 18), len = rd16(head + o + 20);
        if (!memcmp(head + o + 2, "laszip encoded", 14) && rid == 22204 && len >= 16) {
            wr32(head + o + 54 + 12, UINT32_MAX);
            found = 1;
        }
        o += 54 + (size_t)len;
    }
    if (!found) return die("no laszip VLR in ", argv[1]);

    FILE *out = fopen(argv[2], "wb");
    if (!out) return die("cannot write ", argv[2]);
    int bad = fwrite(head, 1, h->data_off, out) != h->data_off;
    uint8_t zero8[8] = {0};
    bad |= fwrite(zero8, 1, 8, out) != 8; /* the chunk table's offset, written at the end */
    uint64_t pos = (uint64_t)h->data_off + 8;
    size_t maxc = 0;
    for (size_t c = 0; c < lf.nchunks; c++)
        if (lf.chunk_start[c + 1] - lf.chunk_start[c] > maxc)
            maxc = (size_t)(lf.chunk_start[c + 1] - lf.chunk_start[c]);
    uint8_t *buf = malloc(maxc);
    if (!buf) return die("out of memory", NULL);
    for (int j = 0; j < ny && !bad; j++)
        for (int i = 0; i < nx && !bad; i++)
            for (size_t c = 0; c < lf.nchunks && !bad; c++) {
                size_t len = (size_t)(lf.chunk_start[c + 1] - lf.chunk_start[c]);
                memcpy(buf, d + lf.chunk_start[c], len);
                int64_t x = rdi32(buf) + (int64_t)i * sx, y = rdi32(buf + 4) + (int64_t)j * sy;
                if (x > INT32_MAX || y > INT32_MAX)
                    return die("the copies leave int32 range", NULL);
                wr32(buf, (uint32_t)(int32_t)x);
                wr32(buf + 4, (uint32_t)(int32_t)y);
                bad |= fwrite(buf, 1, len, out) != len;
                pos += len;
            }

    /* the chunk table: version 0, the count, then per chunk its points and bytes */
    laz_ic ic;
    if (laz_ic_create(&ic, 32, 2) || laz_ic_init(&ic)) return die("out of memory", NULL);
    enc e = {.base = 0, .length = UINT32_MAX};
    int32_t prev_pts = 0, prev_bytes = 0;
    for (uint64_t t = 0; t < tiles; t++)
        for (size_t c = 0; c < lf.nchunks; c++) {
            int32_t pts = (int32_t)(lf.chunk_first[c + 1] - lf.chunk_first[c]);
            int32_t bytes = (int32_t)(lf.chunk_start[c + 1] - lf.chunk_start[c]);
            ic_compress(&e, &ic, prev_pts, pts, 0);
            ic_compress(&e, &ic, prev_bytes, bytes, 1);
            prev_pts = pts;
            prev_bytes = bytes;
        }
    enc_done(&e);
    laz_ic_free(&ic);
    uint8_t th[8];
    wr32(th, 0);
    wr32(th + 4, (uint32_t)(tiles * lf.nchunks));
    bad |= fwrite(th, 1, 8, out) != 8;
    bad |= fwrite(e.out, 1, e.n, out) != e.n;
    uint8_t off[8];
    wr64(off, pos);
    bad |= fseek(out, (long)h->data_off, SEEK_SET) != 0 || fwrite(off, 1, 8, out) != 8;
    bad |= fclose(out) != 0;
    if (bad) return die("write failed: ", argv[2]);
    printf("%s: %llu points in %llu chunks (%d x %d copies of %s)\n", argv[2],
           (unsigned long long)total, (unsigned long long)(tiles * lf.nchunks), nx, ny, argv[1]);
    free(e.out);
    free(buf);
    free(head);
    laz_close(&lf);
    free(d);
    return 0;
}
