/* view.c — a cloud's default view (view.h). */
#include "view.h"

#include "lod.h"
#include "prepared.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

int view_rule(const char *format)
{
    static const char *zup[] = {"LAS", "LAZ", "COPC", "E57"};
    for (size_t i = 0; i < sizeof zup / sizeof zup[0]; i++) {
        size_t n = strlen(zup[i]);
        if (!strncasecmp(format, zup[i], n) && (format[n] == ' ' || format[n] == 0)) return SP_UP_Z;
    }
    if (!strncasecmp(format, "PCD", 3) && (format[3] == ' ' || format[3] == 0)) return SP_UP_SENSOR;
    return SP_UP_GUESS;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

void view_box(const float *pos, uint64_t n, const double offset[3], const double bmin[3],
              const double bmax[3], double vmin[3], double vmax[3])
{
    memcpy(vmin, bmin, 3 * sizeof(double));
    memcpy(vmax, bmax, 3 * sizeof(double));
    uint64_t m = n < VIEW_SAMPLE ? n : VIEW_SAMPLE;
    if (m < 16) return; /* too few points to call any of them an outlier */
    float *v = malloc(m * sizeof *v);
    if (!v) return;
    for (int a = 0; a < 3; a++) {
        for (uint64_t i = 0; i < m; i++) v[i] = pos[3 * (i * n / m) + a];
        qsort(v, m, sizeof *v, cmp_float);
        uint64_t lo = (uint64_t)(VIEW_TRIM * (double)(m - 1)), hi = m - 1 - lo;
        double qlo = v[lo] + offset[a], qhi = v[hi] + offset[a];
        double ext = qhi - qlo;
        /* a gap to the true end under half the trimmed extent is the cloud's own (a roof's
         * top): keep the bound there; a larger one holds outliers only */
        vmin[a] = bmin[a] >= qlo - 0.5 * ext ? bmin[a] : qlo;
        vmax[a] = bmax[a] <= qhi + 0.5 * ext ? bmax[a] : qhi;
    }
    free(v);
}

void view_make(const char *fmt, const double bmin[3], const double bmax[3], const double vmin[3],
               const double vmax[3], const double *q, sp_view *v)
{
    (void)bmin, (void)bmax;
    /* the rule reads the cloud's shape and georeference from the framed box: an outlier does
     * not make a terrain look tall */
    sp_view_default(vmin, vmax, view_rule(fmt), q, v);
}

/* view_of_sample: the view of a cloud of format fmt, bounds bmin..bmax and sensor rotation q
 * (NULL: none) from n positions spread over it (local coordinates: file = local + offset). */
static void view_of_sample(const char *fmt, const float *pos, uint64_t n, const double offset[3],
                           const double bmin[3], const double bmax[3], const double *q, sp_view *v)
{
    double vmin[3], vmax[3];
    view_box(pos, n, offset, bmin, bmax, vmin, vmax);
    view_make(fmt, bmin, bmax, vmin, vmax, q, v);
    uint64_t m = n < VIEW_SAMPLE ? n : VIEW_SAMPLE;
    double *p = m ? malloc(3 * m * sizeof *p) : NULL;
    if (!p) return; /* the box's corners serve */
    for (uint64_t i = 0; i < m; i++)
        for (int a = 0; a < 3; a++) p[3 * i + a] = (double)pos[3 * (i * n / m) + a] + offset[a];
    sp_view_hull(v, p, m);
    free(p);
}

void view_of_prepared(const pc_prepared *p, sp_view *v)
{
    view_of_sample(p->format, p->pos, p->n, p->offset, p->bmin, p->bmax,
                   p->has_sensor_q ? p->sensor_q : NULL, v);
}

void view_of_lod(const lod_cloud *c, sp_view *v)
{
    /* the top nodes, breadth first, until VIEW_SAMPLE points: a uniform sample of the cloud */
    uint64_t n = 0, i = 0;
    while (i < c->nnodes && n < VIEW_SAMPLE) n += c->nodes[i++].count;
    float *pos = n ? malloc(3 * n * sizeof *pos) : NULL;
    if (pos) {
        uint64_t at = 0;
        for (uint64_t j = 0; j < i; j++) {
            lod_node_data d;
            lod_node_get(c, j, &d);
            memcpy(pos + 3 * at, d.pos, 3 * sizeof(float) * c->nodes[j].count);
            at += c->nodes[j].count;
        }
    }
    view_of_sample(c->format, pos, pos ? n : 0, c->offset, c->bmin, c->bmax,
                   c->has_sensor_q ? c->sensor_q : NULL, v);
    free(pos);
}
