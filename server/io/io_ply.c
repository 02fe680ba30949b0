/* io_ply.c — PLY reader: ascii, binary_little_endian and binary_big_endian, any property order
 * and type, with colours, normals, radius, intensity and one scalar property taken from the
 * vertex element and every other element (faces, range grids, lists) skipped with bounds checks.
 *
 * The whole file is mapped once. The header is parsed into ply_header; each element before the
 * vertex element is walked (binary: fixed records by arithmetic, list records one by one;
 * ascii: one record per line), then the vertex element is decoded through a slot table that
 * maps each property to its destination array, and the elements after it are walked too, so a
 * file cut short anywhere is reported. Nothing is reserved before the file is known to hold it. */
#include "cloud.h"
#include "io_text.h"
#include "ply_stream.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PLY_MAX_HEADER (64 * 1024) /* a header longer than this is garbage, not a header */
#define PLY_MAX_ELEMS  64
#define PLY_MAX_PROPS  512         /* over all elements */
#define PLY_NAME_LEN   48

enum { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 };
static const uint8_t type_size[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};

enum { FMT_ASCII, FMT_LE, FMT_BE };
static const char *const fmt_name[] = {"ascii", "binary_little_endian", "binary_big_endian"};

/* Where a vertex property goes. */
enum {
    D_NONE, D_X, D_Y, D_Z, D_R, D_G, D_B, D_A, D_NX, D_NY, D_NZ, D_RADIUS, D_INTENS, D_SCALAR,
    D_COUNT
};

typedef struct ply_prop {
    char name[PLY_NAME_LEN];
    uint8_t type;       /* value type; the item type for a list */
    uint8_t count_type; /* list count type, T_NONE for a scalar property */
} ply_prop;

typedef struct ply_elem {
    char name[PLY_NAME_LEN];
    uint64_t count;
    size_t first_prop, nprop; /* range in ply_header.props */
    size_t line;              /* header line of the element declaration */
} ply_elem;

typedef struct ply_header {
    int fmt;
    char version[16];
    size_t nelem, nprop;
    size_t data_off;  /* byte offset of the first data byte */
    size_t data_line; /* line number of the first data line (ascii) */
    ply_elem elems[PLY_MAX_ELEMS];
    ply_prop props[PLY_MAX_PROPS];
} ply_header;

/* One decoded vertex property: where it lies (binary), its type and destination. */
typedef struct ply_slot {
    size_t off;     /* byte offset in a fixed-size binary record */
    uint8_t type;
    uint8_t dst;
    double cscale;  /* colour scale to 0..255 */
} ply_slot;

/* The reading state shared by the element walkers. */
typedef struct ply_ctx {
    const char *path;
    const uint8_t *data;
    size_t size;
    size_t pos;   /* byte offset of the next unread data byte */
    size_t line;  /* ascii: line number of the line starting at pos */
    int swap;     /* binary: the file's byte order differs from the host's */
    sd_err *err;
} ply_ctx;

/* ---------------------------------------------------------------- header */

static int type_from_name(const char *s)
{
    static const struct { const char *name; int type; } names[] = {
        {"char", T_I8},    {"int8", T_I8},      {"uchar", T_U8},    {"uint8", T_U8},
        {"short", T_I16},  {"int16", T_I16},    {"ushort", T_U16},  {"uint16", T_U16},
        {"int", T_I32},    {"int32", T_I32},    {"uint", T_U32},    {"uint32", T_U32},
        {"float", T_F32},  {"float32", T_F32},  {"double", T_F64},  {"float64", T_F64},
    };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (!strcmp(s, names[i].name)) return names[i].type;
    return T_NONE;
}

/* Splits line (NUL-terminated, modified) into at most max whitespace-separated tokens;
 * returns the number found (max + 1 when there are more). */
static int split(char *line, char **tok, int max)
{
    int n = 0;
    char *p = line;
    for (;;) {
        while (*p == ' ' || *p == '\t') p++;
        if (!*p) return n;
        if (n == max) return max + 1;
        tok[n++] = p;
        while (*p && *p != ' ' && *p != '\t') p++;
        if (*p) *p++ = 0;
    }
}

/* Parses a decimal element count (digits only) into *out; returns 0 or -1. */
static int parse_count(const char *s, uint64_t *out)
{
    uint64_t v = 0;
    if (!*s) return -1;
    for (; *s; s++) {
        if (*s < '0' || *s > '9') return -1;
        if (v > (UINT64_MAX - 9) / 10) return -1;
        v = v * 10 + (uint64_t)(*s - '0');
    }
    *out = v;
    return 0;
}

/* header_property: adds the property declared on header line ln (tok, nt tokens) to the last
 * element of h. Returns 0 or SD_EFORMAT/SD_ELIMIT. */
