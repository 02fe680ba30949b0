/* e57_scan.c — the scans of an E57 XML tree (e57_scan.h). */
#include "e57_scan.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct ctx {
    const char *what;
    sd_err *err;
    e57_desc *d;
    uint32_t nfields, cap; /* fields used / allocated in d->fields */
} ctx;

static const char *const role_names[E57_R_COUNT] = {
#define E57_ROLE_NAME_(id, name) name,
    E57_ROLES(E57_ROLE_NAME_)
#undef E57_ROLE_NAME_
};

const char *e57_role_name(int role)
{
    return role >= 0 && role < E57_R_COUNT ? role_names[role] : "(none)";
}

/* trimmed: s without leading and trailing white space, into buf (len bytes); NULL when it does
 * not fit. */
static const char *trimmed(const char *s, char *buf, size_t len)
{
    while (*s == ' ' || *s == '\t' || *s == '\n' || *s == '\r') s++;
    size_t n = strlen(s);
    while (n && (s[n - 1] == ' ' || s[n - 1] == '\t' || s[n - 1] == '\n' || s[n - 1] == '\r')) n--;
    if (n >= len) return NULL;
    memcpy(buf, s, n);
    buf[n] = 0;
    return buf;
}

/* parse_i64 / parse_u64 / parse_f64: the whole string s (white space around it allowed; empty:
 * def) as a number. 0 or -1 when it is not one. */
static int parse_i64(const char *s, int64_t def, int64_t *out)
{
    char b[64];
    const char *t = s ? trimmed(s, b, sizeof b) : "";
    if (!t) return -1;
    if (!*t) return *out = def, 0;
    char *e;
    errno = 0;
    long long v = strtoll(t, &e, 10);
    if (errno || *e) return -1;
    *out = v;
    return 0;
}

static int parse_u64(const char *s, uint64_t *out)
{
    char b[64];
    const char *t = s ? trimmed(s, b, sizeof b) : NULL;
    if (!t || !*t || *t == '-') return -1;
    char *e;
    errno = 0;
    unsigned long long v = strtoull(t, &e, 10);
    if (errno || *e) return -1;
    *out = v;
    return 0;
}

static int parse_f64(const char *s, double def, double *out)
{
    char b[128];
    const char *t = s ? trimmed(s, b, sizeof b) : "";
    if (!t) return -1;
    if (!*t) return *out = def, 0;
    char *e;
    errno = 0;
    double v = strtod(t, &e);
    if (*e || isnan(v)) return -1; /* ERANGE: ±HUGE_VAL or a denormal, both usable */
    *out = v;
    return 0;
}

static int bad(ctx *c, const e57_node *n, const char *fmt, const char *a, const char *b)
{
    char m[300];
    snprintf(m, sizeof m, fmt, a, b);
    return sd_errf(c->err, SD_EFORMAT, "%s: line %lu: <%s>: %s", c->what, n ? n->line : 0UL,
                   n ? n->name : "?", m);
}

/* number: the value of a numeric element n (Integer, ScaledInteger or Float) into *v. */
static int number(ctx *c, const e57_node *n, double *v)
{
    int rc;
    if (!strcmp(n->type, "Integer")) {
        int64_t i;
        rc = parse_i64(n->text, 0, &i);
        *v = (double)i;
    } else if (!strcmp(n->type, "ScaledInteger")) {
        int64_t i;
        double scale, off;
        rc = parse_i64(n->text, 0, &i) | parse_f64(e57_attr(n, "scale"), 1.0, &scale) |
            parse_f64(e57_attr(n, "offset"), 0.0, &off);
        *v = (double)i * scale + off;
    } else if (!strcmp(n->type, "Float")) {
        rc = parse_f64(n->text, 0.0, v);
    } else {
        return bad(c, n, "type '%s' where a number (Integer, ScaledInteger, Float) belongs%s",
                   n->type, "");
    }
    if (rc < 0 || !isfinite(*v)) return bad(c, n, "'%s' is not a finite number%s", n->text, "");
    return 0;
}

/* opt_number: the value of child name of n, or def when there is none. */
static int opt_number(ctx *c, const e57_node *n, const char *name, double def, double *v)
{
    const e57_node *k = e57_child(n, name);
    *v = def;
    return k ? number(c, k, v) : 0;
}

