/* io_pcd.c — the PCD reader (Point Cloud Library format, versions 0.5 to 0.7).
 *
 * A PCD file is a text header, one "KEYWORD values..." line each, ending with the DATA line:
 *   VERSION 0.7 / FIELDS x y z rgb / SIZE 4 4 4 4 / TYPE F F F U / COUNT 1 1 1 1 /
 *   WIDTH 640 / HEIGHT 480 / VIEWPOINT tx ty tz qw qx qy qz / POINTS 307200 /
 *   DATA ascii | binary | binary_compressed
 * '#' lines are comments; the keywords may come in any order (as PCL tolerates); COUNT is
 * optional (1 each). The data follows the DATA line: ascii is one point per line; binary is one
 * packed record per point (array of structures); binary_compressed is u32 compressed size,
 * u32 uncompressed size and an LZF stream that decodes to each field's values for all points
 * stored contiguously (structure of arrays). Values are little-endian, as PCL writes them on
 * every platform it supports.
 *
 * Fields read: x y z (or X Y Z), rgb/rgba (packed in 4 bytes, B G R A from the low byte),
 * red green blue (separate, 8 or 16 bit: scaled to 8 bit when a value exceeds 255),
 * intensity, normal_x normal_y normal_z, classification (any case of the first letter).
 * Everything else is skipped by its SIZE * COUNT. */
#include "cloud.h"
#include "io_text.h"
#include "lzf.h"
#include "pcd_stream.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/mman.h>
#include <unistd.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "io_pcd.c reads little-endian PCD values with memcpy; add byte swapping for this host"
#endif

#define PCD_MAX_HEADER (1u << 20)      /* a header longer than this is garbage, not a PCD */
#define PCD_MAX_FIELDS 4096u           /* FIELDS entries; PCL's largest descriptors use ~10 */
#define PCD_MAX_COUNT (1u << 20)       /* COUNT of one field */
#define PCD_MAX_POINT_SIZE (1u << 20)  /* bytes of one point record */

enum role {
    R_SKIP, R_X, R_Y, R_Z, R_PACKED_RGB, R_INTENSITY, R_NX, R_NY, R_NZ, R_CLASS,
    R_RED, R_GREEN, R_BLUE,
};

/* One FIELDS entry, with its SIZE, TYPE and COUNT. */
typedef struct pcd_field {
    char name[48];
    uint32_t size, count;
    char type;         /* 'F', 'I' or 'U' */
    int role;
    uint64_t off;      /* byte offset in a binary (array of structures) point record */
    uint64_t soa_off;  /* byte offset of the field's block in the decompressed data */
} pcd_field;

/* The parsed header. Line numbers are 1-based, 0 when the keyword was absent. */
typedef struct pcd_header {
    pcd_field *f;
    size_t nf;
    uint32_t *size, *count; /* as read, before they are checked against FIELDS */
    char *type;
    size_t n_size, n_type, n_count;
    int ln_version, ln_fields, ln_size, ln_type, ln_count, ln_width, ln_height, ln_points;
    int ln_data, ln_viewpoint;
    double viewpoint[7];   /* tx ty tz qw qx qy qz, when ln_viewpoint */
    uint64_t width, height, points;
    char version[8];
    char data[24];
    uint64_t data_off;   /* first byte after the DATA line */
    uint64_t point_size; /* bytes of one record */
    uint64_t values;     /* numbers per point (sum of COUNT), for ascii */
    int used[16];        /* indices of the fields with a role, in field order */
    int n_used;
    int sep_rgb;         /* colour from red/green/blue fields */
} pcd_header;

static void header_free(pcd_header *h)
{
    free(h->f);
    free(h->size);
    free(h->count);
    free(h->type);
    memset(h, 0, sizeof *h);
}

/* ---- header tokens ---- */

typedef struct tok { const char *s; size_t n; } tok;

/* Returns the next whitespace-separated token of [*p, end) in t and advances *p; 0 at the end. */
static int next_tok(const char **p, const char *end, tok *t)
{
    const char *s = *p;
    while (s < end && pc__is_space((unsigned char)*s)) s++;
    if (s >= end) {
        *p = s;
        return 0;
    }
    const char *e = s;
    while (e < end && !pc__is_space((unsigned char)*e)) e++;
    t->s = s;
    t->n = (size_t)(e - s);
    *p = e;
    return 1;
}

static size_t count_toks(const char *p, const char *end)
{
    size_t n = 0;
    tok t;
    while (next_tok(&p, end, &t)) n++;
    return n;
}

static int tok_is(const tok *t, const char *word)
{
    size_t n = strlen(word);
    return t->n == n && memcmp(t->s, word, n) == 0;
}

/* Writes a printable copy of at most 24 bytes of t to buf (for messages about garbage). */
static const char *printable(const tok *t, char *buf, size_t len)
{
    size_t n = t->n < 24 ? t->n : 24, j = 0;
    for (size_t i = 0; i < n && j + 1 < len; i++) {
        unsigned char c = (unsigned char)t->s[i];
        buf[j++] = (c >= 32 && c < 127) ? (char)c : '?';
    }
    buf[j] = 0;
    if (t->n > n && j + 4 < len) strcat(buf, "...");
    return buf;
}

/* Parses a decimal unsigned integer token; 0 on success, -1 on anything else or overflow. */
static int tok_u64(const tok *t, uint64_t *v)
{
    if (t->n == 0 || t->n > 20) return -1;
    uint64_t x = 0;
    for (size_t i = 0; i < t->n; i++) {
        unsigned d = (unsigned)(t->s[i] - '0');
        if (d > 9) return -1;
        if (x > (UINT64_MAX - d) / 10) return -1;
        x = x * 10 + d;
    }
    *v = x;
    return 0;
}

/* Reads the single unsigned value of a WIDTH/HEIGHT/POINTS line into *v. */
static int header_u64(const char *path, const char *kw, int line, const char *p, const char *end,
                      uint64_t *v, sd_err *err)
{
    tok t;
    if (!next_tok(&p, end, &t) || tok_u64(&t, v) != 0 || count_toks(p, end) != 0)
        return sd_errf(err, SD_EFORMAT, "%s: %s at line %d needs one unsigned integer", path, kw,
                       line);
    return 0;
}