static int header_property(ply_ctx *c, ply_header *h, char **tok, int nt, size_t ln)
{
    if (h->nelem == 0)
        return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: property before any element",
                       c->path, ln);
    if (h->nprop == PLY_MAX_PROPS)
        return sd_errf(c->err, SD_ELIMIT, "%s: line %zu: more than %d properties", c->path, ln,
                       PLY_MAX_PROPS);
    ply_prop *q = &h->props[h->nprop];
    memset(q, 0, sizeof *q);
    const char *tname, *pname;
    if (nt >= 2 && !strcmp(tok[1], "list")) {
        if (nt != 5)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: line %zu: expected 'property list <count type> <item type> "
                           "<name>'", c->path, ln);
        int ct = type_from_name(tok[2]);
        if (ct == T_NONE)
            return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: unknown type '%.32s'",
                           c->path, ln, tok[2]);
        if (ct == T_F32 || ct == T_F64)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: line %zu: list count type '%.32s' is not an integer type",
                           c->path, ln, tok[2]);
        q->count_type = (uint8_t)ct;
        tname = tok[3];
        pname = tok[4];
    } else {
        if (nt != 3)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: line %zu: expected 'property <type> <name>'", c->path, ln);
        tname = tok[1];
        pname = tok[2];
    }
    int t = type_from_name(tname);
    if (t == T_NONE)
        return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: unknown type '%.32s'", c->path, ln,
                       tname);
    q->type = (uint8_t)t;
    snprintf(q->name, sizeof q->name, "%s", pname);
    h->nprop++;
    h->elems[h->nelem - 1].nprop++;
    return 0;
}

/* header_line: interprets one tokenised header line (format, element or property) at line
 * ln into h; *have_format is set by the format line. Returns 0 or a negative SD_E* code. */
static int header_line(ply_ctx *c, ply_header *h, char **tok, int nt, size_t ln, int *have_format)
{
    if (!strcmp(tok[0], "format")) {
        if (nt != 3)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: line %zu: expected 'format <encoding> 1.0'", c->path, ln);
        int f = -1;
        for (int i = 0; i < 3; i++)
            if (!strcmp(tok[1], fmt_name[i])) f = i;
        if (f < 0)
            return sd_errf(c->err, SD_EUNSUP,
                           "%s: line %zu: unknown format '%.64s' (expected ascii, "
                           "binary_little_endian or binary_big_endian)", c->path, ln, tok[1]);
        if (strcmp(tok[2], "1.0") && strcmp(tok[2], "1"))
            return sd_errf(c->err, SD_EUNSUP, "%s: line %zu: unsupported PLY version '%.16s'",
                           c->path, ln, tok[2]);
        h->fmt = f;
        snprintf(h->version, sizeof h->version, "%s", tok[2]);
        *have_format = 1;
        return 0;
    }
    if (!strcmp(tok[0], "element")) {
        if (nt != 3)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: line %zu: expected 'element <name> <count>'", c->path, ln);
        if (h->nelem == PLY_MAX_ELEMS)
            return sd_errf(c->err, SD_ELIMIT, "%s: line %zu: more than %d elements", c->path, ln,
                           PLY_MAX_ELEMS);
        ply_elem *e = &h->elems[h->nelem];
        if (parse_count(tok[2], &e->count) != 0 || e->count > ((uint64_t)1 << 48))
            return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: bad element count '%.32s'",
                           c->path, ln, tok[2]);
        snprintf(e->name, sizeof e->name, "%s", tok[1]);
        e->first_prop = h->nprop;
        e->nprop = 0;
        e->line = ln;
        h->nelem++;
        return 0;
    }
    if (!strcmp(tok[0], "property")) return header_property(c, h, tok, nt, ln);
    return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: unknown header keyword '%.32s'",
                   c->path, ln, tok[0]);
}

/* parse_header: parses the header of the file in c into h and sets c->pos/c->line to the first
 * data byte. Comment and obj_info lines are skipped whatever their length; other lines must be
 * printable and under 512 bytes. Returns 0 or SD_EFORMAT/SD_EUNSUP/SD_ETRUNC/SD_ELIMIT with
 * the line named. */