static e57_field *new_field(ctx *c, const e57_node *n)
{
    if (c->nfields >= c->cap) {
        uint32_t cap = c->cap ? 2 * c->cap : 16;
        e57_field *f = realloc(c->d->fields, cap * sizeof *f);
        if (!f) {
            sd_errf(c->err, SD_ENOMEM, "%s: out of memory", c->what);
            return NULL;
        }
        c->d->fields = f;
        c->cap = cap;
    }
    e57_field *f = &c->d->fields[c->nfields++];
    memset(f, 0, sizeof *f);
    f->role = E57_R_NONE;
    return f;
}

/* bits_for: the bits of a value in [0, range]. */
static int bits_for(uint64_t range)
{
    return range ? 64 - __builtin_clzll(range) : 0;
}

/* leaf: the prototype element n as one or more fields (depth first for structures). */
static int leaf(ctx *c, e57_scan *s, const e57_node *n, int depth)
{
    if (!strcmp(n->type, "Structure") || !strcmp(n->type, "Vector")) {
        for (const e57_node *k = n->child; k; k = k->next) {
            int rc = leaf(c, s, k, depth + 1);
            if (rc < 0) return rc;
        }
        return 0;
    }
    if (!strcmp(n->type, "String"))
        return sd_errf(c->err, SD_EUNSUP,
                       "%s: line %lu: scan %u: the prototype field <%s> is a "
                       "String, which the bit-pack codec cannot hold",
                       c->what, n->line, s->index, n->name);
    if (s->nfields >= E57_MAX_FIELDS)
        return sd_errf(c->err, SD_ELIMIT, "%s: line %lu: scan %u: more than %d prototype fields",
                       c->what, n->line, s->index, E57_MAX_FIELDS);
    e57_field *f = new_field(c, n);
    if (!f) return SD_ENOMEM;
    s->nfields++;
    if (!strcmp(n->type, "Integer") || !strcmp(n->type, "ScaledInteger")) {
        f->kind = n->type[0] == 'I' ? E57_INTEGER : E57_SCALED;
        if (parse_i64(e57_attr(n, "minimum"), INT64_MIN, &f->min) < 0 ||
            parse_i64(e57_attr(n, "maximum"), INT64_MAX, &f->max) < 0 || f->min > f->max)
            return bad(c, n,
                       "minimum '%s' and maximum '%s' are not integers with minimum <= "
                       "maximum",
                       e57_attr(n, "minimum") ? e57_attr(n, "minimum") : "",
                       e57_attr(n, "maximum") ? e57_attr(n, "maximum") : "");
        f->bits = bits_for((uint64_t)f->max - (uint64_t)f->min);
        f->scale = 1.0;
        if (f->kind == E57_SCALED &&
            (parse_f64(e57_attr(n, "scale"), 1.0, &f->scale) < 0 ||
             parse_f64(e57_attr(n, "offset"), 0.0, &f->offset) < 0 || !isfinite(f->scale) ||
             !isfinite(f->offset)))
            return bad(c, n, "scale '%s' or offset '%s' is not a finite number",
                       e57_attr(n, "scale") ? e57_attr(n, "scale") : "",
                       e57_attr(n, "offset") ? e57_attr(n, "offset") : "");
    } else if (!strcmp(n->type, "Float")) {
        const char *prec = e57_attr(n, "precision");
        if (!prec || !strcmp(prec, "double"))
            f->kind = E57_DOUBLE, f->bits = 64;
        else if (!strcmp(prec, "single"))
            f->kind = E57_FLOAT, f->bits = 32;
        else
            return bad(c, n, "precision '%s' (want single or double)%s", prec, "");
        if (parse_f64(e57_attr(n, "minimum"), -HUGE_VAL, &f->fmin) < 0 ||
            parse_f64(e57_attr(n, "maximum"), HUGE_VAL, &f->fmax) < 0)
            return bad(c, n, "minimum or maximum is not a number%s%s", "", "");
    } else {
        return bad(c, n,
                   "type '%s' in a prototype (want Integer, ScaledInteger, Float, "
                   "Structure or Vector)%s",
                   n->type, "");
    }
    if (depth == 0 && n->ns != E57_NS_OTHER)
        for (int r = 0; r < E57_R_COUNT; r++) {
            int normal = r == E57_R_NX || r == E57_R_NY || r == E57_R_NZ;
            if ((n->ns == E57_NS_NOR) != normal || strcmp(n->name, role_names[r])) continue;
            if (s->role[r] >= 0) return bad(c, n, "a second <%s> in the prototype%s", n->name, "");
            s->role[r] = (int)s->nfields - 1;
            f->role = r;
        }
    return 0;
}

