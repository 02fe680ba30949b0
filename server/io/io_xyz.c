/* io_xyz.c — XYZ/PTS text reader (.xyz .pts .txt).
 *
 * Rows of whitespace-, comma- or semicolon-separated numbers: "x y z", "x y z i",
 * "x y z r g b" or "x y z i r g b" (the PTS order: intensity, then colour). An optional first
 * data line holding a single integer is the PTS point count and must match the rows found.
 * Blank lines and lines starting with '#' or '//' are skipped; LF and CRLF both work.
 * The layout is decided from the first data row and every later row must match it.
 * Colours are 0..255 integers; when any value exceeds 255 the file is taken as 16-bit colour
 * (scaled by 255/65535), and when all are within [0,1] with a fraction, as 0..1 floats. */
#include "cloud.h"
#include "io_text.h"
#include "xyz_stream.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/mman.h>
#include <unistd.h>

#define XYZ_MAX_COLS 7

static inline int is_sep(int c)
{
    return c == ' ' || c == '\t' || c == ',' || c == ';' || c == '\r' || c == '\v' || c == '\f';
}

/* The reading state of one file. */
typedef struct xyz_ctx {
    const char *path;
    sd_err *err;
    int ncol;           /* columns of the first data row, 0 before it */
    size_t first_line;  /* line of the first data row */
    size_t bound;       /* most points the file's bytes can hold */
    float *col;         /* 3 * raw->cap colour values as read, scaled at the end */
    double col_max;
    int col_frac;       /* some colour value has a fractional part */
    size_t count_line;  /* line of the current block's count line, 0 when none */
    uint64_t declared;  /* points that count line declares */
    uint64_t block_start; /* rows when that block began */
    uint64_t rows;      /* data rows read so far */
    size_t pos, ln;     /* where the next line starts, and the lines read */
    int done;           /* every line read and checked */
    int stream;         /* streamed: raw is a window, never reserved by a count line */
} xyz_ctx;

/* Splits the line [p, te) into numbers. Returns the count (XYZ_MAX_COLS + 1 when there are
 * more), or -1 with *bad set to the first token that is not a number. */
static int split_nums(const char *p, const char *te, double *v, const char **bad)
{
    int n = 0;
    for (;;) {
        while (p < te && is_sep((unsigned char)*p)) p++;
        if (p >= te) return n;
        if (n == XYZ_MAX_COLS) return n + 1;
        const char *e = pc__parse_num(p, te, &v[n]);
        if (!e || (e < te && !is_sep((unsigned char)*e))) {
            *bad = p;
            return -1;
        }
        n++;
        p = e;
    }
}

/* A double as float without the undefined conversion of out-of-range values. */
static inline float to_f32(double v)
{
    if (v > FLT_MAX) return FLT_MAX;
    if (v < -FLT_MAX) return -FLT_MAX;
    return (float)v;
}

/* grow: makes room for one more point, doubling the capacity but never beyond what the file
 * can hold. Returns 0 or SD_ENOMEM/SD_ELIMIT. */
static int grow(xyz_ctx *x, pc_raw *raw)
{
    if (raw->n < raw->cap) return 0;
    size_t cap = raw->cap < 1024 ? 1024 : raw->cap * 2;
    if (cap > x->bound) cap = x->bound;
    if (cap <= raw->n) /* cannot happen: each row takes at least 6 bytes */
        return sd_errf(x->err, SD_ELIMIT, "%s: more rows than the file size allows", x->path);
    int rc = pc_raw_reserve(raw, cap, x->err);
    if (rc < 0) return rc;
    if (raw->attrs & PC_ATTR_RGB) {
        float *c = realloc(x->col, cap * 3 * sizeof(float));
        if (!c)
            return sd_errf(x->err, SD_ENOMEM, "%s: out of memory for %zu colours", x->path, cap);
        x->col = c;
    }
    return 0;
}

/* set_layout: decides the attributes from the first data row's column count n at line ln. */
static int set_layout(xyz_ctx *x, pc_raw *raw, int n, size_t ln)
{
    static const char *const names[XYZ_MAX_COLS + 1] = {
        [3] = "x y z", [4] = "x y z i", [6] = "x y z r g b", [7] = "x y z i r g b"};
    if (n > XYZ_MAX_COLS || !names[n])
        return sd_errf(x->err, SD_EUNSUP,
                       "%s: line %zu: %d%s values in the first data row; expected 3 (x y z), "
                       "4 (x y z i), 6 (x y z r g b) or 7 (x y z i r g b)",
                       x->path, ln, n > XYZ_MAX_COLS ? XYZ_MAX_COLS : n,
                       n > XYZ_MAX_COLS ? " or more" : "");
    x->ncol = n;
    x->first_line = ln;
    if (n == 4 || n == 7) raw->attrs |= PC_ATTR_INTENSITY;
    if (n >= 6) raw->attrs |= PC_ATTR_RGB;
    return 0;
}

