/* prep.c — preprocessing orchestration; see prep.h for the steps and rules. */
#include "prep.h"

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "morton.h"
#include "pca.h"
#include "simd.h"

enum { CHUNK = 16384 }; /* queries per parallel work unit */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- selection ---- */

enum { SMALL_MAX = 64 };

/* The value of rank want among the n <= SMALL_MAX values v (a neighbourhood's radii: called
 * once a point), by counting for 8 values at a time how many are smaller and how many equal:
 * the value quickselect finds, without its data-dependent branches. 0 when v holds a NaN (the
 * caller falls back to quickselect). */
PREP_CLONES static int select_small(const float *v, size_t n, size_t want, float *out)
{
    prep_v8f a[SMALL_MAX / 8];
    size_t nv = (n + 7) / 8;
    float *f = (float *)a;
    for (size_t j = 0; j < n; j++)
        if (v[j] != v[j]) return 0;
    memcpy(f, v, n * sizeof *v);
    for (size_t j = n; j < nv * 8; j++) f[j] = NAN; /* neither smaller nor equal to anything */
    const prep_v8i zero = {0, 0, 0, 0, 0, 0, 0, 0}, w = zero + (int)want;
    for (size_t b = 0; b < nv; b++) {
        prep_v8i lt = zero, eq = zero;
        for (size_t j = 0; j < n; j++) {
            const prep_v8f x = (prep_v8f){0, 0, 0, 0, 0, 0, 0, 0} + v[j];
            lt -= x < a[b]; /* true lanes are -1 */
            eq -= x == a[b];
        }
        prep_v8i hit = (lt <= w) & (w < lt + eq);
        for (int l = 0; l < 8; l++)
            if (hit[l]) {
                *out = f[8 * b + (size_t)l];
                return 1;
            }
    }
    return 0;
}

float prep_percentile(float *v, size_t n, double q)
{
    if (n == 0) return 0;
    if (!(q >= 0)) q = 0;
    if (q > 1) q = 1;
    ptrdiff_t want = (ptrdiff_t)floor(q * (double)(n - 1) + 0.5);
    float r;
    if (n <= SMALL_MAX && select_small(v, n, (size_t)want, &r)) return r;
    ptrdiff_t lo = 0, hi = (ptrdiff_t)n - 1;
    /* Quickselect with Hoare partitioning around a median of three; scans stop on elements
     * equal to the pivot, so runs of equal values (regular grids, clamped F) stay O(n). */
    while (lo < hi) {
        ptrdiff_t mid = lo + (hi - lo) / 2;
        float a = v[lo], b = v[mid], c = v[hi];
        float piv = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        ptrdiff_t i = lo, j = hi;
        while (i <= j) {
            while (v[i] < piv) i++;
            while (v[j] > piv) j--;
            if (i <= j) {
                float t = v[i]; v[i] = v[j]; v[j] = t;
                i++;
                j--;
            }
        }
        /* now v[lo..j] <= piv, v[j+1..i-1] == piv, v[i..hi] >= piv */
        if (want <= j) hi = j;
        else if (want >= i) lo = i;
        else return v[want];
    }
    return v[want];
}

/* ---- the job shared by the workers ---- */

typedef struct worker {
    prep_knn_scratch *ks;
    uint32_t *idx;          /* CHUNK * K, when neighbour lists are not kept */
    float *d2;              /* CHUNK * K */
    double t_query, t_normal, t_radius, t_field;
} worker;

typedef struct job {
    pc_prepared *p;
    const prep_knn *kn;
    int K;
    uint32_t *nbr;          /* n * K kept neighbour lists, or NULL */
    float *nnd;             /* n nearest-neighbour distances */
    float *rcap;            /* n radius limits (computed radii only), or NULL */
    float *svar;            /* n surface variations (computed radii only), or NULL */
    float scatter_cap;      /* radius limit of points whose neighbourhood is no surface */
    int need_normal, need_radius;
    double centroid[3];
    int has_vp;             /* orient towards vp (the sensor, local coordinates) */
    double vp[3];
    worker *w;
} job;

/* Orients the unit normal n of point p by the rule of prep.h: towards the sensor at vp when
 * has_vp, else away from the centroid c; where that direction says little (n within 10 degrees
 * of perpendicular to it), up. */
