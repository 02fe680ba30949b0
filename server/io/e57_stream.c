/* e57_stream.c — E57 scans as a stream of posed points (e57_stream.h). */
#include "e57_stream.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "cloud.h"
#include "e57_cv.h"
#include "e57_pages.h"
#include "e57_scan.h"
#include "e57_xml.h"

enum { BATCH = 4096, XML_CHUNK = 1 << 16 };

struct pc_e57_stream {
    e57_file f;
    e57_desc d;
    uint32_t attrs;
    uint64_t bound;
    char format[64];
    /* the scan being read */
    uint32_t cur;
    e57_cv *cv;
    double **cols; /* per field of the scan: a column of BATCH values, NULL when unused */
    double *colbuf; /* the columns' storage: BATCH per used field */
};

int pc_e57_signature(const char *path)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return 0;
    char sig[8];
    ssize_t g = pread(fd, sig, sizeof sig, 0);
    close(fd);
    return g == (ssize_t)sizeof sig && !memcmp(sig, "ASTM-E57", 8);
}

/* is_e57: 1 when path ends in .e57 (any case) or starts with the signature. */
static int is_e57(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(slash ? slash : path, '.');
    return (dot && !strcasecmp(dot, ".e57")) || pc_e57_signature(path);
}

/* read_xml: the XML section, page run by page run, through expat into the scan list. */
static int read_xml(pc_e57_stream *s, sd_err *err)
{
    e57_file *f = &s->f;
    char what[4200];
    snprintf(what, sizeof what, "%s: the XML section at physical offset %llu", f->path,
             (unsigned long long)f->xml_off);
    e57_xml *x = e57_xml_new();
    char *buf = malloc(XML_CHUNK);
    int rc = x && buf ? 0 : sd_errf(err, SD_ENOMEM, "%s: out of memory", f->path);
    uint64_t phys = f->xml_off, left = f->xml_len;
    while (rc == 0 && left > 0) {
        size_t m = left < XML_CHUNK ? (size_t)left : XML_CHUNK;
        rc = e57_file_read(f, phys, buf, m, err);
        if (rc == 0) rc = e57_xml_feed(x, buf, m, m == left, what, err);
        phys = e57_phys_advance(f, phys, m);
        left -= m;
    }
    if (rc == 0) rc = e57_desc_read(e57_xml_root(x), &s->d, what, err);
    free(buf);
    e57_xml_free(x);
    return rc;
}

/* used: 1 when field i of scan sc is read for the points the stream hands out. */
static int used(const pc_e57_stream *s, const e57_scan *sc, uint32_t i)
{
    int r = sc->fields[i].role;
    if (sc->coords == E57_CARTESIAN) {
        if (r == E57_R_CX || r == E57_R_CY || r == E57_R_CZ || r == E57_R_CART_INVALID) return 1;
    } else if (r == E57_R_RANGE || r == E57_R_AZIMUTH || r == E57_R_ELEVATION ||
               r == E57_R_SPH_INVALID) {
        return 1;
    }
    if (r == E57_R_INTENSITY || r == E57_R_INTENSITY_INVALID) return sc->has_intensity;
    if (r == E57_R_RED || r == E57_R_GREEN || r == E57_R_BLUE || r == E57_R_COLOR_INVALID)
        return sc->has_color;
    if (r == E57_R_NX || r == E57_R_NY || r == E57_R_NZ) return (s->attrs & PC_ATTR_NORMAL) != 0;
    return 0;
}

typedef struct span {
    uint64_t lo, hi; /* physical offsets: a compressed vector section */
    uint32_t scan;
} span;

static int cmp_span(const void *a, const void *b)
{
    const span *x = a, *y = b;
    return x->lo < y->lo ? -1 : x->lo > y->lo;
}

/* overlaps: 0 when no two scans' sections share a byte (each scan's points then come from bytes
 * of their own, so the points a file gives are bounded by its size); else SD_EFORMAT. */