/* Reads VIEWPOINT's seven finite numbers into h->viewpoint. */
static int header_viewpoint(const char *path, pcd_header *h, int line, const char *p,
                            const char *end, sd_err *err)
{
    int k = 0;
    tok t;
    while (next_tok(&p, end, &t)) {
        double v;
        if (k == 7 || pc__parse_num(t.s, t.s + t.n, &v) != t.s + t.n || !isfinite(v)) {
            k = -1;
            break;
        }
        h->viewpoint[k++] = v;
    }
    if (k != 7)
        return sd_errf(err, SD_EFORMAT, "%s: VIEWPOINT at line %d needs 7 finite numbers "
                       "(tx ty tz qw qx qy qz)", path, line);
    return 0;
}

/* Reads the per-field values of SIZE or COUNT into a new array *out of *n entries. */
static int header_u32_list(const char *path, const char *kw, int line, const char *p,
                           const char *end, uint32_t **out, size_t *n, sd_err *err)
{
    size_t k = count_toks(p, end);
    if (k == 0 || k > PCD_MAX_FIELDS)
        return sd_errf(err, SD_EFORMAT, "%s: %s at line %d has %zu values (1 to %u expected)",
                       path, kw, line, k, PCD_MAX_FIELDS);
    *out = malloc(k * sizeof **out);
    if (!*out) return sd_errf(err, SD_ENOMEM, "%s: out of memory at line %d", path, line);
    tok t;
    for (size_t i = 0; next_tok(&p, end, &t); i++) {
        uint64_t v;
        char buf[32];
        if (tok_u64(&t, &v) != 0 || v > UINT32_MAX)
            return sd_errf(err, SD_EFORMAT, "%s: %s value %zu ('%s') at line %d is not an "
                           "unsigned integer", path, kw, i + 1, printable(&t, buf, sizeof buf),
                           line);
        (*out)[i] = (uint32_t)v;
    }
    *n = k;
    return 0;
}

static int header_fields(const char *path, pcd_header *h, int line, const char *p,
                         const char *end, sd_err *err)
{
    size_t k = count_toks(p, end);
    if (k == 0 || k > PCD_MAX_FIELDS)
        return sd_errf(err, SD_EFORMAT, "%s: FIELDS at line %d has %zu names (1 to %u expected)",
                       path, line, k, PCD_MAX_FIELDS);
    h->f = calloc(k, sizeof *h->f);
    if (!h->f) return sd_errf(err, SD_ENOMEM, "%s: out of memory at line %d", path, line);
    tok t;
    for (size_t i = 0; next_tok(&p, end, &t); i++) {
        size_t n = t.n < sizeof h->f[i].name - 1 ? t.n : sizeof h->f[i].name - 1;
        memcpy(h->f[i].name, t.s, n);
    }
    h->nf = k;
    return 0;
}

static int header_type(const char *path, pcd_header *h, int line, const char *p,
                       const char *end, sd_err *err)
{
    size_t k = count_toks(p, end);
    if (k == 0 || k > PCD_MAX_FIELDS)
        return sd_errf(err, SD_EFORMAT, "%s: TYPE at line %d has %zu values (1 to %u expected)",
                       path, line, k, PCD_MAX_FIELDS);
    h->type = malloc(k);
    if (!h->type) return sd_errf(err, SD_ENOMEM, "%s: out of memory at line %d", path, line);
    tok t;
    for (size_t i = 0; next_tok(&p, end, &t); i++) {
        char buf[32];
        if (t.n != 1 || (t.s[0] != 'F' && t.s[0] != 'I' && t.s[0] != 'U'))
            return sd_errf(err, SD_EFORMAT, "%s: TYPE value %zu ('%s') at line %d is not F, I "
                           "or U", path, i + 1, printable(&t, buf, sizeof buf), line);
        h->type[i] = t.s[0];
    }
    h->n_type = k;
    return 0;
}

static int header_version(const char *path, pcd_header *h, int line, const char *p,
                          const char *end, sd_err *err)
{
    static const char *const ok[] = {"0.7", ".7", "0.6", ".6", "0.5", ".5"};
    tok t;
    char buf[32];
    if (!next_tok(&p, end, &t))
        return sd_errf(err, SD_EFORMAT, "%s: VERSION at line %d has no value", path, line);
    for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
        if (!tok_is(&t, ok[i])) continue;
        snprintf(h->version, sizeof h->version, "0.%c", ok[i][strlen(ok[i]) - 1]);
        return 0;
    }
    return sd_errf(err, SD_EUNSUP, "%s: PCD VERSION '%s' at line %d is not supported (0.5 to "
                   "0.7)", path, printable(&t, buf, sizeof buf), line);
}

static int header_data(const char *path, pcd_header *h, int line, const char *p,
                       const char *end, sd_err *err)
{
    tok t;
    char buf[32];
    if (!next_tok(&p, end, &t))
        return sd_errf(err, SD_EFORMAT, "%s: DATA at line %d has no value", path, line);
    if (!tok_is(&t, "ascii") && !tok_is(&t, "binary") && !tok_is(&t, "binary_compressed"))
        return sd_errf(err, SD_EUNSUP, "%s: DATA '%s' at line %d is not supported (ascii, "
                       "binary, binary_compressed)", path, printable(&t, buf, sizeof buf), line);
    memcpy(h->data, t.s, t.n);
    h->data[t.n] = 0;
    return 0;
}

/* Marks keyword kw as seen at line; a second occurrence is an error. */
static int seen(const char *path, const char *kw, int *ln, int line, sd_err *err)
{
    if (*ln)
        return sd_errf(err, SD_EFORMAT, "%s: %s at line %d repeats the one at line %d", path,
                       kw, line, *ln);
    *ln = line;
    return 0;
}

/* Reads header lines from data[0..) until the DATA line. Returns 0 with h filled (data_off,
 * the raw per-keyword values), or a negative code naming the line. */