/* The scale of the colours, from every value of the file. */
static double colour_scale(const xyz_ctx *x)
{
    if (x->col_max > 255) return 255.0 / 65535.0;
    if (x->col_max <= 1.0 && x->col_frac) return 255.0;
    return 1.0;
}

/* One row's colour as read (3 floats) into RGBA8. */
static void colour8(const float *c, double scale, uint8_t *out)
{
    for (int k = 0; k < 3; k++) {
        double v = c[k] * scale;
        out[k] = !(v > 0) ? 0 : v >= 255 ? 255 : (uint8_t)(v + 0.5);
    }
    out[3] = 255;
}

/* finish_colour: converts the colours read into raw->rgba with the scale the values imply. */
static void finish_colour(xyz_ctx *x, pc_raw *raw)
{
    double scale = colour_scale(x);
    for (size_t i = 0; i < raw->n; i++) colour8(x->col + 3 * i, scale, raw->rgba + 4 * i);
}

/* count_row: takes the single value v on line ln ([q, te)) as a PTS count line, which must be a
 * plain non-negative integer, and starts a block at raw->n. Returns 0 or SD_EFORMAT. */
static int count_row(xyz_ctx *x, const char *q, const char *te, double v, size_t ln)
{
    size_t digits = 0;
    const char *t = q;
    while (t < te && (unsigned)(*t - '0') < 10) t++, digits++;
    while (t < te && is_sep((unsigned char)*t)) t++;
    if (digits == 0 || digits > 15 || t != te)
        return sd_errf(x->err, SD_EFORMAT, "%s: line %zu: a single value that is not a point count",
                       x->path, ln);
    x->declared = (uint64_t)v;
    x->count_line = ln;
    x->block_start = x->rows;
    return 0;
}

/* check_block: when a count line opened the current block, its rows (ending before line ln)
 * must number what it declared. Returns 0, SD_ETRUNC (fewer) or SD_EFORMAT (more). */
static int check_block(const xyz_ctx *x, size_t ln)
{
    uint64_t rows = x->rows - x->block_start;
    if (!x->count_line || rows == x->declared) return 0;
    return sd_errf(x->err, x->declared > rows ? SD_ETRUNC : SD_EFORMAT,
                   "%s: line %zu: the count line declares %llu points but %llu rows follow it "
                   "(up to line %zu)", x->path, x->count_line, (unsigned long long)x->declared,
                   (unsigned long long)rows, ln);
}

/* first_row: sets the layout from the first data row (n values, line ln; cut when it is an
 * unterminated last line), names the format and, after a count line, reserves the declared
 * points within what the file can hold. Returns 0 or a negative SD_E* code. */
static int first_row(xyz_ctx *x, pc_raw *raw, int n, size_t ln, int cut)
{
    int rc = set_layout(x, raw, n, ln);
    if (rc < 0 && cut && n < 3)
        return sd_errf(x->err, SD_ETRUNC, "%s: line %zu: the file ends inside the first row "
                       "(%d values)", x->path, ln, n);
    if (rc < 0) return rc;
    snprintf(raw->format, sizeof raw->format, "%s text (%s)", x->count_line ? "PTS" : "XYZ",
             x->ncol == 3 ? "x y z" : x->ncol == 4 ? "x y z i"
             : x->ncol == 6 ? "x y z r g b" : "x y z i r g b");
    size_t want = x->declared < x->bound ? (size_t)x->declared : x->bound;
    if (!x->count_line || want == 0 || x->stream) return 0;
    rc = pc_raw_reserve(raw, want, x->err);
    if (rc < 0) return rc;
    if ((raw->attrs & PC_ATTR_RGB) && !(x->col = malloc(want * 3 * sizeof(float))))
        return sd_errf(x->err, SD_ENOMEM, "%s: out of memory for %zu colours", x->path, want);
    return 0;
}