static int parse_header(ply_ctx *c, ply_header *h)
{
    const char *path = c->path;
    const char *s = (const char *)c->data, *end = s + c->size;
    const char *lim = s + (c->size < PLY_MAX_HEADER ? c->size : PLY_MAX_HEADER);
    int have_format = 0;
    if (!(c->size >= 4 && !memcmp(s, "ply\n", 4)) && !(c->size >= 5 && !memcmp(s, "ply\r\n", 5)))
        return sd_errf(c->err, SD_EFORMAT,
                       "%s: line 1 (byte offset 0): wrong magic, a PLY file starts with the line "
                       "'ply'", path);
    const char *p = s + (s[3] == '\n' ? 4 : 5);
    for (size_t ln = 2;; ln++) {
        const char *nl = memchr(p, '\n', (size_t)(lim - p));
        const char *le = nl ? nl : lim;
        if (!nl && lim < end)
            return sd_errf(c->err, SD_ELIMIT,
                           "%s: absurd header size: no end_header line within the first %d "
                           "bytes (line %zu, byte offset %zu)",
                           path, PLY_MAX_HEADER, ln, (size_t)(p - s));
        const char *te = pc__trim_cr(p, le);
        size_t len = (size_t)(te - p);
        if (!nl && !(len == 10 && !memcmp(p, "end_header", 10)))
            return sd_errf(c->err, SD_ETRUNC,
                           "%s: line %zu (byte offset %zu): the file ends inside the header, "
                           "before end_header", path, ln, (size_t)(p - s));
        const char *line = p;
        p = nl ? nl + 1 : end;
        if ((len >= 7 && !memcmp(line, "comment", 7) && (len == 7 || line[7] == ' ' ||
                                                         line[7] == '\t')) ||
            (len >= 8 && !memcmp(line, "obj_info", 8) && (len == 8 || line[8] == ' ' ||
                                                          line[8] == '\t')))
            continue;
        char buf[512];
        if (len >= sizeof buf)
            return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: header line longer than %zu bytes",
                           path, ln, sizeof buf - 1);
        for (size_t i = 0; i < len; i++) {
            unsigned char ch = (unsigned char)line[i];
            if ((ch < 0x20 && ch != '\t') || ch == 0x7f)
                return sd_errf(c->err, SD_EFORMAT,
                               "%s: line %zu (byte offset %zu): control byte 0x%02x in the header",
                               path, ln, (size_t)(line - s) + i, ch);
        }
        memcpy(buf, line, len);
        buf[len] = 0;
        char *tok[8];
        int nt = split(buf, tok, 6);
        if (nt == 0) continue; /* blank header line: tolerated */
        if (!strcmp(tok[0], "end_header")) {
            if (!have_format)
                return sd_errf(c->err, SD_EFORMAT,
                               "%s: line %zu: end_header before any format line", path, ln);
            c->pos = (size_t)(p - s);
            c->line = ln + 1;
            h->data_off = c->pos;
            h->data_line = c->line;
            return 0;
        }
        int rc = header_line(c, h, tok, nt, ln, &have_format);
        if (rc < 0) return rc;
    }
}

/* ---------------------------------------------------------------- values */

static inline __attribute__((always_inline)) double load(const uint8_t *p, int type, int swap)
{
    switch (type) {
    case T_I8: return (int8_t)p[0];
    case T_U8: return p[0];
    case T_I16:
    case T_U16: {
        uint16_t u;
        memcpy(&u, p, 2);
        if (swap) u = __builtin_bswap16(u);
        return type == T_I16 ? (double)(int16_t)u : (double)u;
    }
    case T_I32:
    case T_U32: {
        uint32_t u;
        memcpy(&u, p, 4);
        if (swap) u = __builtin_bswap32(u);
        return type == T_I32 ? (double)(int32_t)u : (double)u;
    }
    case T_F32: {
        uint32_t u;
        float f;
        memcpy(&u, p, 4);
        if (swap) u = __builtin_bswap32(u);
        memcpy(&f, &u, 4);
        return f;
    }
    default: {
        uint64_t u;
        double d;
        memcpy(&u, p, 8);
        if (swap) u = __builtin_bswap64(u);
        memcpy(&d, &u, 8);
        return d;
    }
    }
}

static inline uint8_t colour8(double v)
{
    if (!(v > 0)) return 0; /* also NaN */
    if (v >= 255) return 255;
    return (uint8_t)(v + 0.5);
}

/* A double as float without the undefined conversion of out-of-range values. */
static inline float to_f32(double v)
{
    if (v > FLT_MAX) return FLT_MAX;
    if (v < -FLT_MAX) return -FLT_MAX;
    return (float)v;
}

static inline void store(pc_raw *raw, size_t i, const ply_slot *s, double v)
{
    switch (s->dst) {
    case D_X: case D_Y: case D_Z: raw->xyz[3 * i + (size_t)(s->dst - D_X)] = v; break;
    case D_R: case D_G: case D_B: case D_A:
        raw->rgba[4 * i + (size_t)(s->dst - D_R)] = colour8(v * s->cscale);
        break;
    case D_NX: case D_NY: case D_NZ:
        raw->normal[3 * i + (size_t)(s->dst - D_NX)] = to_f32(v);
        break;
    case D_RADIUS: raw->radius[i] = to_f32(v); break;
    case D_INTENS: raw->intensity[i] = to_f32(v); break;
    case D_SCALAR: raw->scalar[i] = to_f32(v); break;
    default: break;
    }
}

/* ---------------------------------------------------------------- vertex layout */

static int name_in(const char *n, const char *const *list)
{
    for (; *list; list++)
        if (!strcmp(n, *list)) return 1;
    return 0;
}