static int parse_header_lines(const char *path, const uint8_t *data, size_t size,
                              pcd_header *h, sd_err *err)
{
    const char *base = (const char *)data;
    const char *hend = base + (size < PCD_MAX_HEADER ? size : PCD_MAX_HEADER);
    const char *s = base;
    int line = 0, rc = 0;
    while (!h->ln_data) {
        if (s >= base + size)
            return sd_errf(err, SD_ETRUNC, "%s: the header ends at line %d (offset %zu) without "
                           "a DATA line", path, line, size);
        if (s >= hend)
            return sd_errf(err, SD_ELIMIT, "%s: no DATA line in the first %u bytes (line %d at "
                           "offset %zu): not a PCD header", path, PCD_MAX_HEADER, line + 1,
                           (size_t)(s - base));
        line++;
        const char *e = pc__line_end(s, hend);
        if (e == hend && hend < base + size)
            return sd_errf(err, SD_ELIMIT, "%s: header line %d (offset %zu) runs past %u bytes: "
                           "not a PCD header", path, line, (size_t)(s - base), PCD_MAX_HEADER);
        const char *next = e < hend ? e + 1 : e;
        const char *p = s;
        tok kw;
        s = next;
        if (!next_tok(&p, e, &kw) || kw.s[0] == '#') continue;
        if (tok_is(&kw, "VERSION")) {
            if (!(rc = seen(path, "VERSION", &h->ln_version, line, err)))
                rc = header_version(path, h, line, p, e, err);
        } else if (tok_is(&kw, "FIELDS") || tok_is(&kw, "COLUMNS")) {
            if (!(rc = seen(path, "FIELDS", &h->ln_fields, line, err)))
                rc = header_fields(path, h, line, p, e, err);
        } else if (tok_is(&kw, "SIZE")) {
            if (!(rc = seen(path, "SIZE", &h->ln_size, line, err)))
                rc = header_u32_list(path, "SIZE", line, p, e, &h->size, &h->n_size, err);
        } else if (tok_is(&kw, "TYPE")) {
            if (!(rc = seen(path, "TYPE", &h->ln_type, line, err)))
                rc = header_type(path, h, line, p, e, err);
        } else if (tok_is(&kw, "COUNT")) {
            if (!(rc = seen(path, "COUNT", &h->ln_count, line, err)))
                rc = header_u32_list(path, "COUNT", line, p, e, &h->count, &h->n_count, err);
        } else if (tok_is(&kw, "WIDTH")) {
            if (!(rc = seen(path, "WIDTH", &h->ln_width, line, err)))
                rc = header_u64(path, "WIDTH", line, p, e, &h->width, err);
        } else if (tok_is(&kw, "HEIGHT")) {
            if (!(rc = seen(path, "HEIGHT", &h->ln_height, line, err)))
                rc = header_u64(path, "HEIGHT", line, p, e, &h->height, err);
        } else if (tok_is(&kw, "POINTS")) {
            if (!(rc = seen(path, "POINTS", &h->ln_points, line, err)))
                rc = header_u64(path, "POINTS", line, p, e, &h->points, err);
        } else if (tok_is(&kw, "VIEWPOINT")) {
            /* The sensor pose (translation, then a rotation quaternion); the cloud stays in
             * the file's frame, and prep orients normals towards the translation. */
            if (!(rc = seen(path, "VIEWPOINT", &h->ln_viewpoint, line, err)))
                rc = header_viewpoint(path, h, line, p, e, err);
        } else if (tok_is(&kw, "DATA")) {
            if (!(rc = header_data(path, h, line, p, e, err))) {
                h->ln_data = line;
                h->data_off = (uint64_t)(next - base);
            }
        } else {
            char buf[32];
            rc = sd_errf(err, SD_EFORMAT, "%s: unknown PCD header keyword '%s' at line %d "
                         "(offset %zu)", path, printable(&kw, buf, sizeof buf), line,
                         (size_t)(kw.s - base));
        }
        if (rc) return rc;
    }
    return 0;
}

/* Picks the role of field f from its name; fields whose shape does not fit a role are skipped. */
static int role_of(const pcd_field *f)
{
    static const struct { const char *name; int role; } names[] = {
        {"x", R_X}, {"X", R_X}, {"y", R_Y}, {"Y", R_Y}, {"z", R_Z}, {"Z", R_Z},
        {"rgb", R_PACKED_RGB}, {"rgba", R_PACKED_RGB},
        {"intensity", R_INTENSITY}, {"Intensity", R_INTENSITY},
        {"normal_x", R_NX}, {"normal_y", R_NY}, {"normal_z", R_NZ},
        {"classification", R_CLASS}, {"Classification", R_CLASS},
        {"red", R_RED}, {"Red", R_RED}, {"green", R_GREEN}, {"Green", R_GREEN},
        {"blue", R_BLUE}, {"Blue", R_BLUE},
    };
    if (f->count != 1) return R_SKIP;
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        if (strcmp(f->name, names[i].name) != 0) continue;
        if (names[i].role == R_PACKED_RGB && f->size != 4) return R_SKIP;
        return names[i].role;
    }
    return R_SKIP;
}

/* Checks the parsed header lines against each other and lays out the fields. Returns 0 or a
 * negative code naming the header lines involved. Sets raw->attrs. */