/* store_row: appends the row v (x->ncol values) to raw, growing it. Returns 0 or SD_ENOMEM. */
static int store_row(xyz_ctx *x, pc_raw *raw, const double *v)
{
    int rc = grow(x, raw);
    if (rc < 0) return rc;
    size_t i = raw->n++;
    x->rows++;
    raw->xyz[3 * i] = v[0];
    raw->xyz[3 * i + 1] = v[1];
    raw->xyz[3 * i + 2] = v[2];
    int inten = x->ncol == 4 || x->ncol == 7;
    if (inten) raw->intensity[i] = to_f32(v[3]);
    if (x->ncol >= 6) {
        const double *c = v + (inten ? 4 : 3);
        for (int k = 0; k < 3; k++) {
            if (c[k] > x->col_max) x->col_max = c[k];
            if (c[k] != floor(c[k])) x->col_frac = 1;
            x->col[3 * i + k] = to_f32(c[k]);
        }
    }
    return 0;
}

/* What the guarded part of pc_read_xyz works on (pc__guarded: its colour array is in x). */
typedef struct xyz_job {
    const pc__file *f;
    xyz_ctx *x;
    pc_raw *raw;
    size_t limit;       /* stop once raw holds this many rows */
} xyz_job;

/* xyz_lines: the lines of the file mapped in j->f from x->pos on, into j->raw, until it holds
 * j->limit rows or the file ends (then x->done, the last block checked). */
static int xyz_lines(void *arg)
{
    xyz_job *j = arg;
    xyz_ctx *x = j->x;
    pc_raw *raw = j->raw;
    const char *path = x->path;
    sd_err *err = x->err;
    int rc = 0;
    const char *s = (const char *)j->f->data, *end = s + j->f->size;
    const char *p = s + x->pos;
    size_t ln = x->ln;
    for (; p < end && raw->n < j->limit; p = p < end ? p + 1 : p) {
        /* p is at a line's '\n' at the loop's end */
        ln++;
        const char *le = pc__line_end(p, end), *te = pc__trim_cr(p, le);
        const char *q = p;
        p = le;
        while (q < te && is_sep((unsigned char)*q)) q++;
        if (q >= te || *q == '#' || (te - q >= 2 && q[0] == '/' && q[1] == '/')) continue;
        double v[XYZ_MAX_COLS + 1];
        const char *bad = NULL;
        int n = split_nums(q, te, v, &bad);
        int cut = le == end; /* the last line has no '\n': the file may be cut short */
        if (n < 0) {
            const char *t = bad;
            while (t < te && !is_sep((unsigned char)*t)) t++;
            int partial = cut && t == te; /* "-", "1e-": a number cut in half */
            rc = sd_errf(err, partial ? SD_ETRUNC : SD_EFORMAT,
                         "%s: line %zu: bad number token '%.*s'%s", path, ln,
                         (int)(t - bad > 40 ? 40 : t - bad), bad,
                         partial ? " (the file ends inside it)" : "");
            return rc;
        }
        if (n == 1 && (x->ncol == 0 || x->count_line)) {
            /* A PTS count line: before the first row, or starting the next block of a
             * multi-scan file whose first block had one. */
            rc = check_block(x, ln);
            if (rc < 0) return rc;
            rc = count_row(x, q, te, v[0], ln);
            if (rc < 0) return rc;
            continue;
        }
        if (x->ncol == 0) {
            rc = first_row(x, raw, n, ln, cut);
            if (rc < 0) return rc;
        } else if (n != x->ncol) {
            rc = sd_errf(err, cut && n < x->ncol ? SD_ETRUNC : SD_EFORMAT,
                         "%s: line %zu: %d%s values, but the first data row (line %zu) has %d%s",
                         path, ln, n > XYZ_MAX_COLS ? XYZ_MAX_COLS : n,
                         n > XYZ_MAX_COLS ? " or more" : "", x->first_line, x->ncol,
                         cut && n < x->ncol ? " (the file ends inside this row)" : "");
            return rc;
        }
        rc = store_row(x, raw, v);
        if (rc < 0) return rc;
    }
    x->pos = (size_t)(p - s);
    x->ln = ln;
    if (p < end) return 0;
    rc = check_block(x, ln);
    if (rc < 0) return rc;
    if (x->ncol == 0 && !raw->format[0])
        snprintf(raw->format, sizeof raw->format, "%s text (no rows)",
                 x->count_line ? "PTS" : "XYZ");
    x->done = 1;
    return 0;
}