static int overlaps(const pc_e57_stream *s, span *sp, uint32_t n, sd_err *err)
{
    qsort(sp, n, sizeof *sp, cmp_span);
    for (uint32_t i = 1; i < n; i++)
        if (sp[i].lo < sp[i - 1].hi)
            return sd_errf(err, SD_EFORMAT, "%s: the compressed vectors of scans %u (physical "
                           "offsets %llu to %llu) and %u (from %llu) overlap", s->f.path,
                           sp[i - 1].scan, (unsigned long long)sp[i - 1].lo,
                           (unsigned long long)sp[i - 1].hi, sp[i].scan,
                           (unsigned long long)sp[i].lo);
    return 0;
}

/* check_scans: every compressed vector's section header (no two overlapping), the attributes
 * and the bound. */
static int check_scans(pc_e57_stream *s, sd_err *err)
{
    uint32_t normals = 1, with_records = 0;
    for (uint32_t i = 0; i < s->d.nscans; i++) {
        const e57_scan *sc = &s->d.scans[i];
        if (sc->has_color) s->attrs |= PC_ATTR_RGB;
        if (sc->has_intensity) s->attrs |= PC_ATTR_INTENSITY;
        if (sc->records) with_records++, normals &= (uint32_t)sc->has_normals;
    }
    if (with_records && normals) s->attrs |= PC_ATTR_NORMAL;
    if (s->d.nscans > 1) s->attrs |= PC_ATTR_SCAN;
    span *sp = malloc((s->d.nscans ? s->d.nscans : 1) * sizeof *sp);
    if (!sp) return sd_errf(err, SD_ENOMEM, "%s: out of memory", s->f.path);
    int rc = 0;
    uint32_t nsp = 0;
    for (uint32_t i = 0; i < s->d.nscans && rc == 0; i++) {
        const e57_scan *sc = &s->d.scans[i];
        e57_cv *cv;
        if ((rc = e57_cv_open(&s->f, sc, &cv, err)) < 0) break;
        uint64_t bytes = e57_cv_logical_len(cv);
        e57_cv_close(cv);
        if (sc->records) /* an empty scan's section is never read */
            sp[nsp++] = (span){sc->cv_offset, e57_phys_advance(&s->f, sc->cv_offset, bytes), i};
        uint64_t bits = 0;
        for (uint32_t k = 0; k < sc->nfields; k++)
            if (used(s, sc, k)) bits += (uint64_t)sc->fields[k].bits;
        /* a record of 0 bits (every field read a constant) takes no room: such a scan may not
         * claim more records than its section has bits */
        uint64_t cap = bytes > UINT64_MAX / 8 ? UINT64_MAX : 8 * bytes;
        if (!bits && sc->records > cap) {
            rc = sd_errf(err, SD_EFORMAT,
                           "%s: scan %u (XML line %lu): %llu records of 0 bits "
                           "each in a compressed vector of %llu bytes: refused",
                         s->f.path, i, sc->line, (unsigned long long)sc->records,
                         (unsigned long long)bytes);
            break;
        }
        uint64_t fit = bits ? cap / bits : cap;
        uint64_t b = sc->records < fit ? sc->records : fit;
        s->bound = b > UINT64_MAX - s->bound ? UINT64_MAX : s->bound + b;
    }
    if (rc == 0) rc = overlaps(s, sp, nsp, err);
    free(sp);
    if (rc < 0) return rc;
    snprintf(s->format, sizeof s->format, "E57 %u.%u, %u scan%s", s->f.major, s->f.minor,
             s->d.nscans, s->d.nscans == 1 ? "" : "s");
    return 0;
}