static int check_header(const char *path, pcd_header *h, pc_raw *raw, sd_err *err)
{
    if (!h->ln_fields || !h->ln_size || !h->ln_type)
        return sd_errf(err, SD_EFORMAT, "%s: the header (up to DATA at line %d) lacks %s", path,
                       h->ln_data, !h->ln_fields ? "FIELDS" : !h->ln_size ? "SIZE" : "TYPE");
    struct { const char *kw; size_t n; int ln; } lists[] = {
        {"SIZE", h->n_size, h->ln_size}, {"TYPE", h->n_type, h->ln_type},
        {"COUNT", h->ln_count ? h->n_count : h->nf, h->ln_count},
    };
    for (size_t i = 0; i < 3; i++)
        if (lists[i].n != h->nf)
            return sd_errf(err, SD_EFORMAT, "%s: %s at line %d has %zu values but FIELDS at line "
                           "%d names %zu fields", path, lists[i].kw, lists[i].ln, lists[i].n,
                           h->ln_fields, h->nf);
    uint64_t off = 0, values = 0;
    for (size_t i = 0; i < h->nf; i++) {
        pcd_field *f = &h->f[i];
        f->size = h->size[i];
        f->type = h->type[i];
        f->count = h->ln_count ? h->count[i] : 1;
        int ok = f->type == 'F' ? (f->size == 4 || f->size == 8)
                                : (f->size == 1 || f->size == 2 || f->size == 4 || f->size == 8);
        if (!ok)
            return sd_errf(err, SD_EFORMAT, "%s: field '%s' has SIZE %u (line %d) that does not "
                           "fit its TYPE %c (line %d): F takes 4 or 8, I and U 1, 2, 4 or 8",
                           path, f->name, f->size, h->ln_size, f->type, h->ln_type);
        if (f->count == 0 || f->count > PCD_MAX_COUNT)
            return sd_errf(err, SD_EFORMAT, "%s: field '%s' has COUNT %u at line %d (1 to %u "
                           "allowed)", path, f->name, f->count, h->ln_count, PCD_MAX_COUNT);
        f->off = off;
        off += (uint64_t)f->size * f->count;
        values += f->count;
        if (off > PCD_MAX_POINT_SIZE)
            return sd_errf(err, SD_ELIMIT, "%s: the fields of line %d add up to more than %u "
                           "bytes per point", path, h->ln_fields, PCD_MAX_POINT_SIZE);
    }
    h->point_size = off;
    h->values = values;

    /* WIDTH x HEIGHT must equal POINTS; a missing one follows from the others. */
    if (!h->ln_height) h->height = 1;
    if (!h->ln_width && !h->ln_points)
        return sd_errf(err, SD_EFORMAT, "%s: the header (up to DATA at line %d) has neither "
                       "WIDTH nor POINTS", path, h->ln_data);
    if (!h->ln_width) {
        h->width = h->points;
        h->height = 1;
    }
    if (h->width != 0 && h->height > UINT64_MAX / h->width)
        return sd_errf(err, SD_EFORMAT, "%s: WIDTH %llu (line %d) times HEIGHT %llu (line %d) "
                       "overflows", path, (unsigned long long)h->width, h->ln_width,
                       (unsigned long long)h->height, h->ln_height);
    if (!h->ln_points) h->points = h->width * h->height;
    if (h->width * h->height != h->points)
        return sd_errf(err, SD_EFORMAT, "%s: WIDTH %llu (line %d) times HEIGHT %llu (line %d) "
                       "is not POINTS %llu (line %d)", path, (unsigned long long)h->width,
                       h->ln_width, (unsigned long long)h->height, h->ln_height,
                       (unsigned long long)h->points, h->ln_points);

    /* Roles: the first field of each role wins; normals and split colours need all three. */
    int have[R_BLUE + 1] = {0};
    for (size_t i = 0; i < h->nf; i++) {
        int r = role_of(&h->f[i]);
        if (r != R_SKIP && have[r]) r = R_SKIP;
        h->f[i].role = r;
        if (r != R_SKIP) have[r] = 1;
    }
    if (!have[R_X] || !have[R_Y] || !have[R_Z]) {
        for (size_t i = 0; i < h->nf; i++) {
            const char *n = h->f[i].name;
            if ((!strcmp(n, "x") || !strcmp(n, "y") || !strcmp(n, "z")) && h->f[i].count != 1)
                return sd_errf(err, SD_EFORMAT, "%s: field '%s' has COUNT %u at line %d; a "
                               "coordinate needs 1", path, n, h->f[i].count, h->ln_count);
        }
        return sd_errf(err, SD_EFORMAT, "%s: FIELDS at line %d has no x, y and z", path,
                       h->ln_fields);
    }
    int normals = have[R_NX] && have[R_NY] && have[R_NZ];
    h->sep_rgb = !have[R_PACKED_RGB] && have[R_RED] && have[R_GREEN] && have[R_BLUE];
    h->n_used = 0;
    for (size_t i = 0; i < h->nf; i++) {
        int r = h->f[i].role;
        if ((r == R_NX || r == R_NY || r == R_NZ) && !normals) r = R_SKIP;
        if ((r == R_RED || r == R_GREEN || r == R_BLUE) && !h->sep_rgb) r = R_SKIP;
        h->f[i].role = r;
        if (r != R_SKIP) h->used[h->n_used++] = (int)i; /* at most one field per role */
    }
    raw->attrs = 0;
    if (have[R_PACKED_RGB] || h->sep_rgb) raw->attrs |= PC_ATTR_RGB;
    if (normals) raw->attrs |= PC_ATTR_NORMAL;
    if (have[R_INTENSITY]) raw->attrs |= PC_ATTR_INTENSITY;
    if (have[R_CLASS]) raw->attrs |= PC_ATTR_CLASS;
    return 0;
}

/* ---- points ---- */

/* Converts n values of the given PCD type and size, stride bytes apart from p (any
 * alignment), to doubles in out. One loop per type keeps the switch out of the inner loop. */
static void to_double(const uint8_t *p, size_t stride, char type, uint32_t size, size_t n,
                      double *out)
{
#define PCD_CONVERT(T)                                   \
    for (size_t i = 0; i < n; i++) {                     \
        T v;                                             \
        memcpy(&v, p + i * stride, sizeof v);            \
        out[i] = (double)v;                              \
    }                                                    \
    return
    switch (type == 'F' ? 10 + size : type == 'I' ? 20 + size : 30 + size) {
    case 14: PCD_CONVERT(float);
    case 18: PCD_CONVERT(double);
    case 21: PCD_CONVERT(int8_t);
    case 22: PCD_CONVERT(int16_t);
    case 24: PCD_CONVERT(int32_t);
    case 28: PCD_CONVERT(int64_t);
    case 31: PCD_CONVERT(uint8_t);
    case 32: PCD_CONVERT(uint16_t);
    case 34: PCD_CONVERT(uint32_t);
    default: PCD_CONVERT(uint64_t);
    }
#undef PCD_CONVERT
}

static uint16_t clamp_u16(double v)
{
    if (!(v > 0)) return 0; /* also NaN */
    return v >= 65535 ? 65535 : (uint16_t)(v + 0.5);
}

/* State shared by the decoding loops: where each used field's first value lives and how far
 * apart its values are, and the split colours kept at 16 bits until their maximum is known. */
typedef struct pcd_reader {
    const pcd_header *h;
    const uint8_t *base[16]; /* per used field: address of the first point's value */
    size_t stride[16];       /* per used field: bytes from one point's value to the next */
    uint16_t *col16;         /* 3 per point, when h->sep_rgb */
    uint32_t col_max;
    void *scratch;           /* the body reader's buffer, kept here so that pc_read_pcd frees
                              * it even when a SIGBUS ends the parse mid-way (pc__guarded) */
} pcd_reader;