/* plan_vertex: fills slot[k] (one per property of e) with the destination of each property,
 * sets raw->attrs and raw->scalar_name. Returns 1 when the colours have an alpha property,
 * 0 when not, or SD_EFORMAT when x, y or z is missing or is a list. */
static int plan_vertex(ply_ctx *c, const ply_header *h, const ply_elem *e, ply_slot *slot,
                       pc_raw *raw)
{
    static const char *const rn[] = {"red", "r", "diffuse_red", NULL};
    static const char *const gn[] = {"green", "g", "diffuse_green", NULL};
    static const char *const bn[] = {"blue", "b", "diffuse_blue", NULL};
    static const char *const an[] = {"alpha", "a", "diffuse_alpha", NULL};
    int have[D_COUNT] = {0};
    int scalar_rank = 99, scalar_k = -1;
    for (size_t k = 0; k < e->nprop; k++) {
        const ply_prop *q = &h->props[e->first_prop + k];
        ply_slot *s = &slot[k];
        memset(s, 0, sizeof *s);
        s->type = q->type;
        s->cscale = 1.0;
        if (q->count_type != T_NONE) {
            if (!strcmp(q->name, "x") || !strcmp(q->name, "y") || !strcmp(q->name, "z"))
                return sd_errf(c->err, SD_EFORMAT,
                               "%s: line %zu: vertex property '%s' is a list, not a coordinate",
                               c->path, e->line, q->name);
            continue;
        }
        int d = D_NONE;
        if (!strcmp(q->name, "x")) d = D_X;
        else if (!strcmp(q->name, "y")) d = D_Y;
        else if (!strcmp(q->name, "z")) d = D_Z;
        else if (name_in(q->name, rn)) d = D_R;
        else if (name_in(q->name, gn)) d = D_G;
        else if (name_in(q->name, bn)) d = D_B;
        else if (name_in(q->name, an)) d = D_A;
        else if (!strcmp(q->name, "nx")) d = D_NX;
        else if (!strcmp(q->name, "ny")) d = D_NY;
        else if (!strcmp(q->name, "nz")) d = D_NZ;
        else if (!strcmp(q->name, "radius") || !strcmp(q->name, "scale")) d = D_RADIUS;
        else if (!strcmp(q->name, "intensity")) d = D_INTENS;
        else {
            /* The scalar: quality before confidence before the first scalar_*. */
            int rank = !strcmp(q->name, "quality")           ? 0
                       : !strcmp(q->name, "confidence")      ? 1
                       : !strncmp(q->name, "scalar_", 7)     ? 2
                                                             : 99;
            if (rank < scalar_rank) {
                scalar_rank = rank;
                scalar_k = (int)k;
            }
        }
        if (d != D_NONE && have[d]) d = D_NONE; /* a repeated name: the first one wins */
        if (d != D_NONE) have[d] = 1;
        s->dst = (uint8_t)d;
        if (d >= D_R && d <= D_A) {
            if (q->type == T_U16 || q->type == T_I16) s->cscale = 255.0 / 65535.0;
            else if (q->type == T_F32 || q->type == T_F64) s->cscale = 255.0;
        }
    }
    if (scalar_k >= 0) {
        slot[scalar_k].dst = D_SCALAR;
        snprintf(raw->scalar_name, sizeof raw->scalar_name, "%s",
                 h->props[e->first_prop + (size_t)scalar_k].name);
        raw->attrs |= PC_ATTR_SCALAR;
    }
    static const char *const axis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; a++)
        if (!have[D_X + a])
            return sd_errf(c->err, SD_EFORMAT, "%s: line %zu: element vertex has no property '%s'",
                           c->path, e->line, axis[a]);
    if (have[D_R] && have[D_G] && have[D_B]) {
        raw->attrs |= PC_ATTR_RGB;
    } else {
        for (size_t k = 0; k < e->nprop; k++)
            if (slot[k].dst >= D_R && slot[k].dst <= D_A) slot[k].dst = D_NONE;
        have[D_A] = 0;
    }
    if (have[D_NX] && have[D_NY] && have[D_NZ]) {
        raw->attrs |= PC_ATTR_NORMAL;
    } else {
        for (size_t k = 0; k < e->nprop; k++)
            if (slot[k].dst >= D_NX && slot[k].dst <= D_NZ) slot[k].dst = D_NONE;
    }
    if (have[D_RADIUS]) raw->attrs |= PC_ATTR_RADIUS;
    if (have[D_INTENS]) raw->attrs |= PC_ATTR_INTENSITY;
    return have[D_A];
}

/* ---------------------------------------------------------------- binary */

/* Fixed record size of e in bytes, or 0 when it has a list property; *min gets the smallest
 * possible record size (lists counted as empty). */