int pc_e57_stream_open(const char *path, pc_e57_stream **out, sd_err *err)
{
    *out = NULL;
    if (!is_e57(path)) return 0;
    pc_e57_stream *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    int rc = e57_file_open(path, &s->f, err);
    if (rc == 0) rc = read_xml(s, err);
    if (rc == 0 && s->d.nscans == 0)
        rc = sd_errf(err, SD_EEMPTY,
                     "%s: no scans: /data3D is %s (%u images in /images2D, "
                     "which are not read)",
                     path, "empty or absent", s->d.nimages);
    if (rc == 0) rc = check_scans(s, err);
    if (rc < 0) {
        pc_e57_stream_close(s);
        return rc;
    }
    *out = s;
    return 1;
}

/* close_scan: the current scan's reader and columns. */
static void close_scan(pc_e57_stream *s)
{
    e57_cv_close(s->cv);
    s->cv = NULL;
    free(s->cols);
    free(s->colbuf);
    s->cols = NULL;
    s->colbuf = NULL;
}

void pc_e57_stream_close(pc_e57_stream *s)
{
    if (!s) return;
    close_scan(s);
    e57_desc_free(&s->d);
    e57_file_close(&s->f);
    free(s);
}

void pc_e57_stream_rewind(pc_e57_stream *s)
{
    close_scan(s);
    s->cur = 0;
}

uint32_t pc_e57_stream_attrs(const pc_e57_stream *s)
{
    return s->attrs;
}
uint64_t pc_e57_stream_bound(const pc_e57_stream *s)
{
    return s->bound;
}
uint32_t pc_e57_stream_scans(const pc_e57_stream *s)
{
    return s->d.nscans;
}

uint64_t pc_e57_stream_records(const pc_e57_stream *s)
{
    uint64_t n = 0;
    for (uint32_t i = 0; i < s->d.nscans; i++)
        n = s->d.scans[i].records > UINT64_MAX - n ? UINT64_MAX : n + s->d.scans[i].records;
    return n;
}
const char *pc_e57_stream_format(const pc_e57_stream *s)
{
    return s->format;
}
uint64_t pc_e57_stream_pages_checked(const pc_e57_stream *s)
{
    return s->f.pages_checked;
}

/* open_scan: the reader and the columns of scan s->cur. */
static int open_scan(pc_e57_stream *s, sd_err *err)
{
    const e57_scan *sc = &s->d.scans[s->cur];
    uint32_t nused = 0;
    for (uint32_t i = 0; i < sc->nfields; i++) nused += (uint32_t)used(s, sc, i);
    s->cols = calloc(sc->nfields ? sc->nfields : 1, sizeof *s->cols);
    s->colbuf = malloc((size_t)(nused ? nused : 1) * BATCH * sizeof *s->colbuf);
    if (!s->cols || !s->colbuf) return sd_errf(err, SD_ENOMEM, "%s: out of memory", s->f.path);
    for (uint32_t i = 0, k = 0; i < sc->nfields; i++)
        if (used(s, sc, i)) s->cols[i] = s->colbuf + (size_t)BATCH * k++;
    return e57_cv_open(&s->f, sc, &s->cv, err);
}

/* to8: colour value v mapped from [lo, hi] to 0-255, rounded to nearest (a division, not a
 * multiplication by 255 / (hi - lo): a half lands on the half). */
static uint8_t to8(double v, double lo, double hi)
{
    double x = (v - lo) * 255.0 / (hi - lo);
    if (!(x > 0)) return 0;
    return x >= 255 ? 255 : (uint8_t)(x + 0.5);
}