#define PCD_BLOCK 2048 /* points converted at a time: the double buffer stays in L1 */

/* Decodes points [0, n) of the layout in rd into raw at indices raw->n .. raw->n + n - 1 and
 * adds n to raw->n. raw has room (pc_raw_reserve). Field by field, in blocks. */
static void decode_points(pcd_reader *rd, size_t n, pc_raw *raw)
{
    const pcd_header *h = rd->h;
    double tmp[PCD_BLOCK];
    for (size_t b0 = 0; b0 < n; b0 += PCD_BLOCK) {
        size_t m = n - b0 < PCD_BLOCK ? n - b0 : PCD_BLOCK, at = raw->n + b0;
        for (int u = 0; u < h->n_used; u++) {
            const pcd_field *f = &h->f[h->used[u]];
            const uint8_t *p = rd->base[u] + b0 * rd->stride[u];
            if (f->role == R_PACKED_RGB) { /* PCL: B, G, R, A from the low byte */
                for (size_t i = 0; i < m; i++) {
                    const uint8_t *q = p + i * rd->stride[u];
                    uint8_t *c = raw->rgba + 4 * (at + i);
                    c[0] = q[2];
                    c[1] = q[1];
                    c[2] = q[0];
                    c[3] = 255; /* opaque: cloud.h keeps alpha 255 */
                }
                continue;
            }
            to_double(p, rd->stride[u], f->type, f->size, m, tmp);
            switch (f->role) {
            case R_X: case R_Y: case R_Z: {
                double *d = raw->xyz + 3 * at + (f->role - R_X);
                for (size_t i = 0; i < m; i++) d[3 * i] = tmp[i];
                break;
            }
            case R_NX: case R_NY: case R_NZ: {
                float *d = raw->normal + 3 * at + (f->role - R_NX);
                for (size_t i = 0; i < m; i++) d[3 * i] = (float)tmp[i];
                break;
            }
            case R_INTENSITY:
                for (size_t i = 0; i < m; i++) raw->intensity[at + i] = (float)tmp[i];
                break;
            case R_CLASS:
                for (size_t i = 0; i < m; i++) {
                    double v = tmp[i];
                    raw->cls[at + i] = !(v > 0) ? 0 : v >= 255 ? 255 : (uint8_t)v;
                }
                break;
            case R_RED: case R_GREEN: case R_BLUE: {
                uint16_t *d = rd->col16 + 3 * at + (f->role - R_RED);
                for (size_t i = 0; i < m; i++) {
                    d[3 * i] = clamp_u16(tmp[i]);
                    if (d[3 * i] > rd->col_max) rd->col_max = d[3 * i];
                }
                break;
            }
            default: break;
            }
        }
    }
    if (raw->normal) { /* unit length as cloud.h promises; an unusable normal becomes 0 */
        for (size_t i = raw->n; i < raw->n + n; i++) {
            float *v = raw->normal + 3 * i;
            double l = sqrt((double)v[0] * v[0] + (double)v[1] * v[1] + (double)v[2] * v[2]);
            for (int k = 0; k < 3; k++) v[k] = (isfinite(l) && l > 0) ? (float)(v[k] / l) : 0.0f;
        }
    }
    raw->n += n;
}

/* Turns the 16-bit split colours into raw->rgba: as they are when all fit in 8 bits, else
 * scaled by 255/65535 (autzen-utm.pcd stores 16-bit colours). */
static void finish_colours(pcd_reader *rd, pc_raw *raw)
{
    if (!rd->col16) return;
    int wide = rd->col_max > 255;
    for (size_t i = 0; i < raw->n; i++) {
        for (int k = 0; k < 3; k++) {
            uint32_t v = rd->col16[3 * i + k];
            raw->rgba[4 * i + k] = (uint8_t)(wide ? (v + 128) / 257 : v);
        }
        raw->rgba[4 * i + 3] = 255;
    }
}

/* Reads the binary (array of structures) body at data[h->data_off..); the caller has checked
 * that h->points records fit in the file. */
static void read_binary(const pcd_header *h, const uint8_t *data, pcd_reader *rd, pc_raw *raw)
{
    for (int u = 0; u < h->n_used; u++) {
        rd->base[u] = data + h->data_off + h->f[h->used[u]].off;
        rd->stride[u] = (size_t)h->point_size;
    }
    decode_points(rd, (size_t)h->points, raw);
}

/* Reads and checks the two sizes that open a binary_compressed body, before anything is
 * allocated: the compressed size must fit in the file, the uncompressed size must be POINTS
 * times the point size and within what LZF can make of the compressed bytes. */
static int compressed_sizes(const char *path, const pcd_header *h, const uint8_t *data,
                            size_t size, uint32_t *csize, uint32_t *usize, sd_err *err)
{
    uint64_t off = h->data_off, left = size - off;
    if (left < 8)
        return sd_errf(err, SD_ETRUNC, "%s: the compressed sizes at offset %llu are cut off "
                       "(%llu bytes left)", path, (unsigned long long)off,
                       (unsigned long long)left);
    memcpy(csize, data + off, 4);
    memcpy(usize, data + off + 4, 4);
    if (*csize > left - 8)
        return sd_errf(err, SD_ETRUNC, "%s: compressed size %u at offset %llu exceeds the %llu "
                       "bytes left in the file", path, *csize, (unsigned long long)off,
                       (unsigned long long)(left - 8));
    if (h->points > UINT32_MAX / h->point_size || h->points * h->point_size != *usize)
        return sd_errf(err, SD_EFORMAT, "%s: uncompressed size %u at offset %llu is not POINTS "
                       "%llu (line %d) times the point size %llu", path, *usize,
                       (unsigned long long)off + 4, (unsigned long long)h->points, h->ln_points,
                       (unsigned long long)h->point_size);
    if ((uint64_t)*usize > (uint64_t)*csize * PC_LZF_MAX_RATIO)
        return sd_errf(err, SD_EFORMAT, "%s: uncompressed size %u at offset %llu is more than "
                       "LZF can produce from the %u compressed bytes", path, *usize,
                       (unsigned long long)off + 4, *csize);
    return 0;
}

/* Decompresses the binary_compressed body (sizes checked by compressed_sizes) and decodes its
 * structure-of-arrays values. Returns 0 or the decompressor's error. */