static size_t record_size(const ply_header *h, const ply_elem *e, size_t *min)
{
    size_t fixed = 0, lo = 0;
    int var = 0;
    for (size_t k = 0; k < e->nprop; k++) {
        const ply_prop *q = &h->props[e->first_prop + k];
        if (q->count_type != T_NONE) {
            var = 1;
            lo += type_size[q->count_type];
        } else {
            fixed += type_size[q->type];
            lo += type_size[q->type];
        }
    }
    *min = lo;
    return var ? 0 : fixed;
}

/* bin_record: walks one variable-size record of e starting at c->pos, storing the vertex
 * properties of slot (NULL when not a vertex) into point i of raw. Advances c->pos.
 * Returns 0 or SD_ETRUNC/SD_EFORMAT naming the byte offset. */
static int bin_record(ply_ctx *c, const ply_header *h, const ply_elem *e, uint64_t r,
                      const ply_slot *slot, pc_raw *raw, size_t i)
{
    size_t pos = c->pos;
    for (size_t k = 0; k < e->nprop; k++) {
        const ply_prop *q = &h->props[e->first_prop + k];
        if (q->count_type == T_NONE) {
            size_t sz = type_size[q->type];
            if (c->size - pos < sz) goto trunc;
            if (slot) store(raw, i, &slot[k], load(c->data + pos, q->type, c->swap));
            pos += sz;
            continue;
        }
        size_t csz = type_size[q->count_type];
        if (c->size - pos < csz) goto trunc;
        double n = load(c->data + pos, q->count_type, c->swap);
        if (n < 0)
            return sd_errf(c->err, SD_EFORMAT,
                           "%s: byte offset %zu: negative list count %.0f in record %llu of "
                           "element '%s'", c->path, pos, n, (unsigned long long)r, e->name);
        pos += csz;
        if ((double)(c->size - pos) / type_size[q->type] < n) goto trunc;
        pos += (size_t)n * type_size[q->type];
    }
    c->pos = pos;
    return 0;
trunc:
    return sd_errf(c->err, SD_ETRUNC,
                   "%s: byte offset %zu: file truncated inside record %llu of element '%s' "
                   "(%llu declared)", c->path, pos, (unsigned long long)r, e->name,
                   (unsigned long long)e->count);
}

#define PLY_BLOCK 4096 /* records decoded per block, column by column */

/* Expands BODY(type, swap) for the slot type t and byte order sw with both constant, so that
 * load() specialises into a branch-free loop. */
#define PLY_FOR_TYPE(t, sw, BODY)                                                          \
    switch ((t) * 2 + ((sw) != 0)) {                                                       \
    case T_I8 * 2: case T_I8 * 2 + 1: BODY(T_I8, 0); break;                                \
    case T_U8 * 2: case T_U8 * 2 + 1: BODY(T_U8, 0); break;                                \
    case T_I16 * 2: BODY(T_I16, 0); break;                                                 \
    case T_I16 * 2 + 1: BODY(T_I16, 1); break;                                             \
    case T_U16 * 2: BODY(T_U16, 0); break;                                                 \
    case T_U16 * 2 + 1: BODY(T_U16, 1); break;                                             \
    case T_I32 * 2: BODY(T_I32, 0); break;                                                 \
    case T_I32 * 2 + 1: BODY(T_I32, 1); break;                                             \
    case T_U32 * 2: BODY(T_U32, 0); break;                                                 \
    case T_U32 * 2 + 1: BODY(T_U32, 1); break;                                             \
    case T_F32 * 2: BODY(T_F32, 0); break;                                                 \
    case T_F32 * 2 + 1: BODY(T_F32, 1); break;                                             \
    case T_F64 * 2: BODY(T_F64, 0); break;                                                 \
    case T_F64 * 2 + 1: BODY(T_F64, 1); break;                                             \
    default: break;                                                                        \
    }

/* decode_column: decodes n values of one property, found at p with record stride rec, into
 * points base..base+n-1 of the slot's destination array in raw. */
static void decode_column(const uint8_t *p, size_t rec, size_t n, const ply_slot *s, int swap,
                          pc_raw *raw, size_t base)
{
    int d = s->dst;
    if (d >= D_X && d <= D_Z) {
        double *out = raw->xyz + 3 * base + (d - D_X);
#define COL_D(T, SW) for (size_t i = 0; i < n; i++) out[3 * i] = load(p + i * rec, T, SW)
        PLY_FOR_TYPE(s->type, swap, COL_D)
#undef COL_D
    } else if (d >= D_R && d <= D_A) {
        uint8_t *out = raw->rgba + 4 * base + (d - D_R);
        double sc = s->cscale;
        if (s->type == T_U8) {
            for (size_t i = 0; i < n; i++) out[4 * i] = p[i * rec];
        } else {
#define COL_C(T, SW) \
    for (size_t i = 0; i < n; i++) out[4 * i] = colour8(load(p + i * rec, T, SW) * sc)
            PLY_FOR_TYPE(s->type, swap, COL_C)
#undef COL_C
        }
    } else {
        float *out;
        size_t stride = 1;
        if (d >= D_NX && d <= D_NZ) {
            out = raw->normal + 3 * base + (d - D_NX);
            stride = 3;
        } else if (d == D_RADIUS) {
            out = raw->radius + base;
        } else if (d == D_INTENS) {
            out = raw->intensity + base;
        } else if (d == D_SCALAR) {
            out = raw->scalar + base;
        } else {
            return;
        }
#define COL_F(T, SW) \
    for (size_t i = 0; i < n; i++) out[stride * i] = to_f32(load(p + i * rec, T, SW))
        PLY_FOR_TYPE(s->type, swap, COL_F)
#undef COL_F
    }
}