/* xyz_parse: every line of the file, then the colours scaled. */
static int xyz_parse(void *arg)
{
    xyz_job *j = arg;
    int rc = xyz_lines(j);
    if (rc == 0 && (j->raw->attrs & PC_ATTR_RGB)) finish_colour(j->x, j->raw);
    return rc;
}

int pc_read_xyz(const char *path, pc_raw *raw, sd_err *err)
{
    if (!path || !raw) return sd_errf(err, SD_EINVAL, "pc_read_xyz: NULL argument");
    pc__file f;
    int rc = pc__file_open(path, &f, err);
    if (rc < 0) return rc;
    xyz_ctx x = {.path = path, .err = err, .bound = f.size / 6 + 1};
    xyz_job j = {.f = &f, .x = &x, .raw = raw, .limit = SIZE_MAX};
    rc = pc__guarded(&f, path, xyz_parse, &j, err);
    free(x.col);
    pc__file_close(&f);
    return rc;
}

/* ---- the stream (xyz_stream.h) ---- */

struct pc_xyz_stream {
    char path[4096];
    pc__file f;
    xyz_ctx x;
    pc_raw win;          /* the rows of the last window */
    int final;           /* a whole pass read: layout, format and colour scale known */
    double scale;
    int has_rgb;
    char format[64];
};

int pc_xyz_stream_open(const char *path, pc_xyz_stream **out, sd_err *err)
{
    *out = NULL;
    const char *slash = strrchr(path, '/'), *dot = strrchr(slash ? slash : path, '.');
    const char *e = dot ? dot + 1 : "";
    if (strcasecmp(e, "xyz") && strcasecmp(e, "pts") && strcasecmp(e, "txt")) return 0;
    pc_xyz_stream *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    snprintf(s->path, sizeof s->path, "%s", path);
    int rc = pc__file_open(path, &s->f, err);
    if (rc < 0) {
        free(s);
        return rc;
    }
    s->x.path = s->path;
    s->x.bound = s->f.size / 6 + 1;
    s->x.stream = 1;
    *out = s;
    return 1;
}

void pc_xyz_stream_close(pc_xyz_stream *s)
{
    if (!s) return;
    free(s->x.col);
    pc_raw_free(&s->win);
    pc__file_close(&s->f);
    free(s);
}

void pc_xyz_stream_rewind(pc_xyz_stream *s)
{
    xyz_ctx *x = &s->x;
    x->ncol = 0;
    x->first_line = x->count_line = 0;
    x->declared = x->block_start = x->rows = 0;
    x->pos = x->ln = 0;
    x->done = 0;
}

int64_t pc_xyz_stream_next(pc_xyz_stream *s, double *xyz, uint8_t *rgba, size_t max,
                           sd_err *err)
{
    if (rgba && !s->final)
        return sd_errf(err, SD_EINVAL, "%s: colours asked before a whole pass", s->path);
    if (s->x.done || max == 0) return 0;
    s->win.n = 0;
    s->x.err = err;
    xyz_job j = {.f = &s->f, .x = &s->x, .raw = &s->win, .limit = max};
    int rc = pc__guarded(&s->f, s->path, xyz_lines, &j, err);
    if (rc < 0) return rc;
    size_t n = s->win.n;
    if (n) memcpy(xyz, s->win.xyz, 3 * n * sizeof *xyz); /* none read: win.xyz may be NULL */
    if (rgba) {
        for (size_t i = 0; i < n; i++) {
            if (s->has_rgb) colour8(s->x.col + 3 * i, s->scale, rgba + 4 * i);
            else memset(rgba + 4 * i, 255, 4);
        }
    }
    if (s->x.done) {
        s->final = 1;
        s->scale = colour_scale(&s->x);
        s->has_rgb = (s->win.attrs & PC_ATTR_RGB) != 0;
        snprintf(s->format, sizeof s->format, "%s", s->win.format);
    }
    /* the lines read are not needed again this pass: give their pages back */
    long pg = sysconf(_SC_PAGESIZE);
    size_t upto = pg > 0 ? s->x.pos & ~((size_t)pg - 1) : 0;
    if (upto > 0 && s->f.map) (void)madvise(s->f.map, upto, MADV_DONTNEED);
    return (int64_t)n;
}

const char *pc_xyz_stream_format(const pc_xyz_stream *s)
{
    return s->format;
}

int pc_xyz_stream_has_rgb(const pc_xyz_stream *s)
{
    return s->has_rgb;
}