static int read_compressed(const char *path, const pcd_header *h, const uint8_t *data,
                           uint32_t csize, uint32_t usize, pcd_reader *rd, pc_raw *raw,
                           sd_err *err)
{
    uint8_t *buf = malloc(usize ? usize : 1);
    if (!buf)
        return sd_errf(err, SD_ENOMEM, "%s: out of memory for %u uncompressed bytes", path,
                       usize);
    rd->scratch = buf;
    int rc = pc_lzf_decompress(data + h->data_off + 8, csize, buf, usize, path,
                               h->data_off + 8, err);
    if (rc == 0) {
        for (int u = 0; u < h->n_used; u++) {
            const pcd_field *f = &h->f[h->used[u]];
            /* Each field's block starts after the blocks of the fields before it. */
            rd->base[u] = buf + f->off * h->points;
            rd->stride[u] = (size_t)f->size * f->count;
        }
        decode_points(rd, (size_t)h->points, raw);
    }
    rd->scratch = NULL;
    free(buf);
    return rc;
}

/* Parses one ascii token of field f into its binary form at out. For a packed colour stored
 * as F, an integer token is the 32-bit pattern (what PCL writes), a decimal the float's bits.
 * Returns the end of the token or NULL when it is not a number of that type. */
static const char *ascii_value(const pcd_field *f, const char *s, const char *e, uint8_t *out)
{
    double v;
    const char *q = pc__parse_num(s, e, &v);
    if (!q || (q < e && !pc__is_space((unsigned char)*q))) return NULL;
    int integral = 1;
    for (const char *c = s; c < q; c++)
        if (!((*c >= '0' && *c <= '9') || *c == '-' || *c == '+')) integral = 0;
    if (f->role == R_PACKED_RGB && f->type == 'F' && integral) {
        if (!(v >= 0 && v <= UINT32_MAX)) return NULL;
        uint32_t bits = (uint32_t)v;
        memcpy(out, &bits, 4);
        return q;
    }
    if (f->type == 'F') {
        if (f->size == 4) { float x = (float)v; memcpy(out, &x, 4); }
        else memcpy(out, &v, 8);
        return q;
    }
    if (!integral) return NULL;
    /* Integers up to 2^53 are exact in the double; beyond, 8-byte fields lose low bits. */
    double lo = f->type == 'U' ? 0 : -ldexp(1, (int)f->size * 8 - 1);
    double hi = f->type == 'U' ? ldexp(1, (int)f->size * 8) - 1 : ldexp(1, (int)f->size * 8 - 1) - 1;
    if (v < lo || v > hi) return NULL;
    if (f->type == 'U') {
        uint64_t x = v >= 18446744073709551615.0 ? UINT64_MAX : (uint64_t)v;
        memcpy(out, &x, f->size); /* little-endian: the low bytes */
    } else {
        int64_t x = v >= 9223372036854775807.0 ? INT64_MAX : (int64_t)v;
        memcpy(out, &x, f->size);
    }
    return q;
}

/* Where reading an ascii body stands: the next line's offset and number, the points read. */
typedef struct ascii_pos {
    uint64_t off;
    int line;
    uint64_t done;
} ascii_pos;

/* Reads want points of the ascii body from at (one point per line, the values of all fields in
 * order) into raw, and moves at past them. rd->scratch holds the record buffer. */
static int read_ascii(const char *path, const pcd_header *h, const uint8_t *data, size_t size,
                      pcd_reader *rd, pc_raw *raw, ascii_pos *at, size_t want, sd_err *err)
{
    uint8_t *rec = rd->scratch;
    if (!rec) {
        rec = malloc((size_t)h->point_size);
        if (!rec) return sd_errf(err, SD_ENOMEM, "%s: out of memory", path);
        rd->scratch = rec;
    }
    for (int u = 0; u < h->n_used; u++) {
        rd->base[u] = rec + h->f[h->used[u]].off;
        rd->stride[u] = 0;
    }
    const char *s = (const char *)data + at->off, *end = (const char *)data + size;
    int line = at->line;
    int rc = 0;
    size_t n0 = raw->n;
    while (raw->n - n0 < want) {
        if (s >= end) {
            rc = sd_errf(err, SD_ETRUNC, "%s: the ascii data ends at line %d (offset %zu) after "
                         "%llu of the %llu points the header declares", path, line, size,
                         (unsigned long long)(at->done + (raw->n - n0)),
                         (unsigned long long)h->points);
            break;
        }
        line++;
        const char *e = pc__line_end(s, end), *p = s;
        s = e < end ? e + 1 : e;
        while (p < e && pc__is_space((unsigned char)*p)) p++;
        if (p == e) continue; /* blank line */
        uint64_t k = 0;
        for (size_t i = 0; i < h->nf && !rc; i++) {
            const pcd_field *f = &h->f[i];
            for (uint32_t c = 0; c < f->count; c++, k++) {
                while (p < e && pc__is_space((unsigned char)*p)) p++;
                if (p == e) { /* on the file's last, unterminated line: a cut-off file */
                    rc = sd_errf(err, e == end ? SD_ETRUNC : SD_EFORMAT, "%s: line %d has %llu "
                                 "values, the fields need %llu%s", path, line,
                                 (unsigned long long)k, (unsigned long long)h->values,
                                 e == end ? " (the file ends there)" : "");
                    break;
                }
                const char *q = ascii_value(f, p, e, rec + f->off + (size_t)c * f->size);
                if (!q) {
                    rc = sd_errf(err, SD_EFORMAT, "%s: value %llu at line %d (offset %zu) is not "
                                 "a valid %c%u number for field '%s'", path,
                                 (unsigned long long)k + 1, line, (size_t)(p - (const char *)data),
                                 f->type, f->size * 8, f->name);
                    break;
                }
                p = q;
            }
        }
        if (rc) break;
        while (p < e && pc__is_space((unsigned char)*p)) p++;
        if (p < e) {
            rc = sd_errf(err, SD_EFORMAT, "%s: line %d has more than the %llu values the fields "
                         "need", path, line, (unsigned long long)h->values);
            break;
        }
        decode_points(rd, 1, raw);
    }
    at->off = (uint64_t)(s - (const char *)data);
    at->line = line;
    at->done += raw->n - n0;
    return rc;
}