/* bounds_of: the value range of field f ([lo, hi]; 0 when it has no finite one). */
static int bounds_of(const e57_field *f, double *lo, double *hi)
{
    if (f->kind == E57_INTEGER || f->kind == E57_SCALED) {
        double a = (double)f->min * f->scale + f->offset, b = (double)f->max * f->scale + f->offset;
        *lo = a < b ? a : b;
        *hi = a < b ? b : a;
    } else {
        *lo = f->fmin;
        *hi = f->fmax;
    }
    return isfinite(*lo) && isfinite(*hi) && *hi > *lo;
}

static int pose(ctx *c, e57_scan *s, const e57_node *sn)
{
    double q[4] = {1, 0, 0, 0};
    for (int i = 0; i < 9; i++) s->rot[i] = i % 4 == 0;
    const e57_node *p = e57_child(sn, "pose");
    if (!p) return 0;
    const e57_node *r = e57_child(p, "rotation"), *t = e57_child(p, "translation");
    static const char *const qn[4] = {"w", "x", "y", "z"}, *const tn[3] = {"x", "y", "z"};
    int rc = 0;
    for (int i = 0; i < 4 && r && rc == 0; i++) rc = opt_number(c, r, qn[i], i == 0, &q[i]);
    for (int i = 0; i < 3 && t && rc == 0; i++) rc = opt_number(c, t, tn[i], 0.0, &s->trans[i]);
    if (rc < 0) return rc;
    double len = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(len > 1e-12) || !isfinite(len))
        return bad(c, r, "the rotation quaternion has length %s%s", len == 0 ? "0" : "not finite",
                   "");
    double w = q[0] / len, x = q[1] / len, y = q[2] / len, z = q[3] / len;
    double m[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                   2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                   2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    memcpy(s->rot, m, sizeof m);
    return 0;
}

/* limits: intensity and colour ranges from intensityLimits / colorLimits, else the prototype
 * (its fields f). */
static int limits(ctx *c, e57_scan *s, const e57_node *sn, const e57_field *f)
{
    int rc = 0;
    if (s->has_intensity) {
        const e57_node *l = e57_child(sn, "intensityLimits");
        double lo = 0, hi = 0;
        if (l && (rc = opt_number(c, l, "intensityMinimum", 0.0, &lo)) == 0)
            rc = opt_number(c, l, "intensityMaximum", 0.0, &hi);
        if (rc < 0) return rc;
        if ((!l || !(hi > lo)) && !bounds_of(&f[s->role[E57_R_INTENSITY]], &lo, &hi)) lo = hi = 0;
        s->ilo = lo;
        s->ihi = hi;
    }
    if (s->has_color) {
        static const char *const mn[3] = {"colorRedMinimum", "colorGreenMinimum",
                                          "colorBlueMinimum"};
        static const char *const mx[3] = {"colorRedMaximum", "colorGreenMaximum",
                                          "colorBlueMaximum"};
        const e57_node *l = e57_child(sn, "colorLimits");
        for (int k = 0; k < 3; k++) {
            double lo = 0, hi = 0;
            if (l && (rc = opt_number(c, l, mn[k], 0.0, &lo)) == 0)
                rc = opt_number(c, l, mx[k], 0.0, &hi);
            if (rc < 0) return rc;
            if ((!l || !(hi > lo)) && !bounds_of(&f[s->role[E57_R_RED + k]], &lo, &hi))
                lo = 0, hi = 255;
            s->clo[k] = lo;
            s->chi[k] = hi;
        }
    }
    return 0;
}

/* codecs: 0 when every codec entry is the bit-pack codec (an empty vector is the default). */
static int codecs(ctx *c, const e57_scan *s, const e57_node *pts)
{
    const e57_node *cv = e57_child(pts, "codecs");
    for (const e57_node *k = cv ? cv->child : NULL; k; k = k->next)
        if (!e57_child(k, "bitPackCodec"))
            return sd_errf(c->err, SD_EUNSUP,
                           "%s: line %lu: scan %u: a codec other than the "
                           "bit-pack codec (the only one E2807 defines)",
                           c->what, k->line, s->index);
    return 0;
}

