/* e57test.c — see e57test.h. */
#include "e57test.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { PACKET_MAX = 65536 };

uint32_t e57w_crc32c(const uint8_t *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) c = (c >> 1) ^ (0x82F63B78u & (0u - (c & 1u)));
    }
    return ~c;
}

uint64_t e57w_phys(uint64_t l, uint32_t page)
{
    return l / (page - 4) * page + l % (page - 4);
}

static void put_crc(uint8_t *pg, uint32_t page, uint32_t c)
{
    pg[page - 4] = (uint8_t)(c >> 24);
    pg[page - 3] = (uint8_t)(c >> 16);
    pg[page - 2] = (uint8_t)(c >> 8);
    pg[page - 1] = (uint8_t)c;
}

void e57w_fix_crcs(uint8_t *d, size_t n, uint32_t page)
{
    for (size_t p = 0; p + page <= n; p += page) put_crc(d + p, page, e57w_crc32c(d + p, page - 4));
}

/* The page writer: logical bytes in, pages with checksums out; page 0 is held until the end
 * (it gets the header last). */
typedef struct pw {
    FILE *fp;
    uint32_t page;
    uint64_t l; /* logical bytes written */
    uint8_t *cur, *page0; /* the page being filled; page 0 */
    uint32_t table[256];
    int failed;
} pw;

static uint32_t crc_table(const pw *w, const uint8_t *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) c = w->table[(c ^ p[i]) & 0xFF] ^ (c >> 8);
    return ~c;
}

static void pw_put(pw *w, const void *src, size_t n)
{
    const uint8_t *s = src;
    uint32_t data = w->page - 4;
    while (n > 0) {
        uint32_t in = (uint32_t)(w->l % data);
        size_t m = data - in < n ? data - in : n;
        memcpy(w->cur + in, s, m);
        s += m;
        n -= m;
        w->l += m;
        if (w->l % data == 0) {
            if (w->l / data == 1) {
                memcpy(w->page0, w->cur, w->page);
            } else {
                put_crc(w->cur, w->page, crc_table(w, w->cur, data));
                if (fwrite(w->cur, 1, w->page, w->fp) != w->page) w->failed = 1;
            }
            memset(w->cur, 0, w->page);
        }
    }
}

static void pw_u8(pw *w, unsigned v)
{
    uint8_t b = (uint8_t)v;
    pw_put(w, &b, 1);
}

static void pw_uint(pw *w, uint64_t v, int size)
{
    uint8_t b[8];
    for (int i = 0; i < size; i++) b[i] = (uint8_t)(v >> (8 * i));
    pw_put(w, b, (size_t)size);
}

/* A field's bit writer: whole bytes in buf, the bits of a started byte in acc. */
typedef struct bw {
    uint8_t *buf;
    size_t len, cap, taken; /* bytes written, allocated, already put in packets */
    uint64_t acc;
    int nacc;
    uint64_t bits; /* bits written so far */
} bw;

static void bw_byte(bw *b, uint8_t v)
{
    if (b->len == b->cap) {
        b->cap = b->cap ? 2 * b->cap : 4096;
        b->buf = realloc(b->buf, b->cap);
        if (!b->buf) abort();
    }
    b->buf[b->len++] = v;
}

static void bw_bits(bw *b, uint64_t v, int k)
{
    b->bits += (uint64_t)k;
    for (int i = 0; i < k; i++) { /* bit by bit: the simplest form of least-significant first */
        b->acc |= ((v >> i) & 1u) << b->nacc;
        if (++b->nacc == 8) {
            bw_byte(b, (uint8_t)b->acc);
            b->acc = 0;
            b->nacc = 0;
        }
    }
}

static void bw_flush(bw *b)
{
    if (b->nacc) bw_byte(b, (uint8_t)b->acc);
    b->acc = 0;
    b->nacc = 0;
}

/* Drops the bytes already put in packets. */
static void bw_compact(bw *b)
{
    memmove(b->buf, b->buf + b->taken, b->len - b->taken);
    b->len -= b->taken;
    b->taken = 0;
}

static int bits_of(const e57w_field *f)
{
    if (f->kind == E57W_F32) return 32;
    if (f->kind == E57W_F64) return 64;
    int64_t lo = f->no_bounds ? INT64_MIN : f->min, hi = f->no_bounds ? INT64_MAX : f->max;
    uint64_t r = (uint64_t)hi - (uint64_t)lo;
    int k = 0;
    while (k < 64 && (r >> k)) k++;
    return k;
}

/* The layout of a scan's packets: per packet, each field's bytes. */
typedef struct plan {
    uint64_t npk; /* data packets */
    uint64_t *bytes; /* npk * nfields: bytes of field f in packet k */
    uint64_t section_len; /* logical bytes of the section */
} plan;