/* emit: the m records of the batch as points at out[k...]; returns the points kept. */
static size_t emit(const pc_e57_stream *s, const e57_scan *sc, size_t m, const pc_e57_points *o,
                   size_t k)
{
    const int *ro = sc->role;
    double *const *c = s->cols;
    const int cart = sc->coords == E57_CARTESIAN;
    const double *a = c[ro[cart ? E57_R_CX : E57_R_RANGE]];
    const double *b = c[ro[cart ? E57_R_CY : E57_R_AZIMUTH]];
    const double *e = c[ro[cart ? E57_R_CZ : E57_R_ELEVATION]];
    int inv_role = cart ? E57_R_CART_INVALID : E57_R_SPH_INVALID;
    const double *inv = ro[inv_role] >= 0 ? c[ro[inv_role]] : NULL;
    const double *R = sc->rot, *T = sc->trans;
    /* colours and intensities are written whenever asked for (white, 0 where the scan has
     * none); normals only when every scan has them */
    const double *col[3] = {NULL, NULL, NULL}, *cbad = NULL, *in = NULL, *ibad = NULL;
    if (sc->has_color) {
        for (int r = 0; r < 3; r++) col[r] = c[ro[E57_R_RED + r]];
        if (ro[E57_R_COLOR_INVALID] >= 0) cbad = c[ro[E57_R_COLOR_INVALID]];
    }
    if (sc->has_intensity) {
        in = c[ro[E57_R_INTENSITY]];
        if (ro[E57_R_INTENSITY_INVALID] >= 0) ibad = c[ro[E57_R_INTENSITY_INVALID]];
    }
    const double ilo = sc->ilo, iscale = sc->ihi > sc->ilo ? 1.0 / (sc->ihi - sc->ilo) : 0.0;
    const int nrm = (s->attrs & PC_ATTR_NORMAL) && o->normal;
    size_t kept = 0;
    for (size_t i = 0; i < m; i++) {
        if (inv && inv[i] != 0) continue; /* 1: direction only, 2: invalid (e57_stream.h) */
        double p[3];
        if (cart) {
            p[0] = a[i], p[1] = b[i], p[2] = e[i];
        } else {
            double ce = cos(e[i]);
            p[0] = a[i] * ce * cos(b[i]);
            p[1] = a[i] * ce * sin(b[i]);
            p[2] = a[i] * sin(e[i]);
        }
        size_t j = k + kept++;
        if (o->xyz)
            for (int r = 0; r < 3; r++)
                o->xyz[3 * j + r] =
                    R[3 * r] * p[0] + R[3 * r + 1] * p[1] + R[3 * r + 2] * p[2] + T[r];
        if (o->rgba) {
            uint8_t *q = o->rgba + 4 * j;
            int white = !col[0] || (cbad && cbad[i] != 0);
            for (int r = 0; r < 3; r++)
                q[r] = white ? 255 : to8(col[r][i], sc->clo[r], sc->chi[r]);
            q[3] = 255;
        }
        if (o->intensity) {
            double x = in && !(ibad && ibad[i] != 0) ? in[i] : 0.0;
            if (in && iscale > 0) {
                x = (x - ilo) * iscale;
                x = x > 0 ? (x < 1 ? x : 1) : 0;
            }
            o->intensity[j] = (float)x;
        }
        if (nrm) {
            double n[3], w[3];
            for (int r = 0; r < 3; r++) n[r] = c[ro[E57_R_NX + r]][i];
            for (int r = 0; r < 3; r++)
                w[r] = R[3 * r] * n[0] + R[3 * r + 1] * n[1] + R[3 * r + 2] * n[2];
            double len = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
            for (int r = 0; r < 3; r++)
                o->normal[3 * j + r] = len > 0 ? (float)(w[r] / len) : 0.0f;
        }
        if (o->scan) o->scan[j] = (uint16_t)sc->index;
    }
    return kept;
}

int64_t pc_e57_stream_next(pc_e57_stream *s, const pc_e57_points *out, size_t max, sd_err *err)
{
    size_t k = 0;
    while (k < max && s->cur < s->d.nscans) {
        if (!s->cv) {
            int rc = open_scan(s, err);
            if (rc < 0) {
                close_scan(s);
                return rc;
            }
        }
        size_t want = max - k < BATCH ? max - k : BATCH;
        int64_t m = e57_cv_read(s->cv, s->cols, want, err);
        if (m < 0) return m;
        if (m == 0) {
            close_scan(s);
            s->cur++;
            continue;
        }
        k += emit(s, &s->d.scans[s->cur], (size_t)m, out, k);
    }
    return (int64_t)k;
}