static int scan(ctx *c, e57_scan *s, const e57_node *sn)
{
    s->line = sn->line;
    for (int r = 0; r < E57_R_COUNT; r++) s->role[r] = -1;
    const e57_node *pts = e57_child(sn, "points");
    if (!pts || strcmp(pts->type, "CompressedVector"))
        return bad(c, sn, "scan has no <points> CompressedVector%s%s", "", "");
    if (parse_u64(e57_attr(pts, "fileOffset"), &s->cv_offset) < 0)
        return bad(c, pts, "fileOffset '%s' is not an unsigned integer%s",
                   e57_attr(pts, "fileOffset") ? e57_attr(pts, "fileOffset") : "(absent)", "");
    if (parse_u64(e57_attr(pts, "recordCount"), &s->records) < 0)
        return bad(c, pts, "recordCount '%s' is not an unsigned integer%s",
                   e57_attr(pts, "recordCount") ? e57_attr(pts, "recordCount") : "(absent)", "");
    const e57_node *proto = e57_child(pts, "prototype");
    if (!proto || strcmp(proto->type, "Structure"))
        return bad(c, pts, "no <prototype> Structure%s%s", "", "");
    int rc = codecs(c, s, pts);
    uint32_t first = c->nfields;
    for (const e57_node *k = proto->child; k && rc == 0; k = k->next) rc = leaf(c, s, k, 0);
    if (rc < 0) return rc;
    s->field0 = first;
    const int *ro = s->role;
    if (ro[E57_R_CX] >= 0 && ro[E57_R_CY] >= 0 && ro[E57_R_CZ] >= 0)
        s->coords = E57_CARTESIAN;
    else if (ro[E57_R_RANGE] >= 0 && ro[E57_R_AZIMUTH] >= 0 && ro[E57_R_ELEVATION] >= 0)
        s->coords = E57_SPHERICAL;
    else
        return sd_errf(c->err, SD_EFORMAT,
                       "%s: line %lu: scan %u: the prototype has neither "
                       "cartesianX/Y/Z nor sphericalRange/Azimuth/Elevation: no coordinates",
                       c->what, proto->line, s->index);
    s->has_intensity = ro[E57_R_INTENSITY] >= 0;
    s->has_color = ro[E57_R_RED] >= 0 && ro[E57_R_GREEN] >= 0 && ro[E57_R_BLUE] >= 0;
    s->has_normals = ro[E57_R_NX] >= 0 && ro[E57_R_NY] >= 0 && ro[E57_R_NZ] >= 0;
    rc = limits(c, s, sn, c->d->fields + first);
    return rc < 0 ? rc : pose(c, s, sn);
}

int e57_desc_read(const e57_node *root, e57_desc *d, const char *what, sd_err *err)
{
    memset(d, 0, sizeof *d);
    ctx c = {.what = what, .err = err, .d = d};
    if (!root || strcmp(root->name, "e57Root") || root->ns != E57_NS_E57)
        return sd_errf(err, SD_EFORMAT, "%s: the document element is <%s>, not <e57Root>", what,
                       root ? root->name : "(none)");
    const e57_node *d3 = e57_child(root, "data3D"), *im = e57_child(root, "images2D");
    for (const e57_node *k = im ? im->child : NULL; k; k = k->next) d->nimages++;
    uint32_t n = 0;
    for (const e57_node *k = d3 ? d3->child : NULL; k; k = k->next) n++;
    if (n > E57_MAX_SCANS)
        return sd_errf(err, SD_ELIMIT, "%s: %u scans in /data3D, more than %d", what, n,
                       E57_MAX_SCANS);
    d->scans = calloc(n ? n : 1, sizeof *d->scans);
    if (!d->scans) return sd_errf(err, SD_ENOMEM, "%s: out of memory", what);
    int rc = 0;
    for (const e57_node *k = d3 ? d3->child : NULL; k && rc == 0; k = k->next) {
        e57_scan *s = &d->scans[d->nscans];
        s->index = d->nscans++;
        rc = strcmp(k->type, "Structure") ? bad(&c, k,
                                                "a /data3D child of type '%s', not "
                                                "Structure%s",
                                                k->type, "")
                                          : scan(&c, s, k);
    }
    /* the field array is final: point each scan at its fields */
    for (uint32_t i = 0; i < d->nscans && rc == 0; i++)
        d->scans[i].fields = d->fields + d->scans[i].field0;
    if (rc < 0) e57_desc_free(d);
    return rc;
}

void e57_desc_free(e57_desc *d)
{
    free(d->scans);
    free(d->fields);
    memset(d, 0, sizeof *d);
}