/* bin_element: reads (slot != NULL) or skips element e at c->pos with every length checked
 * against the file size before use. Returns 0, SD_ETRUNC, SD_EFORMAT or SD_ENOMEM. */
static int bin_element(ply_ctx *c, const ply_header *h, const ply_elem *e, const ply_slot *slot,
                       pc_raw *raw, int have_alpha)
{
    size_t minrec;
    size_t rec = record_size(h, e, &minrec);
    size_t left = c->size - c->pos;
    if (e->count == 0) return 0;
    if (minrec == 0) /* an element without properties occupies no bytes */
        return 0;
    if (e->count > left / minrec)
        return sd_errf(c->err, SD_ETRUNC,
                       "%s: byte offset %zu: element '%s' declares %llu records of %s%zu bytes "
                       "but only %zu bytes remain", c->path, c->pos, e->name,
                       (unsigned long long)e->count, rec ? "" : "at least ", minrec, left);
    size_t n = (size_t)e->count;
    size_t base = raw ? raw->n : 0;
    if (slot) {
        int rc = pc_raw_reserve(raw, base + n, c->err);
        if (rc < 0) return rc;
        if ((raw->attrs & PC_ATTR_RGB) && !have_alpha)
            for (size_t i = 0; i < n; i++) raw->rgba[4 * (base + i) + 3] = 255;
    }
    if (rec) {
        if (slot) {
            ply_slot used[PLY_MAX_PROPS];
            size_t nslot = 0;
            for (size_t k = 0, off = 0; k < e->nprop; k++) {
                if (slot[k].dst != D_NONE) {
                    used[nslot] = slot[k];
                    used[nslot++].off = off;
                }
                off += type_size[h->props[e->first_prop + k].type];
            }
            /* Column by column within blocks that stay in cache: each column loop has its
             * type, byte order and destination fixed, so it compiles to a tight loop. */
            for (size_t b0 = 0; b0 < n; b0 += PLY_BLOCK) {
                size_t bn = n - b0 < PLY_BLOCK ? n - b0 : PLY_BLOCK;
                const uint8_t *p = c->data + c->pos + b0 * rec;
                for (size_t s = 0; s < nslot; s++)
                    decode_column(p + used[s].off, rec, bn, &used[s], c->swap, raw, base + b0);
            }
        }
        c->pos += n * rec;
    } else {
        for (size_t i = 0; i < n; i++) {
            int rc = bin_record(c, h, e, i, slot, raw, base + i);
            if (rc < 0) return rc;
        }
    }
    if (slot) raw->n = base + n;
    return 0;
}

/* ---------------------------------------------------------------- ascii */

/* asc_record: parses the record of e on the line starting at c->pos (skipping blank lines),
 * storing vertex values through slot (NULL when skipping) into point i. Advances c->pos and
 * c->line past the line. Returns 0, SD_ETRUNC (file ends) or SD_EFORMAT (bad token). */