/* What the guarded part of pc_read_pcd works on (pc__guarded: every allocation of the parse is
 * reachable from h and rd). */
typedef struct pcd_job {
    const char *path;
    const pc__file *f;
    pcd_header *h;
    pcd_reader *rd;
    pc_raw *raw;
    sd_err *err;
} pcd_job;

/* pcd_head: the header of the file mapped in j->f, checked, and the body's size checked
 * against it (csize/usize: a compressed body's sizes). raw gets the attributes. */
static int pcd_head(pcd_job *j, uint32_t *csize_out, uint32_t *usize_out)
{
    const char *path = j->path;
    const pc__file file = *j->f;
    pcd_header *h = j->h;
    pc_raw *raw = j->raw;
    sd_err *err = j->err;
    int rc = 0;
    if (file.size == 0)
        return sd_errf(err, SD_ETRUNC, "%s: the file is empty (no header at offset 0)", path);
    rc = parse_header_lines(path, file.data, file.size, h, err);
    if (!rc) rc = check_header(path, h, raw, err);
    if (rc) return rc;
    if (h->points == 0)
        return sd_errf(err, SD_EEMPTY, "%s: the header declares 0 points (line %d)", path,
                       h->ln_points ? h->ln_points : h->ln_width);
    int ascii = !strcmp(h->data, "ascii"), compressed = !strcmp(h->data, "binary_compressed");
    uint64_t left = file.size - h->data_off;
    uint32_t csize = 0, usize = 0;
    /* An ascii point needs at least one character per value plus a separator each. */
    if (ascii && h->points > (left + 1) / (2 * h->values))
        rc = sd_errf(err, SD_ETRUNC, "%s: the header declares %llu points of %llu values, more "
                     "than the %llu bytes after the header (offset %llu, line %d) can hold",
                     path, (unsigned long long)h->points, (unsigned long long)h->values,
                     (unsigned long long)left, (unsigned long long)h->data_off, h->ln_data + 1);
    else if (!ascii && !compressed && h->points > left / h->point_size)
        rc = sd_errf(err, SD_ETRUNC, "%s: the header declares %llu points of %llu bytes, but "
                     "only %llu bytes follow the header at offset %llu", path,
                     (unsigned long long)h->points, (unsigned long long)h->point_size,
                     (unsigned long long)left, (unsigned long long)h->data_off);
    else if (compressed)
        rc = compressed_sizes(path, h, file.data, file.size, &csize, &usize, err);
    *csize_out = csize;
    *usize_out = usize;
    return rc;
}

/* pcd_describe: the format name and the sensor's pose, when the file gives one. */
static void pcd_describe(const pcd_header *h, pc_raw *raw)
{
    snprintf(raw->format, sizeof raw->format, "PCD%s%s %s", h->version[0] ? " " : "", h->version,
             h->data);
    /* PCL writes the identity pose when it knows no sensor (its default): only another pose
     * says where the sensor was. */
    static const double identity[7] = {0, 0, 0, 1, 0, 0, 0};
    int posed = 0;
    for (int k = 0; k < 7; k++) posed |= h->viewpoint[k] != identity[k];
    if (h->ln_viewpoint && posed) {
        raw->has_viewpoint = 1;
        memcpy(raw->viewpoint, h->viewpoint, sizeof raw->viewpoint);
        memcpy(raw->viewpoint_q, h->viewpoint + 3, sizeof raw->viewpoint_q);
    }
}

/* pcd_parse: the header and body of the file mapped in j->f, into j->raw. */
static int pcd_parse(void *arg)
{
    pcd_job *j = arg;
    const char *path = j->path;
    const pc__file file = *j->f;
    pcd_header *h = j->h;
    pcd_reader *rd = j->rd;
    pc_raw *raw = j->raw;
    sd_err *err = j->err;
    uint32_t csize = 0, usize = 0;
    int rc = pcd_head(j, &csize, &usize);
    if (rc) goto out;
    int ascii = !strcmp(h->data, "ascii"), compressed = !strcmp(h->data, "binary_compressed");
    /* Bounded by the file size (ascii, binary) or by the checked uncompressed size. */
    rc = pc_raw_reserve(raw, (size_t)h->points, err);
    if (rc) goto out;
    if (h->sep_rgb) {
        rd->col16 = malloc((size_t)h->points * 3 * sizeof *rd->col16);
        if (!rd->col16) {
            rc = sd_errf(err, SD_ENOMEM, "%s: out of memory for %llu colours", path,
                         (unsigned long long)h->points);
            goto out;
        }
    }
    if (ascii) {
        ascii_pos at = {h->data_off, h->ln_data, 0};
        rc = read_ascii(path, h, file.data, file.size, rd, raw, &at, (size_t)h->points, err);
    } else if (compressed) {
        rc = read_compressed(path, h, file.data, csize, usize, rd, raw, err);
    } else {
        read_binary(h, file.data, rd, raw);
    }
    if (rc) goto out;
    finish_colours(rd, raw);
    pcd_describe(h, raw);
out:
    return rc;
}

int pc_read_pcd(const char *path, pc_raw *raw, sd_err *err)
{
    pc__file file;
    int rc = pc__file_open(path, &file, err);
    if (rc) return rc;
    pcd_header h = {0};
    pcd_reader rd = {.h = &h};
    pcd_job j = {.path = path, .f = &file, .h = &h, .rd = &rd, .raw = raw, .err = err};
    rc = pc__guarded(&file, path, pcd_parse, &j, err);
    free(rd.scratch);
    free(rd.col16);
    header_free(&h);
    pc__file_close(&file);
    return rc;
}

/* ---- the stream (pcd_stream.h) ---- */

enum { PCD_WINDOW = 1 << 16 };

struct pc_pcd_stream {
    char path[4096];
    pc__file f;
    pcd_header h;
    pcd_reader rd;
    pc_raw win;              /* the points of the last window (attributes as the file's) */
    uint8_t *ubuf;           /* binary_compressed: the decompressed body */
    int ascii, compressed;
    uint64_t next;           /* points read this pass */
    ascii_pos at;            /* ascii: where the next window starts */
    int final;               /* a whole pass read: the split colours' scale is known */
    sd_err *err;             /* the current call's */
    uint32_t csize, usize;
};