void prep_orient_normal(float n[3], const float p[3], const double c[3], int has_vp,
                        const double vp[3])
{
    double u[3];
    for (int a = 0; a < 3; a++) u[a] = has_vp ? vp[a] - p[a] : p[a] - c[a];
    double d = n[0] * u[0] + n[1] * u[1] + n[2] * u[2];
    double ul = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    int flip;
    if (fabs(d) >= 0.17364817766693 * ul && ul > 0) /* cos 80 degrees */
        flip = d < 0;
    else if (fabs(n[2]) >= 0.1f)
        flip = n[2] < 0;
    else if (fabs(n[1]) >= 0.1f)
        flip = n[1] < 0;
    else
        flip = n[0] < 0;
    if (flip) {
        n[0] = -n[0];
        n[1] = -n[1];
        n[2] = -n[2];
    }
}

/* The chunk's neighbour lists: the kept ones, or a fresh query into the worker's buffer. */
static int chunk_neighbours(job *jb, worker *w, size_t first, size_t m, int query,
                            uint32_t **idx, sd_err *err)
{
    *idx = jb->nbr ? jb->nbr + first * (size_t)jb->K : w->idx;
    if (!query) return 0;
    double t0 = now_s();
    int rc = prep_knn_query(jb->kn, NULL, first, m, jb->K, *idx, w->d2, w->ks, err);
    w->t_query += now_s() - t0;
    return rc;
}

/* Phase 1 for one chunk: kNN, nearest distance, radius and normal of its points. */
static int chunk_normals(void *ctx, size_t c, int tid, sd_err *err)
{
    job *jb = ctx;
    worker *w = &jb->w[tid];
    pc_prepared *p = jb->p;
    size_t first = c * CHUNK, m = p->n - first < CHUNK ? p->n - first : CHUNK;
    int K = jb->K;
    uint32_t *idx;
    int rc = chunk_neighbours(jb, w, first, m, 1, &idx, err);
    if (rc != 0) return rc;
    double t0 = now_s();
    float inv_sqrt_k = (float)(1.0 / sqrt((double)K));
    for (size_t i = 0; i < m; i++) {
        const float *d = w->d2 + i * (size_t)K;
        jb->nnd[first + i] = sqrtf(d[0]);
        if (jb->need_radius) p->radius[first + i] = 2.0f * sqrtf(d[K - 1]) * inv_sqrt_k;
    }
    double t1 = now_s();
    w->t_radius += t1 - t0;
    if (jb->need_normal || jb->svar) {
        for (size_t i = 0; i < m; i++) {
            size_t pi = first + i;
            float scratch[3];
            float *n = jb->need_normal ? p->normal + 3 * pi : scratch;
            prep_pca_normal(p->pos, (uint32_t)pi, idx + i * (size_t)K, K, n,
                            jb->svar ? jb->svar + pi : NULL);
            if (jb->need_normal) prep_orient_normal(n, p->pos + 3 * pi, jb->centroid, jb->has_vp, jb->vp);
        }
        w->t_normal += now_s() - t1;
    }
    return 0;
}