static int asc_record(ply_ctx *c, const ply_header *h, const ply_elem *e, uint64_t r,
                      const ply_slot *slot, pc_raw *raw, size_t i)
{
    const char *s = (const char *)c->data, *end = s + c->size;
    const char *p, *le, *te;
    for (;;) {
        p = s + c->pos;
        if (p >= end)
            return sd_errf(c->err, SD_ETRUNC,
                           "%s: line %zu: file ends after %llu of %llu records of element '%s'",
                           c->path, c->line, (unsigned long long)r, (unsigned long long)e->count,
                           e->name);
        le = pc__line_end(p, end);
        te = pc__trim_cr(p, le);
        while (p < te && pc__is_space((unsigned char)*p)) p++;
        if (p < te) break;
        c->pos = (size_t)(le - s) + (le < end);
        c->line++;
    }
    int last = le == end; /* a short last line without '\n' is a cut file, not a bad one */
    for (size_t k = 0; k < e->nprop; k++) {
        const ply_prop *q = &h->props[e->first_prop + k];
        double n = 1;
        if (q->count_type != T_NONE) {
            while (p < te && pc__is_space((unsigned char)*p)) p++;
            const char *q_end = p < te ? pc__parse_num(p, te, &n) : NULL;
            if (!q_end) goto short_or_bad;
            if (q_end < te && !pc__is_space((unsigned char)*q_end)) goto bad;
            if (!(n >= 0 && n <= (double)(te - p) && n == floor(n)))
                return sd_errf(c->err, SD_EFORMAT,
                               "%s: line %zu: bad list count in record %llu of element '%s'",
                               c->path, c->line, (unsigned long long)r, e->name);
            p = q_end;
        }
        for (size_t j = 0; j < (size_t)n; j++) {
            double v;
            while (p < te && pc__is_space((unsigned char)*p)) p++;
            const char *ve = p < te ? pc__parse_num(p, te, &v) : NULL;
            if (!ve) goto short_or_bad;
            if (ve < te && !pc__is_space((unsigned char)*ve)) goto bad;
            if (slot && q->count_type == T_NONE) store(raw, i, &slot[k], v);
            p = ve;
        }
    }
    while (p < te && pc__is_space((unsigned char)*p)) p++;
    if (p < te)
        return sd_errf(c->err, SD_EFORMAT,
                       "%s: line %zu: more values than element '%s' has properties (at '%.20s')",
                       c->path, c->line, e->name, p);
    c->pos = (size_t)(le - s) + (le < end);
    c->line++;
    return 0;
short_or_bad:
    if (p >= te)
        return sd_errf(c->err, last ? SD_ETRUNC : SD_EFORMAT,
                       "%s: line %zu: too few values for record %llu of element '%s'%s", c->path,
                       c->line, (unsigned long long)r, e->name,
                       last ? " (the file ends inside it)" : "");
bad: {
    const char *t = p;
    while (t < te && !pc__is_space((unsigned char)*t)) t++;
    int partial = last && t == te; /* "-" or "1e-" at the very end: a number cut in half */
    return sd_errf(c->err, partial ? SD_ETRUNC : SD_EFORMAT,
                   "%s: line %zu: bad number token '%.*s' in element '%s'%s", c->path, c->line,
                   (int)(t - p > 40 ? 40 : t - p), p, e->name,
                   partial ? " (the file ends inside it)" : "");
}
}

/* asc_element: reads (slot != NULL) or skips the ascii element e. Before reserving, the count is
 * checked against the bytes left: every value needs at least one character and a separator.
 * Returns 0 or a negative SD_E* code. */
static int asc_element(ply_ctx *c, const ply_header *h, const ply_elem *e, const ply_slot *slot,
                       pc_raw *raw, int have_alpha)
{
    size_t base = raw ? raw->n : 0;
    if (e->nprop == 0) return 0; /* records without values occupy nothing, as in binary */
    if (slot) {
        size_t left = c->size - c->pos, minrec = 2 * (e->nprop ? e->nprop : 1);
        if (e->count > (left + 1) / minrec)
            return sd_errf(c->err, SD_ETRUNC,
                           "%s: line %zu: element '%s' declares %llu records but the %zu bytes "
                           "left can hold at most %zu", c->path, c->line, e->name,
                           (unsigned long long)e->count, left, (left + 1) / minrec);
        int rc = pc_raw_reserve(raw, base + (size_t)e->count, c->err);
        if (rc < 0) return rc;
        if ((raw->attrs & PC_ATTR_RGB) && !have_alpha)
            for (size_t i = 0; i < (size_t)e->count; i++) raw->rgba[4 * (base + i) + 3] = 255;
    }
    for (uint64_t r = 0; r < e->count; r++) {
        int rc = asc_record(c, h, e, r, slot, raw, base + (size_t)r);
        if (rc < 0) return rc;
    }
    if (slot) raw->n = base + (size_t)e->count;
    return 0;
}

/* ---------------------------------------------------------------- reader */

/* Scales every non-zero finite normal to unit length, as cloud.h promises. */
static void normalise(pc_raw *raw)
{
    for (size_t i = 0; i < raw->n; i++) {
        float *nv = raw->normal + 3 * i;
        double l = sqrt((double)nv[0] * nv[0] + (double)nv[1] * nv[1] + (double)nv[2] * nv[2]);
        if (l > 0 && isfinite(l) && fabs(l - 1.0) > 1e-6)
            for (int k = 0; k < 3; k++) nv[k] = (float)(nv[k] / l);
    }
}

/* What the guarded part of pc_read_ply (raw) or pc_ply_stream_plan (sp) works on
 * (pc__guarded: everything reachable here). */
typedef struct ply_job {
    const char *path;
    const pc__file *f;
    ply_header *h;
    ply_slot *slot;
    pc_raw *raw;
    pc_ply_stream *sp;
    sd_err *err;
} ply_job;