/* byte_end: the bytes of field f's stream up to the end of packet k (0-based). */
static uint64_t byte_end(const e57w_scan *s, uint32_t f, uint64_t k, uint64_t npk)
{
    uint64_t bits = (uint64_t)bits_of(&s->fields[f]);
    uint64_t total = (s->records * bits + 7) / 8;
    if (k + 1 >= npk) return total;
    uint64_t per = s->per_packet + (uint64_t)f * s->stagger;
    uint64_t recs = (k + 1) * per;
    if (recs >= s->records) return total;
    return recs * bits / 8;
}

static int make_plan(const e57w_scan *in, plan *p)
{
    /* per_packet 0: as many records as fit a packet (the slowest field's count) */
    e57w_scan sv = *in;
    const e57w_scan *s = &sv;
    if (!sv.per_packet) {
        uint64_t bits = 0;
        for (uint32_t f = 0; f < sv.nfields; f++) bits += (uint64_t)bits_of(&sv.fields[f]);
        uint64_t room = 8 * ((uint64_t)PACKET_MAX - 8 - 2 * (uint64_t)sv.nfields - 4 * sv.nfields);
        uint64_t per = bits ? room / bits : sv.records;
        uint64_t grow = (uint64_t)(sv.nfields ? sv.nfields - 1 : 0) * sv.stagger;
        sv.per_packet = (uint32_t)(per > grow + 1 ? per - grow : 1);
    }
    uint64_t npk = 1;
    for (uint32_t f = 0; f < s->nfields && s->per_packet; f++) {
        uint64_t per = s->per_packet + (uint64_t)f * s->stagger;
        uint64_t k = (s->records + per - 1) / per;
        if (k > npk) npk = k;
    }
    p->npk = npk;
    p->bytes = calloc(npk * (s->nfields ? s->nfields : 1), sizeof *p->bytes);
    if (!p->bytes) return -1;
    uint64_t len = 32;
    for (uint64_t k = 0; k < npk; k++) {
        uint64_t pk = 6 + 2 * (uint64_t)s->nfields;
        for (uint32_t f = 0; f < s->nfields; f++) {
            uint64_t a = k ? byte_end(s, f, k - 1, npk) : 0, b = byte_end(s, f, k, npk);
            p->bytes[k * s->nfields + f] = b - a;
            pk += b - a;
        }
        pk = (pk + 3) & ~(uint64_t)3; /* packets padded to 4 bytes */
        if (pk > PACKET_MAX) {
            fprintf(stderr,
                    "e57w: packet %llu would be %llu bytes (at most 65536): set "
                    "per_packet\n",
                    (unsigned long long)k, (unsigned long long)pk);
            free(p->bytes);
            return -1;
        }
        len += pk;
    }
    if (s->empty_packet) len += 8;
    if (s->index_packet) len += 32;
    p->section_len = len;
    return 0;
}