/* Phase 2 for one chunk: raw F (eq. 21) into p->F. */
static int chunk_field(void *ctx, size_t c, int tid, sd_err *err)
{
    job *jb = ctx;
    worker *w = &jb->w[tid];
    pc_prepared *p = jb->p;
    size_t first = c * CHUNK, m = p->n - first < CHUNK ? p->n - first : CHUNK;
    int K = jb->K;
    uint32_t *idx;
    int rc = chunk_neighbours(jb, w, first, m, jb->nbr == NULL, &idx, err);
    if (rc != 0) return rc;
    double t0 = now_s();
    for (size_t i = 0; i < m; i++) {
        size_t pi = first + i;
        const float *ni = p->normal + 3 * pi;
        const uint32_t *nb = idx + i * (size_t)K;
        float s = 0;
        for (int j = 0; j < K; j++) {
            const float *nj = p->normal + 3 * (size_t)nb[j];
            float dd = fabsf(ni[0] * nj[0] + ni[1] * nj[1] + ni[2] * nj[2]);
            if (dd > 1) dd = 1; /* file normals may be slightly off unit length */
            float t = 2 - dd;
            s += t * t;
        }
        if (jb->rcap) {
            /* the median radius of the neighbours: an isolated outlier's own eq. 20 radius
             * reaches to the surface it strays from, its neighbours' radii do not */
            float rn[PREP_MAX_K];
            for (int j = 0; j < K; j++) rn[j] = p->radius[nb[j]];
            float cap = PREP_RADIUS_CAP * prep_percentile(rn, (size_t)K, 0.5);
            if (jb->svar[pi] > PREP_SURFACE_VAR_MAX && cap > jb->scatter_cap)
                cap = jb->scatter_cap;
            jb->rcap[pi] = cap;
        }
        float f = p->radius[pi] * s / (float)K;
        /* a file's radius or normal may be non-finite or negative: such a point gets F = 0
         * rather than poisoning the percentiles */
        p->F[pi] = f >= 0 && f <= FLT_MAX ? f : 0.0f;
    }
    w->t_field += now_s() - t0;
    return 0;
}

/* ---- steps ---- */

/* Checks the cloud and the desc; fills d with defaults. */
static int check_input(const pc_cloud *in, const prep_desc *desc, prep_desc *d, sd_err *err)
{
    *d = desc ? *desc : (prep_desc){0};
    if (d->k == 0) d->k = PREP_DEFAULT_K;
    if (d->threads <= 0) d->threads = prep_default_threads();
    if (d->max_nbr_bytes == 0) d->max_nbr_bytes = (size_t)1 << 30;
    if (!in) return sd_errf(err, SD_EINVAL, "prep: no cloud given");
    if (d->k < 1 || d->k > PREP_MAX_K)
        return sd_errf(err, SD_EINVAL, "prep: k = %d neighbours is outside [1, 256]", d->k);
    if (d->knn != PREP_KNN_GRID && d->knn != PREP_KNN_FLANN)
        return sd_errf(err, SD_EINVAL, "prep: unknown kNN method %d", (int)d->knn);
    if (in->n == 0 || !in->pos) return sd_errf(err, SD_EINVAL, "prep: the cloud has no points");
    if (in->n >= ((size_t)1 << 31))
        return sd_errf(err, SD_ELIMIT, "prep: %zu points is over the limit of 2^31 - 1", in->n);
    struct { uint32_t bit; const void *arr; const char *name; } a[] = {
        {PC_ATTR_RGB, in->rgba, "rgb"},           {PC_ATTR_NORMAL, in->normal, "normal"},
        {PC_ATTR_INTENSITY, in->intensity, "intensity"}, {PC_ATTR_CLASS, in->cls, "class"},
        {PC_ATTR_RADIUS, in->radius, "radius"},   {PC_ATTR_SCALAR, in->scalar, "scalar"},
        {PC_ATTR_SCAN, in->scan, "scan"},
    };
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++)
        if ((in->attrs & a[i].bit) && !a[i].arr)
            return sd_errf(err, SD_EINVAL, "prep: the cloud claims a %s attribute but has no "
                           "%s array", a[i].name, a[i].name);
    return 0;
}

/* Step 1's parallel parts, over blocks of CHUNK points: the codes, then the permutation. */
typedef struct order_job {
    const pc_cloud *in;
    pc_prepared *out;
    const prep_morton_frame *f;
    uint64_t *codes;
    uint32_t *perm;
} order_job;

static int order_codes(void *ctx, size_t c, int tid, sd_err *err)
{
    order_job *o = ctx;
    size_t a = c * CHUNK, e = a + CHUNK < o->in->n ? a + CHUNK : o->in->n;
    for (size_t j = a; j < e; j++) {
        o->codes[j] = prep_morton_code(o->f, o->in->pos + 3 * j);
        o->perm[j] = (uint32_t)j;
    }
    return 0;
}