/* ply_parse: the header and every element of the file mapped in j->f, into j->raw. */
static int ply_parse(void *arg)
{
    ply_job *j = arg;
    ply_header *h = j->h;
    pc_raw *raw = j->raw;
    ply_ctx c = {.path = j->path, .data = j->f->data, .size = j->f->size, .err = j->err};
    int rc = parse_header(&c, h);
    if (rc < 0) return rc;
    const int host_be = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
    c.swap = h->fmt != FMT_ASCII && ((h->fmt == FMT_BE) != host_be);

    size_t vi = h->nelem;
    for (size_t k = 0; k < h->nelem && vi == h->nelem; k++)
        if (!strcmp(h->elems[k].name, "vertex")) vi = k;
    if (vi == h->nelem)
        return sd_errf(j->err, SD_EFORMAT, "%s: line %zu: the header declares no element 'vertex'",
                       j->path, h->data_line - 1);
    rc = plan_vertex(&c, h, &h->elems[vi], j->slot, raw);
    if (rc < 0) return rc;
    int have_alpha = rc;
    snprintf(raw->format, sizeof raw->format, "PLY %s %s", fmt_name[h->fmt], h->version);

    for (size_t k = 0; k < h->nelem; k++) {
        const ply_slot *sl = k == vi ? j->slot : NULL;
        rc = h->fmt == FMT_ASCII ? asc_element(&c, h, &h->elems[k], sl, raw, have_alpha)
                                 : bin_element(&c, h, &h->elems[k], sl, raw, have_alpha);
        if (rc < 0) return rc;
    }
    if (raw->attrs & PC_ATTR_NORMAL) normalise(raw);
    return 0;
}

/* ---------------------------------------------------------------- the streaming plan */

/* ply_plan: pc_ply_stream_plan on the file mapped in j->f: the header, the vertex plan and
 * every element's extent checked as ply_parse checks them, without decoding any value. */
static int ply_plan(void *arg)
{
    ply_job *j = arg;
    ply_header *h = j->h;
    ply_ctx c = {.path = j->path, .data = j->f->data, .size = j->f->size, .err = j->err};
    int rc = parse_header(&c, h);
    if (rc < 0) return rc;
    size_t minrec, rec = h->nelem ? record_size(h, &h->elems[0], &minrec) : 0;
    if (h->fmt != FMT_LE || !rec || strcmp(h->elems[0].name, "vertex")) return 0;
    pc_raw raw = {0}; /* plan_vertex sets only its attrs and scalar name */
    rc = plan_vertex(&c, h, &h->elems[0], j->slot, &raw);
    if (rc < 0) return rc;
    for (size_t k = 0; k < h->nelem; k++)
        if ((rc = bin_element(&c, h, &h->elems[k], NULL, NULL, 0)) < 0) return rc;
    pc_ply_stream *sp = j->sp;
    memset(sp, 0, sizeof *sp);
    sp->data_off = h->data_off;
    sp->count = h->elems[0].count;
    sp->rec = rec;
    for (int i = 0; i < 7; i++) sp->off[i] = -1, sp->cscale[i] = 1.0;
    for (size_t k = 0, off = 0; k < h->elems[0].nprop; k++) {
        const ply_slot *sl = &j->slot[k];
        if (sl->dst >= D_X && sl->dst <= D_A) { /* colours only where r, g and b all are */
            int i = sl->dst - D_X;
            sp->off[i] = (int)off;
            sp->type[i] = sl->type;
            sp->cscale[i] = sl->cscale;
        }
        off += type_size[h->props[h->elems[0].first_prop + k].type];
    }
    snprintf(sp->format, sizeof sp->format, "PLY %s %s", fmt_name[h->fmt], h->version);
    return 1;
}

/* ply_run: maps path and runs fn (ply_parse or ply_plan) on it under pc__guarded, with j's
 * header and slot table allocated for it. Returns fn's result or the mapping's error. */
static int ply_run(const char *path, ply_job *j, int (*fn)(void *))
{
    pc__file f;
    int rc = pc__file_open(path, &f, j->err);
    if (rc < 0) return rc;
    j->path = path;
    j->f = &f;
    j->h = calloc(1, sizeof *j->h);
    j->slot = calloc(PLY_MAX_PROPS, sizeof *j->slot);
    if (!j->h || !j->slot)
        rc = sd_errf(j->err, SD_ENOMEM, "%s: out of memory for the PLY header", path);
    else
        rc = pc__guarded(&f, path, fn, j, j->err);
    free(j->h);
    free(j->slot);
    pc__file_close(&f);
    return rc;
}

int pc_ply_stream_plan(const char *path, pc_ply_stream *sp, sd_err *err)
{
    ply_job j = {.sp = sp, .err = err};
    return ply_run(path, &j, ply_plan);
}

int pc_read_ply(const char *path, pc_raw *raw, sd_err *err)
{
    if (!path || !raw) return sd_errf(err, SD_EINVAL, "pc_read_ply: NULL argument");
    ply_job j = {.raw = raw, .err = err};
    int rc = ply_run(path, &j, ply_parse);
    return rc < 0 ? rc : 0;
}