/* write_scan: scan si's compressed vector section; *phys gets its physical offset. */
static int write_scan(pw *w, const e57w_scan *s, uint32_t si, e57w_gen gen, void *ctx,
                      uint64_t *phys)
{
    plan p;
    if (make_plan(s, &p) < 0) return -1;
    uint32_t nf = s->nfields;
    bw *b = calloc(nf ? nf : 1, sizeof *b);
    int64_t *iv = calloc(nf ? nf : 1, sizeof *iv);
    double *dv = calloc(nf ? nf : 1, sizeof *dv);
    if (!b || !iv || !dv) abort();
    uint64_t l0 = w->l;
    *phys = e57w_phys(l0, w->page);
    pw_u8(w, 1);
    for (int i = 0; i < 7; i++) pw_u8(w, 0);
    pw_uint(w, p.section_len, 8);
    pw_uint(w, e57w_phys(l0 + 32, w->page), 8);
    uint64_t index_l = l0 + p.section_len - 32;
    pw_uint(w, s->index_packet ? e57w_phys(index_l, w->page) : 0, 8);
    uint64_t next = 0; /* the next record to generate */
    for (uint64_t k = 0; k < p.npk; k++) {
        /* generate records until every field has the bytes of packet k */
        for (;;) {
            int enough = 1;
            for (uint32_t f = 0; f < nf && enough; f++)
                enough = b[f].len - b[f].taken >= p.bytes[k * nf + f];
            if (enough || next > s->records) break;
            if (next == s->records) {
                for (uint32_t f = 0; f < nf; f++) bw_flush(&b[f]);
                next++;
                continue;
            }
            gen(ctx, si, next++, iv, dv);
            for (uint32_t f = 0; f < nf; f++) {
                const e57w_field *fd = &s->fields[f];
                int bits = bits_of(fd);
                if (fd->kind == E57W_F32) {
                    float x = (float)dv[f];
                    uint32_t u;
                    memcpy(&u, &x, 4);
                    bw_bits(&b[f], u, 32);
                } else if (fd->kind == E57W_F64) {
                    uint64_t u;
                    memcpy(&u, &dv[f], 8);
                    bw_bits(&b[f], u, 64);
                } else {
                    int64_t lo = fd->no_bounds ? INT64_MIN : fd->min;
                    bw_bits(&b[f], (uint64_t)iv[f] - (uint64_t)lo, bits);
                }
            }
        }
        uint64_t body = 0;
        for (uint32_t f = 0; f < nf; f++) body += p.bytes[k * nf + f];
        uint64_t len = 6 + 2 * (uint64_t)nf + body, padded = (len + 3) & ~(uint64_t)3;
        pw_u8(w, 1);
        pw_u8(w, 0);
        pw_uint(w, padded - 1, 2);
        pw_uint(w, nf, 2);
        for (uint32_t f = 0; f < nf; f++) pw_uint(w, p.bytes[k * nf + f], 2);
        for (uint32_t f = 0; f < nf; f++) {
            uint64_t m = p.bytes[k * nf + f];
            pw_put(w, b[f].buf + b[f].taken, (size_t)m);
            b[f].taken += (size_t)m;
            bw_compact(&b[f]);
        }
        for (uint64_t z = len; z < padded; z++) pw_u8(w, 0);
        if (k == 0 && s->empty_packet) { /* type 2, 8 bytes */
            pw_u8(w, 2);
            pw_u8(w, 0);
            pw_uint(w, 7, 2);
            pw_uint(w, 0, 4);
        }
    }
    if (s->index_packet) { /* one entry: record 0 in the first data packet */
        pw_u8(w, 0);
        pw_u8(w, 0);
        pw_uint(w, 31, 2);
        pw_uint(w, 1, 2);
        pw_u8(w, 0);
        for (int i = 0; i < 9; i++) pw_u8(w, 0);
        pw_uint(w, 0, 8);
        pw_uint(w, e57w_phys(l0 + 32, w->page), 8);
    }
    int ok = w->l == l0 + p.section_len;
    if (!ok)
        fprintf(stderr, "e57w: scan %u: wrote %llu section bytes, planned %llu\n", si,
                (unsigned long long)(w->l - l0), (unsigned long long)p.section_len);
    for (uint32_t f = 0; f < nf; f++) free(b[f].buf);
    free(b);
    free(iv);
    free(dv);
    free(p.bytes);
    return ok ? 0 : -1;
}

/* xml_of: the XML section for the scans at the physical offsets cv. */
static char *xml_of(const e57w_scan *scans, uint32_t nscans, const uint64_t *cv, const e57w_opts *o,
                    size_t *len)
{
    char *x = NULL;
    FILE *m = open_memstream(&x, len);
    if (!m) abort();
    fprintf(m,
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<e57Root type=\"Structure\" "
            "xmlns=\"http://www.astm.org/COMMIT/E57/2010-e57-v1.0\" "
            "xmlns:nor=\"http://www.libe57.org/E57_NOR_surface_normals.txt\">\n"
            "<formatName type=\"String\"><![CDATA[ASTM E57 3D Imaging Data File]]></formatName>\n"
            "<guid type=\"String\"><![CDATA[splatd test]]></guid>\n"
            "<versionMajor type=\"Integer\">1</versionMajor><versionMinor type=\"Integer\"/>\n"
            "<data3D type=\"Vector\" allowHeterogeneousChildren=\"1\">\n");
    for (uint32_t i = 0; i < nscans; i++) {
        const e57w_scan *s = &scans[i];
        fprintf(m, "<vectorChild type=\"Structure\">\n<guid type=\"String\">scan %u</guid>\n", i);
        if (s->pose) {
            fprintf(m, "<pose type=\"Structure\">\n");
            if (!s->pose_no_rotation)
                fprintf(m,
                        "<rotation type=\"Structure\"><w type=\"Float\">%.17g</w><x "
                        "type=\"Float\">%.17g</x><y type=\"Float\">%.17g</y><z type=\"Float\">"
                        "%.17g</z></rotation>\n",
                        s->quat[0], s->quat[1], s->quat[2], s->quat[3]);
            fprintf(m,
                    "<translation type=\"Structure\"><x type=\"Float\">%.17g</x><y "
                    "type=\"Float\">%.17g</y><z type=\"Float\">%.17g</z></translation>\n"
                    "</pose>\n",
                    s->trans[0], s->trans[1], s->trans[2]);
        }
        if (s->extra_xml) fprintf(m, "%s\n", s->extra_xml);
        fprintf(m,
                "<points type=\"CompressedVector\" fileOffset=\"%llu\" recordCount=\"%llu\">\n"
                "<prototype type=\"Structure\">\n",
                (unsigned long long)cv[i], (unsigned long long)s->records);
        for (uint32_t f = 0; f < s->nfields; f++) {
            const e57w_field *fd = &s->fields[f];
            if (fd->kind == E57W_F32 || fd->kind == E57W_F64)
                fprintf(m, "<%s type=\"Float\" precision=\"%s\"/>\n", fd->name,
                        fd->kind == E57W_F32 ? "single" : "double");
            else if (fd->kind == E57W_INT && fd->no_bounds)
                fprintf(m, "<%s type=\"Integer\"/>\n", fd->name);
            else if (fd->kind == E57W_INT)
                fprintf(m, "<%s type=\"Integer\" minimum=\"%lld\" maximum=\"%lld\"/>\n", fd->name,
                        (long long)fd->min, (long long)fd->max);
            else
                fprintf(m,
                        "<%s type=\"ScaledInteger\" minimum=\"%lld\" maximum=\"%lld\" "
                        "scale=\"%.17g\" offset=\"%.17g\"/>\n",
                        fd->name, (long long)fd->min, (long long)fd->max,
                        fd->scale ? fd->scale : 1.0, fd->offset);
        }
        fprintf(m,
                "</prototype>\n<codecs type=\"Vector\" allowHeterogeneousChildren=\"1\">"
                "</codecs>\n</points>\n</vectorChild>\n");
    }
    fprintf(m, "</data3D>\n%s</e57Root>\n", o && o->root_extra ? o->root_extra : "");
    fclose(m);
    return x;
}