static int order_gather(void *ctx, size_t c, int tid, sd_err *err)
{
    order_job *o = ctx;
    const pc_cloud *in = o->in;
    pc_prepared *out = o->out;
    size_t a = c * CHUNK, e = a + CHUNK < in->n ? a + CHUNK : in->n;
    for (size_t i = a; i < e; i++) {
        size_t s = o->perm[i];
        memcpy(out->pos + 3 * i, in->pos + 3 * s, 3 * sizeof(float));
        if (in->attrs & PC_ATTR_NORMAL) memcpy(out->normal + 3 * i, in->normal + 3 * s, 12);
        if (in->attrs & PC_ATTR_RADIUS) out->radius[i] = in->radius[s];
        if (in->attrs & PC_ATTR_RGB) memcpy(out->rgba + 4 * i, in->rgba + 4 * s, 4);
        if (in->attrs & PC_ATTR_INTENSITY) out->intensity[i] = in->intensity[s];
        if (in->attrs & PC_ATTR_CLASS) out->cls[i] = in->cls[s];
        if (in->attrs & PC_ATTR_SCALAR) out->scalar[i] = in->scalar[s];
        if (in->attrs & PC_ATTR_SCAN) out->scan[i] = in->scan[s];
    }
    return 0;
}

/* Step 1: Morton order, attribute permutation, batches, summary. Allocates out. The codes and
 * the permutation run on threads threads; the sort and the centroid (a sum in point order,
 * the same bits at any thread count) on one. */
static int reorder(const pc_cloud *in, int K, int threads, pc_prepared *out, double centroid[3],
                   prep_morton_frame *f, uint64_t **codes_out, sd_err *err)
{
    size_t n = in->n;
    prep_morton_frame_of(in->pos, n, f);
    uint64_t *codes = malloc(n * sizeof *codes);
    uint32_t *perm = malloc(n * sizeof *perm);
    if (!codes || !perm) {
        free(codes); free(perm);
        return sd_errf(err, SD_ENOMEM, "prep: out of memory ordering %zu points", n);
    }
    order_job oj = {.in = in, .out = out, .f = f, .codes = codes, .perm = perm};
    size_t nblk = (n + CHUNK - 1) / CHUNK;
    int rc = prep_par_for(threads, nblk, order_codes, &oj, NULL, err);
    if (rc == 0) rc = prep_radix_sort64(codes, perm, n, err);
    if (rc != 0) {
        free(codes);
        free(perm);
        return rc;
    }
    *codes_out = codes; /* the kNN index takes them: the points are in their order now */
    out->n = n;
    out->attrs = (in->attrs & (PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_INTENSITY | PC_ATTR_CLASS |
                               PC_ATTR_RADIUS | PC_ATTR_SCALAR | PC_ATTR_SCAN)) |
                 PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F;
    out->nbatches = (n + PC_BATCH_POINTS - 1) / PC_BATCH_POINTS;
    out->k = (uint32_t)K;
    rc = pc_prepared_alloc(out, err);
    if (rc != 0) {
        free(perm);
        free(codes);
        *codes_out = NULL;
        return rc;
    }
    rc = prep_par_for(threads, nblk, order_gather, &oj, NULL, err);
    free(perm);
    if (rc != 0) {
        free(codes);
        *codes_out = NULL;
        return rc; /* out is freed by the caller */
    }
    double c[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) c[a] += out->pos[3 * i + a];
    for (int a = 0; a < 3; a++) centroid[a] = c[a] / (double)n;
    pc_prepared_make_batches(out, PC_BATCH_POINTS);
    memcpy(out->offset, in->offset, sizeof out->offset);
    memcpy(out->bmin, in->bmin, sizeof out->bmin);
    memcpy(out->bmax, in->bmax, sizeof out->bmax);
    out->n_dropped = in->n_dropped;
    memcpy(out->format, in->format, sizeof out->format);
    memcpy(out->scalar_name, in->scalar_name, sizeof out->scalar_name);
    out->has_sensor_q = in->has_viewpoint;
    memcpy(out->sensor_q, in->viewpoint_q, sizeof out->sensor_q);
    out->format[sizeof out->format - 1] = 0;
    out->scalar_name[sizeof out->scalar_name - 1] = 0;
    return 0;
}