static int stream_head(void *arg)
{
    pc_pcd_stream *s = arg;
    pcd_job j = {.path = s->path, .f = &s->f, .h = &s->h, .rd = &s->rd, .raw = &s->win,
                 .err = s->err};
    int rc = pcd_head(&j, &s->csize, &s->usize);
    if (rc) return rc;
    pcd_describe(&s->h, &s->win);
    s->ascii = !strcmp(s->h.data, "ascii");
    s->compressed = !strcmp(s->h.data, "binary_compressed");
    if (!s->compressed) return 0;
    s->ubuf = malloc(s->usize ? s->usize : 1);
    if (!s->ubuf)
        return sd_errf(s->err, SD_ENOMEM, "%s: out of memory for %u uncompressed bytes", s->path,
                       s->usize);
    return pc_lzf_decompress(s->f.data + s->h.data_off + 8, s->csize, s->ubuf, s->usize,
                             s->path, s->h.data_off + 8, s->err);
}

int pc_pcd_stream_open(const char *path, pc_pcd_stream **out, sd_err *err)
{
    *out = NULL;
    const char *slash = strrchr(path, '/'), *dot = strrchr(slash ? slash : path, '.');
    if (!dot || strcasecmp(dot + 1, "pcd")) return 0;
    pc_pcd_stream *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    snprintf(s->path, sizeof s->path, "%s", path);
    s->rd.h = &s->h;
    s->err = err;
    int rc = pc__file_open(path, &s->f, err);
    if (rc == 0) rc = pc__guarded(&s->f, path, stream_head, s, err);
    if (rc == 0) rc = pc_raw_reserve(&s->win, PCD_WINDOW, err);
    if (rc == 0 && s->h.sep_rgb &&
        !(s->rd.col16 = malloc((size_t)PCD_WINDOW * 3 * sizeof *s->rd.col16)))
        rc = sd_errf(err, SD_ENOMEM, "%s: out of memory", path);
    if (rc != 0) {
        pc_pcd_stream_close(s);
        return rc;
    }
    pc_pcd_stream_rewind(s);
    *out = s;
    return 1;
}

void pc_pcd_stream_close(pc_pcd_stream *s)
{
    if (!s) return;
    free(s->rd.scratch);
    free(s->rd.col16);
    free(s->ubuf);
    header_free(&s->h);
    pc_raw_free(&s->win);
    pc__file_close(&s->f);
    free(s);
}

void pc_pcd_stream_rewind(pc_pcd_stream *s)
{
    s->next = 0;
    s->at = (ascii_pos){s->h.data_off, s->h.ln_data, 0};
}

typedef struct window_job {
    pc_pcd_stream *s;
    size_t m;
} window_job;

/* The next m points into s->win, from the mapping (binary, ascii) or the decompressed body. */
static int stream_window(void *arg)
{
    window_job *w = arg;
    pc_pcd_stream *s = w->s;
    const pcd_header *h = &s->h;
    pcd_reader *rd = &s->rd;
    s->win.n = 0;
    if (s->ascii)
        return read_ascii(s->path, h, s->f.data, s->f.size, rd, &s->win, &s->at, w->m, s->err);
    for (int u = 0; u < h->n_used; u++) {
        const pcd_field *f = &h->f[h->used[u]];
        if (s->compressed) { /* each field's block, then this window's values in it */
            rd->stride[u] = (size_t)f->size * f->count;
            rd->base[u] = s->ubuf + f->off * h->points + s->next * rd->stride[u];
        } else {
            rd->stride[u] = (size_t)h->point_size;
            rd->base[u] = s->f.data + h->data_off + s->next * h->point_size + f->off;
        }
    }
    decode_points(rd, w->m, &s->win);
    return 0;
}

int64_t pc_pcd_stream_next(pc_pcd_stream *s, double *xyz, uint8_t *rgba, size_t max,
                           sd_err *err)
{
    const pcd_header *h = &s->h;
    if (rgba && h->sep_rgb && !s->final)
        return sd_errf(err, SD_EINVAL, "%s: colours asked before a whole pass", s->path);
    uint64_t left = h->points - s->next;
    size_t m = left < max ? (size_t)left : max;
    if (m > PCD_WINDOW) m = PCD_WINDOW;
    if (m == 0) {
        s->final = 1;
        return 0;
    }
    s->err = err;
    window_job w = {s, m};
    int rc = pc__guarded(&s->f, s->path, stream_window, &w, err);
    if (rc) return rc;
    memcpy(xyz, s->win.xyz, 3 * m * sizeof *xyz);
    if (rgba) {
        int wide = s->rd.col_max > 255;
        for (size_t i = 0; i < m; i++) {
            uint8_t *c = rgba + 4 * i;
            if (h->sep_rgb) {
                for (int k = 0; k < 3; k++) {
                    uint32_t v = s->rd.col16[3 * i + k];
                    c[k] = (uint8_t)(wide ? (v + 128) / 257 : v);
                }
                c[3] = 255;
            } else if (s->win.attrs & PC_ATTR_RGB) {
                memcpy(c, s->win.rgba + 4 * i, 4);
            } else {
                memset(c, 255, 4);
            }
        }
    }
    s->next += m;
    if (s->next == h->points) s->final = 1;
    /* give back the pages of the mapping this pass has read */
    uint64_t done = s->compressed ? 0
                    : s->ascii    ? s->at.off
                                  : h->data_off + s->next * h->point_size;
    long pg = sysconf(_SC_PAGESIZE);
    if (pg > 0 && s->f.map && done > (uint64_t)pg)
        (void)madvise(s->f.map, (size_t)done & ~((size_t)pg - 1), MADV_DONTNEED);
    return (int64_t)m;
}

uint64_t pc_pcd_stream_count(const pc_pcd_stream *s)
{
    return s->h.points;
}

const char *pc_pcd_stream_format(const pc_pcd_stream *s)
{
    return s->win.format;
}

int pc_pcd_stream_has_rgb(const pc_pcd_stream *s)
{
    return (s->win.attrs & PC_ATTR_RGB) != 0;
}

int pc_pcd_stream_viewpoint(const pc_pcd_stream *s, double xyz[3], double q[4])
{
    if (!s->win.has_viewpoint) return 0;
    memcpy(xyz, s->win.viewpoint, 3 * sizeof *xyz);
    memcpy(q, s->win.viewpoint_q, 4 * sizeof *q);
    return 1;
}