int e57w_write(const char *path, const e57w_scan *scans, uint32_t nscans, const e57w_opts *o,
               e57w_gen gen, void *ctx)
{
    pw w = {.page = o && o->page ? o->page : 1024};
    for (uint32_t i = 0; i < 256; i++) {
        uint8_t b = (uint8_t)i;
        /* the table from the bit-by-bit form: the CRC of one byte from an all-zero register */
        uint32_t c = (uint32_t)b;
        for (int k = 0; k < 8; k++) c = (c >> 1) ^ (0x82F63B78u & (0u - (c & 1u)));
        w.table[i] = c;
    }
    w.fp = fopen(path, "wb");
    w.cur = calloc(1, w.page);
    w.page0 = calloc(1, w.page);
    uint64_t *cv = calloc(nscans ? nscans : 1, sizeof *cv);
    if (!w.fp || !w.cur || !w.page0 || !cv) {
        fprintf(stderr, "e57w: cannot write %s\n", path);
        if (w.fp) fclose(w.fp);
        free(w.cur), free(w.page0), free(cv);
        return -1;
    }
    uint8_t zero[48] = {0};
    if (fwrite(w.page0, 1, w.page, w.fp) != w.page) w.failed = 1; /* page 0's place */
    pw_put(&w, zero, 48); /* the header's place */
    int rc = 0;
    for (uint32_t i = 0; i < nscans && rc == 0; i++)
        rc = write_scan(&w, &scans[i], i, gen, ctx, &cv[i]);
    size_t xlen = 0;
    char *x = rc == 0 ? xml_of(scans, nscans, cv, o, &xlen) : NULL;
    uint64_t xl = w.l;
    if (x) pw_put(&w, x, xlen);
    free(x);
    uint32_t data = w.page - 4;
    while (w.l % data) pw_u8(&w, 0); /* a whole number of pages */
    uint64_t npages = w.l / data;
    uint8_t *h = w.page0;
    memcpy(h, "ASTM-E57", 8);
    for (int i = 0; i < 4; i++) h[8 + i] = (uint8_t)(1u >> (8 * i)), h[12 + i] = 0;
    uint64_t hv[4] = {npages * w.page, e57w_phys(xl, w.page), xlen, w.page};
    for (int k = 0; k < 4; k++)
        for (int i = 0; i < 8; i++) h[16 + 8 * k + i] = (uint8_t)(hv[k] >> (8 * i));
    put_crc(h, w.page, crc_table(&w, h, data));
    if (fseek(w.fp, 0, SEEK_SET) != 0 || fwrite(h, 1, w.page, w.fp) != w.page) w.failed = 1;
    if (fclose(w.fp) != 0) w.failed = 1;
    free(w.cur), free(w.page0), free(cv);
    if (w.failed) fprintf(stderr, "e57w: writing %s failed\n", path);
    return rc < 0 || w.failed ? -1 : 0;
}