/* A cloud of one point has no neighbours: an upward normal, radius 1, F 0, sigma 0. */
static void single_point(pc_prepared *p, int had_normal, int had_radius)
{
    if (!had_normal) { p->normal[0] = 0; p->normal[1] = 0; p->normal[2] = 1; }
    if (!had_radius) p->radius[0] = 1;
    p->F[0] = 0;
    p->radius_median = p->radius[0];
}

/* Step 6 and F's normalisation: percentiles over the whole cloud, in two independent tasks
 * (one a thread): 0, F's 99th percentile, the normalisation and F's percentiles, in tmp (n
 * floats); 1, sigma (selected in nnd itself, which is not needed after) and the radius median
 * (in nnd again). Each selection starts from the same array as when they ran one after
 * another, so the results are the same bits. */
typedef struct summary_job {
    pc_prepared *p;
    float *nnd, *tmp;
} summary_job;

static int summarise_task(void *ctx, size_t task, int tid, sd_err *err)
{
    summary_job *j = ctx;
    pc_prepared *p = j->p;
    size_t n = p->n;
    (void)tid;
    (void)err;
    if (task == 1) {
        p->sigma = prep_percentile(j->nnd, n, 0.5);
        memcpy(j->nnd, p->radius, n * sizeof *j->nnd);
        p->radius_median = prep_percentile(j->nnd, n, 0.5);
        return 0;
    }
    float *tmp = j->tmp;
    memcpy(tmp, p->F, n * sizeof *tmp);
    float p99 = prep_percentile(tmp, n, 0.99);
    p->F_raw_p99 = p99;
    for (size_t i = 0; i < n; i++) {
        float v = p99 > 0 ? p->F[i] / p99 : (p->F[i] > 0 ? 1.0f : 0.0f);
        p->F[i] = v < 0 ? 0 : (v > 1 ? 1 : v);
    }
    static const double q[5] = {0.01, 0.25, 0.5, 0.75, 0.99};
    memcpy(tmp, p->F, n * sizeof *tmp);
    for (int i = 0; i < 5; i++) p->F_pct[i] = prep_percentile(tmp, n, q[i]);
    return 0;
}

static int summarise(pc_prepared *p, float *nnd, float *tmp, int threads, sd_err *err)
{
    summary_job j = {p, nnd, tmp};
    return prep_par_for(threads < 2 ? 1 : 2, 2, summarise_task, &j, NULL, err);
}

int prep_run(const pc_cloud *in, const prep_desc *desc, pc_prepared *out, sd_err *err)
{
    prep_desc d;
    if (out) memset(out, 0, sizeof *out);
    if (!out) return sd_errf(err, SD_EINVAL, "prep: no output given");
    int rc = check_input(in, desc, &d, err);
    if (rc != 0) return rc;
    size_t n = in->n;
    int K = (size_t)d.k < n ? d.k : (int)(n - 1);
    prep_progress pr;
    job jb = {.p = out, .K = K};
    jb.need_normal = !(in->attrs & PC_ATTR_NORMAL);
    jb.need_radius = !(in->attrs & PC_ATTR_RADIUS);
    prep_knn *kn = NULL;
    prep_morton_frame frame;
    uint64_t *codes = NULL;
    worker *w = NULL;
    float *tmp = NULL;
    size_t nchunks = (n + CHUNK - 1) / CHUNK;
    int threads = d.threads < 1 ? 1 : ((size_t)d.threads > nchunks ? (int)nchunks : d.threads);
    double wall, tq, tn, tr, tf, sum;

    double t0 = now_s();
    prep_progress_begin(&pr, d.progress, d.user, PROTO_PHASE_REORDER);
    rc = reorder(in, K, d.threads, out, jb.centroid, &frame, &codes, err);
    if (in->has_viewpoint) { /* into the cloud's local coordinates, as the positions */
        jb.has_vp = 1;
        for (int a = 0; a < 3; a++) jb.vp[a] = in->viewpoint[a] - in->offset[a];
    }
    if (rc != 0) goto fail;
    prep_progress_end(&pr);
    out->stats.t_reorder = now_s() - t0;
    if (n == 1) {
        single_point(out, !jb.need_normal, !jb.need_radius);
        free(codes);
        return 0;
    }

    t0 = now_s();
    prep_progress_begin(&pr, d.progress, d.user, PROTO_PHASE_KNN);
    prep_knn_opts ko = {.method = d.knn, .leaf_size = d.knn_leaf, .flann_cores = 1,
                        .frame = &frame, .codes = codes};
    rc = prep_knn_build(out->pos, n, &ko, &kn, err);
    if (rc != 0) goto fail;
    prep_progress_end(&pr);
    out->stats.t_knn_build = now_s() - t0;

    size_t per_nbr = (size_t)K * sizeof(uint32_t);
    int keep = n <= d.max_nbr_bytes / per_nbr;
    jb.kn = kn;
    jb.nnd = malloc(n * sizeof *jb.nnd);
    jb.rcap = jb.need_radius ? malloc(n * sizeof *jb.rcap) : NULL;
    jb.svar = jb.need_radius ? malloc(n * sizeof *jb.svar) : NULL;
    tmp = malloc(n * sizeof *tmp);
    if ((jb.need_radius && (!jb.rcap || !jb.svar)) || !tmp) goto nomem;
    jb.nbr = keep ? malloc(n * per_nbr) : NULL;
    w = calloc((size_t)threads, sizeof *w);
    if (!jb.nnd || (keep && !jb.nbr) || !w) goto nomem;
    jb.w = w;
    for (int t = 0; t < threads; t++) {
        w[t].ks = prep_knn_scratch_new();
        w[t].d2 = malloc((size_t)CHUNK * per_nbr);
        w[t].idx = keep ? NULL : malloc((size_t)CHUNK * per_nbr);
        if (!w[t].ks || !w[t].d2 || (!keep && !w[t].idx)) goto nomem;
    }

    t0 = now_s();
    prep_progress_begin(&pr, d.progress, d.user, PROTO_PHASE_NORMALS);
    rc = prep_par_for(threads, nchunks, chunk_normals, &jb, &pr, err);
    if (rc != 0) goto fail;
    wall = now_s() - t0;
    tq = tn = tr = 0;
    for (int t = 0; t < threads; t++) {
        tq += w[t].t_query; tn += w[t].t_normal; tr += w[t].t_radius;
        w[t].t_query = 0;
    }
    /* The three run fused per chunk: split the wall time in proportion to the work. */
    sum = tq + tn + tr > 0 ? tq + tn + tr : 1;
    out->stats.t_knn_query = wall * tq / sum;
    out->stats.t_normals = wall * tn / sum;
    out->stats.t_radius = wall * tr / sum;

    if (jb.need_radius) {
        memcpy(tmp, out->radius, n * sizeof *tmp);
        jb.scatter_cap = PREP_SCATTER_CAP * prep_percentile(tmp, n, 0.5);
    }
    t0 = now_s();
    prep_progress_begin(&pr, d.progress, d.user, PROTO_PHASE_FIELD);
    rc = prep_par_for(threads, nchunks, chunk_field, &jb, &pr, err);
    if (rc != 0) goto fail;
    if (jb.rcap) { /* after F, which uses the radius of eq. 20 itself */
        for (size_t i = 0; i < n; i++)
            if (out->radius[i] > jb.rcap[i]) out->radius[i] = jb.rcap[i];
    }
    rc = summarise(out, jb.nnd, tmp, threads, err);
    if (rc != 0) goto fail;
    wall = now_s() - t0;
    tf = tq = 0;
    for (int t = 0; t < threads; t++) { tq += w[t].t_query; tf += w[t].t_field; }
    sum = tq + tf > 0 ? tq + tf : 1;
    out->stats.t_knn_query += wall * tq / sum;
    out->stats.t_field = wall * tf / sum;
    rc = 0;
    goto done;

nomem:
    rc = sd_errf(err, SD_ENOMEM, "prep: out of memory for the neighbours of %zu points", n);
fail:
    pc_prepared_free(out);
done:
    free(tmp);
    if (w)
        for (int t = 0; t < threads; t++) {
            prep_knn_scratch_free(w[t].ks);
            free(w[t].d2);
            free(w[t].idx);
        }
    free(w);
    free(jb.nnd);
    free(jb.rcap);
    free(jb.svar);
    free(jb.nbr);
    prep_knn_free(kn);
    free(codes);
    return rc;
}
