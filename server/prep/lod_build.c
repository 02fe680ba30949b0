/* lod_build.c — the out-of-core LOD build (lod.h).
 *
 * Passes over the input (lod_src: the bounds come from its opening pass):
 *   count     the centroid (prep.c's sum: doubles of the float positions, in file order) and
 *             points per Morton cell of depth D = min(grid_bits, 7) (8 MiB of counters); the
 *             chunks are the shallowest cells holding at most chunk_max points (down to
 *             depth D), chunk_max from the memory cap: memory / 400 bytes, the bytes a point
 *             of a chunk costs in the normals pass with its halo (chunks are processed one at a
 *             time, each on every thread, so the cap does not grow with the thread count).
 *   distribute every point (position, colour, index in the file: 20 bytes; its Morton code is
 *             recomputed from the position wherever it is needed, the same bits) into its
 *             chunk's scratch file (unnamed files in the cache directory: nothing is left
 *             behind by kill -9); then each chunk file sorted by code, in parallel over the
 *             chunks. The chunks are octree cells in Morton order, so a region (a chunk and
 *             its halo) is the filtered concatenation of its chunks' files, in order without a
 *             sort; of a neighbouring chunk only the count cells that meet the region's box are
 *             read (a cell's records are a run of the sorted file: cell_pre).
 *   normals   chunk by chunk, each in parallel over blocks of points: the chunk and a halo
 *             (every point within H of its cube, read from the neighbouring chunks' files) in
 *             (Morton code, file index) order, the order prep.c gives the whole cloud, indexed
 *             in the cloud's Morton frame (no sort: the region is in that order already); kNN
 *             of the chunk's points and of their neighbours; a result is exact when its k-th
 *             neighbour is closer than the halo's edge, else H grows to the farthest ball and
 *             the region is loaded again, the exact results kept (renamed into the bigger
 *             region) and only the others queried again. The first H: the previous chunk's,
 *             or the bound the count grid gives (halo_bounds) when smaller or first. The next chunk's region loads on a
 *             thread of its own meanwhile. Then prep.c's per-point values: eq. 20 radius, PCA
 *             normal and surface variation, oriented as prep.c does, raw F, the neighbours'
 *             median radius, the nearest distance, written block by block by the threads to
 *             the chunk's second scratch file (32 bytes a point: what the first one does not
 *             hold already); histograms of the values whose percentiles prep.c takes. Halo
 *             neighbours that belong to a chunk done already are not queried: their normals
 *             and radii are read from its records. Region arrays come from a pool kept across
 *             the chunks. A status line gives the pass's phases in wall seconds.
 *   quantiles exact percentiles out of core: the top 16 bits of each (non-negative) float
 *             counted in the normals pass, the bottom 16 bits of the values in the bucket that
 *             holds the wanted rank counted here: the radius median (scatter cap), F's 99th
 *             percentile and the percentiles prep.c reports, sigma.
 *   radius    the final radii (prep.c's caps), histogram for their median.
 *   octree    per chunk, in parallel: the final values, then the additive octree of lod.h top
 *             down over the chunk's Morton-ordered points; nodes inside the chunk are written
 *             at once, points of the levels above the chunk are kept and grouped into their
 *             nodes at the end (they are few: one per sampling cell of those levels).
 * The passes that run in parallel over the chunks hand them out largest first (by_size).
 * Then the node table (breadth first), the header, fsync and rename. */
#include "lod.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "cache.h"
#include "cloud.h"
#include "knn.h"
#include "lod_ahead.h"
#include "lod_file.h"
#include "lod_src.h"
#include "morton.h"
#include "pca.h"
#include "prep.h"
#include "sd_hash.h"

enum { COUNT_DEPTH_MAX = 7, BLOCK = 1 << 16, NQ = 7 };
enum { KB_NBR, KB_KD2, KB_NN2, KB_EXACT, KB_REDO, KB_SLOT, KB_LIST, KB_R20, KB_NRM, KB_SVAR,
       KB_KNOWN, KB_N };
#define BYTES_PER_CHUNK_POINT 400u /* the normals pass of one chunk (with its halo) */

/* The scratch records are as small as they can be (at 100M points they go through the page
 * cache and to the disk several times): the Morton code is not stored but recomputed from the
 * position (prep_morton_code: the same bits), and the normals pass's record leaves out what the
 * chunk file (sorted, in the same order) holds already. */
typedef struct rec {          /* a point in a chunk file */
    float pos[3];
    uint32_t rgba, gidx;
} rec;

typedef struct arec {         /* a chunk's point after the normals pass: record i of fd_a is
                                 record i of fd_in (the chunk's points in the same order) */
    float normal[3];
    float r20, capn, svar, Fraw, nnd;
} arec;

typedef struct urec {         /* a point of a node above the chunks */
    uint64_t code, node;      /* node: its prefix */
    uint32_t gidx, level;
    float pos[3], normal[3], radius, F;
    uint32_t rgba, surface;
} urec;

typedef struct chunk {
    uint64_t code;            /* Morton prefix of depth `depth` */
    uint32_t depth;
    uint64_t count;
    uint64_t cell0, cell1;    /* its count cells, [cell0, cell1) */
    int fd_in, fd_a;          /* scratch files: recs, arecs */
    float lo[3], hi[3];       /* its cube */
    float hb;                 /* a halo that holds every ball it needs (halo_bounds) */
    int retried;
} chunk;

typedef struct nodeent {      /* a written node, before the table */
    lod_node n;
} nodeent;

typedef struct build {
    const lod_desc *d;
    lod_writer w;
    lod_src_info info;
    double centroid[3];       /* mean of the local float positions (the count pass) */
    prep_morton_frame f;
    int K, threads, g, cdepth;
    chunk *chunks;
    size_t nchunks;
    uint32_t *cell_chunk;     /* count cells -> chunk */
    uint64_t *cell_pre;       /* count cells -> points in the cells before (ncell + 1) */
    uint64_t nread;           /* records the region loads read (the normals pass) */
    double load_cpu;          /* CPU seconds of those loads (on the prefetch thread mostly) */
    struct rbuf *rpool;       /* the regions' arrays, kept across chunks (RPOOL sets) */
    void **tk;                /* per thread, TK_N arrays kept across the chunks of a pass */
    size_t *tkcap;
    uint64_t *hist_hi[4];     /* r20, Fraw, nnd, final radius: 65536 each */
    struct { int which; double q; uint32_t hi; uint64_t rank; uint64_t *lo; float value; } qs[NQ + 1];
    float scatter_cap, p99;
    float halo;               /* the halo the last chunk of the normals pass needed */
    uint64_t normals_done;    /* points through the normals pass so far */
    int radius_pass;          /* chunk_hist: which histograms */
    uint64_t *tcount;         /* chunk_hist's counters, NQ x 65536 per thread */
    double t_pass;            /* when the normals pass began */
    double tph[7];            /* the normals pass's phases, wall seconds (PH_*) */
    prep_knn_counters kc;     /* the grid search's work on the chunks' own points */
    struct prefetch *pf;      /* the next chunk's region, loaded while this one computes */
    size_t *order;            /* the chunks, largest first (by_size) */
    void *keep[KB_N];         /* the normals pass's per-chunk arrays, kept across chunks (KB_*) */
    size_t keepcap[KB_N];
    pthread_mutex_t mu;
    nodeent *nodes;
    size_t nnodes, capnodes;
    urec *up;
    size_t nup, capup;
    double t0;
} build;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void status(build *b, const char *pass, double frac_done, uint64_t points, double dt)
{
    if (!b->d->status) return;
    double el = now_s() - b->t0;
    double eta = frac_done > 0 ? el * (1 - frac_done) / frac_done : 0;
    char line[256];
    snprintf(line, sizeof line, "lod %-10s %llu points in %.2f s (%.2f M points/s); %.0f %% "
             "done, %.1f s elapsed, ETA %.1f s", pass, (unsigned long long)points, dt,
             dt > 0 ? points / dt / 1e6 : 0.0, frac_done * 100, el, eta);
    b->d->status(b->d->user, line);
}

static uint32_t fbits(float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    return u;
}

/* ---- count and chunks ---- */

static int make_chunks(build *b, const uint64_t *cnt, sd_err *err)
{
    int D = b->cdepth;
    uint64_t ncell = (uint64_t)1 << (3 * D);
    uint64_t *pre = malloc((ncell + 1) * sizeof *pre);
    b->cell_chunk = malloc(ncell * sizeof *b->cell_chunk);
    if (!pre || !b->cell_chunk) {
        free(pre);
        return sd_errf(err, SD_ENOMEM, "lod: out of memory for the count grid");
    }
    pre[0] = 0;
    for (uint64_t i = 0; i < ncell; i++) pre[i + 1] = pre[i] + cnt[i];
    uint64_t chunk_max = b->d->chunk_max;
    size_t cap = 64;
    b->chunks = calloc(cap, sizeof *b->chunks);
    /* depth-first over the cells: a stack of (depth, code) */
    uint64_t stack[8 * 24][2];
    int sp = 0;
    stack[sp][0] = 0, stack[sp][1] = 0, sp++;
    while (sp && b->chunks) {
        sp--;
        uint64_t dep = stack[sp][0], code = stack[sp][1];
        uint64_t a = code << (3 * (D - dep)), e = (code + 1) << (3 * (D - dep));
        uint64_t c = pre[e] - pre[a];
        if (!c) continue;
        if (c <= chunk_max || (int)dep == D) {
            if (b->nchunks == cap) {
                chunk *nc = realloc(b->chunks, 2 * cap * sizeof *nc);
                if (!nc) {
                    free(b->chunks);
                    b->chunks = NULL;
                    break;
                }
                b->chunks = nc;
                memset(nc + cap, 0, cap * sizeof *nc);
                cap *= 2;
            }
            chunk *ch = &b->chunks[b->nchunks];
            ch->code = code;
            ch->depth = (uint32_t)dep;
            ch->count = c;
            ch->cell0 = a, ch->cell1 = e;
            ch->fd_in = ch->fd_a = -1;
            uint32_t x, y, z;
            prep_morton_decode(code, &x, &y, &z);
            double cs = b->f.side / (double)((uint64_t)1 << dep);
            uint32_t xyz[3] = {x, y, z};
            for (int k = 0; k < 3; k++) {
                ch->lo[k] = (float)(b->f.origin[k] + xyz[k] * cs);
                ch->hi[k] = (float)(b->f.origin[k] + (xyz[k] + 1) * cs);
            }
            for (uint64_t i = a; i < e; i++) b->cell_chunk[i] = (uint32_t)b->nchunks;
            b->nchunks++;
            continue;
        }
        for (int ci = 7; ci >= 0; ci--) {
            stack[sp][0] = dep + 1;
            stack[sp][1] = code << 3 | (uint64_t)ci;
            sp++;
        }
    }
    b->cell_pre = pre; /* a cell's records in its chunk's (sorted) file: load_region */
    if (!b->chunks) return sd_errf(err, SD_ENOMEM, "lod: out of memory for the chunks");
    if (b->nchunks > 4000)
        return sd_errf(err, SD_ELIMIT, "lod: %zu chunks is too many open files; give more "
                       "--memory", b->nchunks);
    for (size_t i = 0; i < b->nchunks; i++) {
        int rc = lod__scratch(&b->w, err);
        if (rc < 0) return rc;
        b->chunks[i].fd_in = rc;
        rc = lod__scratch(&b->w, err);
        if (rc < 0) return rc;
        b->chunks[i].fd_a = rc;
    }
    return 0;
}

/* An upper bound on the halo each chunk needs, from the count grid (G = 2^D cells a side, cell
 * side cs): a box of (2r + 1)^3 cells around a point's cell that holds K + 1 points or more
 * holds its K nearest neighbours, so their distance is at most sqrt(3) (r + 1) cs. A chunk
 * needs the balls of its points and of their neighbours (within the first bound of its cube)
 * inside the halo. The bound only picks the first halo: the normals pass still checks every
 * ball and grows the halo when one leaves (a loose bound costs a bigger region, a low one a
 * second load). */
static int halo_bounds(build *b, const uint64_t *cnt, sd_err *err)
{
    if (b->nchunks < 2) return 0; /* one chunk: its region is the whole cloud, no halo */
    int D = b->cdepth;
    size_t G = (size_t)1 << D, G1 = G + 1;
    uint32_t *sat = calloc(G1 * G1 * G1, sizeof *sat); /* sat[x][y][z]: cells below (x, y, z) */
    float *rad = malloc(G * G * G * sizeof *rad);      /* per cell, in cells; 0: empty */
    if (!sat || !rad) {
        free(sat);
        free(rad);
        return sd_errf(err, SD_ENOMEM, "lod: out of memory for the halo bounds");
    }
#define SAT(x, y, z) sat[((size_t)(x) * G1 + (size_t)(y)) * G1 + (size_t)(z)]
    for (size_t x = 0; x < G; x++)
        for (size_t y = 0; y < G; y++)
            for (size_t z = 0; z < G; z++) {
                uint64_t code = prep_morton_encode((uint32_t)x, (uint32_t)y, (uint32_t)z);
                SAT(x + 1, y + 1, z + 1) = (uint32_t)cnt[code] + SAT(x, y + 1, z + 1) +
                    SAT(x + 1, y, z + 1) + SAT(x + 1, y + 1, z) - SAT(x, y, z + 1) -
                    SAT(x, y + 1, z) - SAT(x + 1, y, z) + SAT(x, y, z);
            }
    uint64_t want = (uint64_t)b->K + 1;
    for (size_t x = 0; x < G; x++)
        for (size_t y = 0; y < G; y++)
            for (size_t z = 0; z < G; z++) {
                size_t i = (x * G + y) * G + z;
                rad[i] = 0;
                if (!cnt[prep_morton_encode((uint32_t)x, (uint32_t)y, (uint32_t)z)]) continue;
                size_t r = 0;
                for (;; r++) {
                    size_t x0 = x > r ? x - r : 0, y0 = y > r ? y - r : 0, z0 = z > r ? z - r : 0;
                    size_t x1 = x + r + 1 < G ? x + r + 1 : G, y1 = y + r + 1 < G ? y + r + 1 : G,
                           z1 = z + r + 1 < G ? z + r + 1 : G;
                    uint64_t in = (uint64_t)SAT(x1, y1, z1) - SAT(x0, y1, z1) - SAT(x1, y0, z1) -
                        SAT(x1, y1, z0) + SAT(x0, y0, z1) + SAT(x0, y1, z0) + SAT(x1, y0, z0) -
                        SAT(x0, y0, z0);
                    if (in >= want || (x0 == 0 && y0 == 0 && z0 == 0 && x1 == G && y1 == G && z1 == G))
                        break;
                }
                rad[i] = 1.7320508f * (float)(r + 1);
            }
#undef SAT
    float cs = (float)(b->f.side / (double)G);
    for (size_t ci = 0; ci < b->nchunks; ci++) {
        chunk *c = &b->chunks[ci];
        uint32_t xyz[3];
        prep_morton_decode(c->code, &xyz[0], &xyz[1], &xyz[2]);
        int sh = D - (int)c->depth;
        int64_t lo[3], hi[3]; /* the chunk's cells, [lo, hi) */
        for (int a = 0; a < 3; a++) lo[a] = (int64_t)xyz[a] << sh, hi[a] = ((int64_t)xyz[a] + 1) << sh;
        float need = 0;
        for (int pass = 0; pass < 2; pass++) {
            int64_t m = pass == 0 ? 0 : (int64_t)ceilf(need); /* pass 1: the neighbours too */
            int64_t b0[3], b1[3];
            for (int a = 0; a < 3; a++) {
                b0[a] = lo[a] - m > 0 ? lo[a] - m : 0;
                b1[a] = hi[a] + m < (int64_t)G ? hi[a] + m : (int64_t)G;
            }
            for (int64_t x = b0[0]; x < b1[0]; x++)
                for (int64_t y = b0[1]; y < b1[1]; y++)
                    for (int64_t z = b0[2]; z < b1[2]; z++) {
                        float R = rad[((size_t)x * G + (size_t)y) * G + (size_t)z];
                        if (R == 0) continue;
                        int64_t p[3] = {x, y, z};
                        for (int a = 0; a < 3; a++) {
                            float o1 = (float)(p[a] + 1 - hi[a]) + R, o2 = (float)(lo[a] - p[a]) + R;
                            if (o1 > need) need = o1;
                            if (o2 > need) need = o2;
                        }
                    }
        }
        c->hb = need * cs;
    }
    free(sat);
    free(rad);
    return 0;
}

static uint64_t count_cell(const build *b, const float *p)
{
    return prep_morton_code(&b->f, p) >> (3 * (PREP_MORTON_BITS - b->cdepth));
}

static int count_and_distribute(build *b, lod_src *s, sd_err *err)
{
    uint64_t ncell = (uint64_t)1 << (3 * b->cdepth);
    uint64_t *cnt = calloc(ncell, sizeof *cnt);
    lod_ahead ah; /* each pass's next block is read while this one's are worked on */
    int rc = cnt ? lod_ahead_start(&ah, s, BLOCK, err) : sd_errf(err, SD_ENOMEM, "lod: out of memory");
    int64_t m = 0;
    double t = now_s();
    double csum[3] = {0, 0, 0};
    const float *pos = NULL;
    const uint32_t *rgba = NULL;
    while (rc == 0 && (m = lod_ahead_next(&ah, &pos, &rgba, err)) > 0)
        for (int64_t i = 0; i < m; i++) {
            cnt[count_cell(b, pos + 3 * i)]++;
            for (int a = 0; a < 3; a++) csum[a] += pos[3 * i + a];
        }
    if (rc == 0) lod_ahead_stop(&ah);
    if (rc == 0 && m < 0) rc = (int)m;
    for (int a = 0; a < 3; a++) b->centroid[a] = csum[a] / (double)b->info.n;
    if (rc == 0) rc = make_chunks(b, cnt, err);
    if (rc == 0) rc = halo_bounds(b, cnt, err);
    free(cnt);
    status(b, "count", 0.05, b->info.n, now_s() - t);
    /* distribute, through one buffer per chunk */
    enum { PER = 4096 };
    rec *buf = rc == 0 ? malloc(b->nchunks * PER * sizeof *buf) : NULL;
    uint32_t *fill = rc == 0 ? calloc(b->nchunks, sizeof *fill) : NULL;
    uint64_t *off = rc == 0 ? calloc(b->nchunks, sizeof *off) : NULL;
    if (rc == 0 && (!buf || !fill || !off)) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory");
    int ahead = rc == 0 && (rc = lod_ahead_start(&ah, s, BLOCK, err)) == 0;
    t = now_s();
    uint32_t gidx = 0;
    while (rc == 0 && (m = lod_ahead_next(&ah, &pos, &rgba, err)) > 0) {
        for (int64_t i = 0; i < m && rc == 0; i++) {
            uint64_t code = prep_morton_code(&b->f, pos + 3 * i);
            uint32_t c = b->cell_chunk[code >> (3 * (PREP_MORTON_BITS - b->cdepth))];
            rec *r = &buf[(size_t)c * PER + fill[c]++];
            memcpy(r->pos, pos + 3 * i, 12);
            r->rgba = rgba[i];
            r->gidx = gidx++;
            if (fill[c] == PER) {
                if (cf_pwrite_all(b->chunks[c].fd_in, buf + (size_t)c * PER, PER * sizeof *buf, off[c]))
                    rc = sd_errf(err, SD_EIO, "lod: cannot write a scratch file: %s", strerror(errno));
                off[c] += PER * sizeof *buf;
                fill[c] = 0;
            }
        }
    }
    if (ahead) lod_ahead_stop(&ah);
    if (rc == 0 && m < 0) rc = (int)m;
    for (size_t c = 0; rc == 0 && c < b->nchunks; c++)
        if (fill[c] && cf_pwrite_all(b->chunks[c].fd_in, buf + c * PER, fill[c] * sizeof *buf, off[c]))
            rc = sd_errf(err, SD_EIO, "lod: cannot write a scratch file: %s", strerror(errno));
    if (rc == 0) status(b, "distribute", 0.12, b->info.n, now_s() - t);
    free(buf);
    free(fill);
    free(off);
    return rc;
}

/* ---- normals pass ---- */

/* A set of region arrays for cap points. Regions take their arrays from a pool of RPOOL sets
 * kept across the chunks (the current region, the next one loading, the smaller one of a halo
 * that grew): each load writes into pages an earlier region faulted in, instead of ~35 fresh
 * bytes a point (at 100M points, 374M region points: ~13 GB of page faults and zeroing). */
enum { RPOOL = 4 };
typedef struct rbuf {
    float *pos;
    uint32_t *rgba, *gidx, *fidx;
    uint64_t *code;
    uint8_t *own;
    uint16_t *chk;
    size_t cap;
    int used;
} rbuf;

static void rbuf_free(rbuf *x)
{
    free(x->pos);
    free(x->rgba);
    free(x->gidx);
    free(x->fidx);
    free(x->code);
    free(x->own);
    free(x->chk);
    x->pos = NULL, x->rgba = x->gidx = x->fidx = NULL, x->code = NULL, x->own = NULL, x->chk = NULL;
    x->cap = 0;
}

typedef struct region {
    size_t m;
    float *pos;
    uint32_t *gidx, *rgba;
    uint64_t *code;
    uint8_t *own;
    uint16_t *chk;            /* each point's chunk (at most 4000) */
    uint32_t *fidx;           /* and its record in that chunk's files */
    float lo[3], hi[3];       /* the loaded box */
    int edge[6];              /* 1 where the box reaches the cube's face: nothing lies beyond */
    uint64_t nread;           /* records read to load it */
    double cpu;               /* CPU seconds the load took */
    int pool;                 /* 1 + its set in build.rpool, 0: its own arrays */
    rbuf mine;                /* its own arrays (pool 0) */
} region;

enum { TK_N = 4 };

/* Array which (of TK_N) of thread tid, at least bytes long (contents not kept when it grows).
 * The sort and octree passes keep their per-chunk arrays across the chunks: arrays this big
 * are mapped fresh by each malloc, so each chunk would fault in and zero new pages (~50 bytes
 * a point a pass). NULL when out of memory. */
static void *tkeep(build *b, int tid, int which, size_t bytes)
{
    size_t i = (size_t)tid * TK_N + (size_t)which;
    if (bytes == 0) bytes = 1;
    if (bytes > b->tkcap[i]) {
        free(b->tk[i]);
        b->tk[i] = malloc(bytes);
        b->tkcap[i] = b->tk[i] ? bytes : 0;
    }
    return b->tk[i];
}

/* Frees the kept arrays (after a pass). */
static void tkeep_free(build *b)
{
    for (size_t i = 0; b->tk && i < (size_t)b->threads * TK_N; i++) {
        free(b->tk[i]);
        b->tk[i] = NULL;
        b->tkcap[i] = 0;
    }
}

/* The sorting pass for chunk ci: its file, written in file order, rewritten in (code, file
 * index) order (a stable radix sort by code). */
static int chunk_sort(void *ctx, size_t ci, int tid, sd_err *err)
{
    build *b = ctx;
    chunk *o = &b->chunks[ci];
    size_t n = o->count;
    rec *in = tkeep(b, tid, 0, n * sizeof *in), *out = tkeep(b, tid, 1, n * sizeof *out);
    uint64_t *key = tkeep(b, tid, 2, n * sizeof *key);
    uint32_t *perm = tkeep(b, tid, 3, n * sizeof *perm);
    int rc = 0;
    if (!in || !out || !key || !perm) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory sorting a chunk");
    if (rc == 0 && cf_pread_all(o->fd_in, in, n * sizeof *in, 0))
        rc = sd_errf(err, SD_EIO, "lod: cannot read a scratch file: %s", strerror(errno));
    for (size_t i = 0; rc == 0 && i < n; i++)
        key[i] = prep_morton_code(&b->f, in[i].pos), perm[i] = (uint32_t)i;
    if (rc == 0) rc = prep_radix_sort64(key, perm, n, err);
    if (rc == 0) {
        for (size_t i = 0; i < n; i++) out[i] = in[perm[i]];
        if (cf_pwrite_all(o->fd_in, out, n * sizeof *out, 0))
            rc = sd_errf(err, SD_EIO, "lod: cannot write a scratch file: %s", strerror(errno));
    }
    return rc;
}

enum { RBLOCK = 1 << 15 }; /* records read at a time */

/* Appends the records [from, to) of chunk o's file that lie in r's box to r (own: o is the
 * region's own chunk: every record is kept), RBLOCK at a time through tmp. */
static int read_run(const build *b, const chunk *o, int own, uint64_t from, uint64_t to,
                    rec *tmp, region *r, sd_err *err)
{
    for (uint64_t i0 = from; i0 < to; i0 += RBLOCK) {
        size_t nb = to - i0 < RBLOCK ? (size_t)(to - i0) : RBLOCK;
        if (cf_pread_all(o->fd_in, tmp, nb * sizeof *tmp, i0 * sizeof *tmp))
            return sd_errf(err, SD_EIO, "lod: cannot read a scratch file: %s", strerror(errno));
        r->nread += nb;
        size_t m = r->m;
        for (size_t i = 0; i < nb; i++) {
            const float *p = tmp[i].pos;
            if (!own && (p[0] < r->lo[0] || p[0] > r->hi[0] || p[1] < r->lo[1] ||
                         p[1] > r->hi[1] || p[2] < r->lo[2] || p[2] > r->hi[2]))
                continue;
            memcpy(r->pos + 3 * m, p, 12);
            r->rgba[m] = tmp[i].rgba;
            r->gidx[m] = tmp[i].gidx;
            r->code[m] = prep_morton_code(&b->f, p);
            r->own[m] = (uint8_t)own;
            r->chk[m] = (uint16_t)(o - b->chunks);
            r->fidx[m] = (uint32_t)(i0 + i);
            m++;
        }
        r->m = m;
    }
    return 0;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* The records of a neighbouring chunk o that may lie in r's box: only its count cells that meet
 * the box are read (their records are runs of its sorted file: cell_pre). A point inside the
 * box has each finest cell index between those of the box's corners (cell_of is monotonic),
 * so no cell outside that range holds one; the per-point test then keeps exactly the points
 * a read of the whole file would keep, in the same order. */
static int read_neighbour(const build *b, const chunk *o, rec *tmp, region *r, sd_err *err)
{
    int D = b->cdepth, sh = 3 * (PREP_MORTON_BITS - D);
    uint32_t lo[3], hi[3], c[3];
    prep_morton_decode(prep_morton_code(&b->f, r->lo) >> sh, &lo[0], &lo[1], &lo[2]);
    prep_morton_decode(prep_morton_code(&b->f, r->hi) >> sh, &hi[0], &hi[1], &hi[2]);
    prep_morton_decode(o->code, &c[0], &c[1], &c[2]);
    int csh = D - (int)o->depth;
    size_t ncell = 1;
    for (int a = 0; a < 3; a++) {
        uint32_t c0 = c[a] << csh, c1 = ((c[a] + 1) << csh) - 1;
        if (lo[a] < c0) lo[a] = c0;
        if (hi[a] > c1) hi[a] = c1;
        if (lo[a] > hi[a]) return 0;
        ncell *= hi[a] - lo[a] + 1;
    }
    uint32_t *cells = malloc(ncell * sizeof *cells);
    if (!cells) return sd_errf(err, SD_ENOMEM, "lod: out of memory for a chunk");
    size_t nc = 0;
    for (uint32_t x = lo[0]; x <= hi[0]; x++)
        for (uint32_t y = lo[1]; y <= hi[1]; y++)
            for (uint32_t z = lo[2]; z <= hi[2]; z++) cells[nc++] = (uint32_t)prep_morton_encode(x, y, z);
    int whole = nc == (size_t)(o->cell1 - o->cell0); /* every cell: the whole file */
    if (!whole) qsort(cells, nc, sizeof *cells, cmp_u32);
    const uint64_t *pre = b->cell_pre;
    int rc = whole ? read_run(b, o, 0, 0, o->count, tmp, r, err) : 0;
    for (size_t i = 0; !whole && i < nc && rc == 0;) {
        size_t e = i + 1; /* cells[i..e) joined while no record lies between them */
        while (e < nc && pre[cells[e]] == pre[cells[e - 1] + 1]) e++;
        uint64_t from = pre[cells[i]] - pre[o->cell0], to = pre[cells[e - 1] + 1] - pre[o->cell0];
        if (to > from) rc = read_run(b, o, 0, from, to, tmp, r, err);
        i = e;
    }
    free(cells);
    return rc;
}

/* The arrays of r for cap points (at most: pages past the points stay untouched), from an unused
 * set of the pool (grown when smaller than cap) or, with none left, of its own. */
static int region_arrays(build *b, region *r, size_t cap, sd_err *err)
{
    rbuf *x = NULL;
    pthread_mutex_lock(&b->mu); /* the prefetch thread takes sets too */
    for (int i = 0; b->rpool && i < RPOOL; i++)
        if (!b->rpool[i].used && (!x || b->rpool[i].cap > x->cap)) x = &b->rpool[i];
    if (x) {
        x->used = 1;
        r->pool = 1 + (int)(x - b->rpool);
    }
    pthread_mutex_unlock(&b->mu);
    if (!x) x = &r->mine;
    if (x->cap < cap) {
        rbuf_free(x);
        x->pos = malloc(cap * 12);
        x->rgba = malloc(cap * 4);
        x->gidx = malloc(cap * 4);
        x->fidx = malloc(cap * 4);
        x->code = malloc(cap * 8);
        x->own = malloc(cap);
        x->chk = malloc(cap * 2);
        x->cap = cap;
        if (!x->pos || !x->rgba || !x->gidx || !x->fidx || !x->code || !x->own || !x->chk)
            rbuf_free(x);
    }
    r->pos = x->pos, r->rgba = x->rgba, r->gidx = x->gidx, r->fidx = x->fidx;
    r->code = x->code, r->own = x->own, r->chk = x->chk;
    return x->cap ? 0 : sd_errf(err, SD_ENOMEM, "lod: out of memory for a chunk");
}

/* Gives r's arrays back (to the pool, or frees its own); r is empty after. */
static void region_put(build *b, region *r)
{
    if (r->pool) {
        pthread_mutex_lock(&b->mu);
        b->rpool[r->pool - 1].used = 0;
        pthread_mutex_unlock(&b->mu);
    }
    rbuf_free(&r->mine);
    memset(r, 0, sizeof *r);
}

static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* 1 when chunk o's cube meets r's box. */
static int meets(const chunk *o, const region *r)
{
    for (int a = 0; a < 3; a++)
        if (o->lo[a] > r->hi[a] || o->hi[a] < r->lo[a]) return 0;
    return 1;
}

/* Loads chunk ci with every point within h of its cube, in (code, file index) order: the
 * chunks are octree cells in Morton order and their files are sorted (chunk_sort), so each
 * one's points are a run of that order and the region is their filtered concatenation, read
 * a block at a time (of the neighbouring chunks, only the cells that meet the box). */
static int load_region(build *b, size_t ci, float h, region *r, sd_err *err)
{
    double c0 = cpu_s();
    memset(r, 0, sizeof *r);
    const chunk *c = &b->chunks[ci];
    for (int a = 0; a < 3; a++) {
        r->lo[a] = c->lo[a] - h;
        r->hi[a] = c->hi[a] + h;
        r->edge[a] = r->lo[a] <= (float)b->f.origin[a];
        r->edge[3 + a] = r->hi[a] >= (float)(b->f.origin[a] + b->f.side);
    }
    size_t cap = 0;
    for (size_t j = 0; j < b->nchunks; j++)
        if (meets(&b->chunks[j], r)) cap += b->chunks[j].count;
    int rc = region_arrays(b, r, cap ? cap : 1, err);
    rec *tmp = rc == 0 ? malloc(RBLOCK * sizeof *tmp) : NULL;
    if (rc == 0 && !tmp) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory for a chunk");
    for (size_t j = 0; j < b->nchunks && rc == 0; j++) {
        const chunk *o = &b->chunks[j];
        if (!meets(o, r)) continue;
        rc = j == ci ? read_run(b, o, 1, 0, o->count, tmp, r, err) : read_neighbour(b, o, tmp, r, err);
    }
    free(tmp);
    if (rc < 0) region_put(b, r);
    r->cpu = cpu_s() - c0;
    return rc;
}

/* The next chunk's region, loaded on a thread of its own while the current chunk's steps run
 * on every core (a region load is serial: it would leave a core idle). */
typedef struct prefetch {
    pthread_t th;
    int running;
    build *b;
    size_t ci;
    float h;
    region r;
    int rc;
    sd_err err;
} prefetch;

static void *prefetch_run(void *arg)
{
    prefetch *p = arg;
    p->rc = load_region(p->b, p->ci, p->h, &p->r, &p->err);
    return NULL;
}

/* Starts loading chunk ci's region with halo h (or loads it now when no thread starts). */
static void prefetch_start(prefetch *p, build *b, size_t ci, float h)
{
    memset(&p->err, 0, sizeof p->err);
    p->b = b, p->ci = ci, p->h = h, p->rc = 0;
    memset(&p->r, 0, sizeof p->r);
    p->running = pthread_create(&p->th, NULL, prefetch_run, p) == 0;
    if (!p->running) prefetch_run(p);
    else p->running = 2; /* started */
}

/* Waits for the load; 0 and the region (now the caller's) when it is chunk ci's with a halo
 * of at least h, 1 when it is not what is wanted (dropped), or the load's error. */
static int prefetch_take(prefetch *p, size_t ci, float h, region *r, sd_err *err)
{
    if (!p->running) return 1;
    if (p->running == 2) pthread_join(p->th, NULL);
    p->running = 0;
    if (p->rc < 0) {
        if (err) *err = p->err;
        return p->rc;
    }
    if (p->ci != ci || p->h < h) {
        region_put(p->b, &p->r);
        return 1;
    }
    *r = p->r;
    memset(&p->r, 0, sizeof p->r);
    return 0;
}

/* The halo a chunk with cube [lo, hi] needs for the ball (p, sqrt(d2)): the farthest the ball
 * reaches beyond the cube along an axis. */
static float halo_need(const chunk *c, const float *p, float d2)
{
    float d = sqrtf(d2), need = 0;
    for (int a = 0; a < 3; a++) {
        float lo = c->lo[a] - (p[a] - d), hi = p[a] + d - c->hi[a];
        if (lo > need) need = lo;
        if (hi > need) need = hi;
    }
    return need;
}

/* 1 when the ball (p, sqrt(d2)) lies inside the region (faces at the cube's edge excepted). */
static int inside(const region *r, const float *p, float d2)
{
    float d = sqrtf(d2);
    for (int a = 0; a < 3; a++) {
        if (!r->edge[a] && !(p[a] - r->lo[a] > d)) return 0;
        if (!r->edge[3 + a] && !(r->hi[a] - p[a] > d)) return 0;
    }
    return 1;
}

enum { QBLOCK = 4096, QBLOCK_K = QBLOCK * PREP_MAX_K };

typedef struct tls {
    uint64_t hist[3][65536];
    float d2[QBLOCK_K];       /* one block's neighbour distances */
    uint32_t idx[QBLOCK_K];   /* one block's neighbours, where they do not go in place */
    arec out[QBLOCK];         /* one block's records, written from here */
} tls;

/* One chunk's normals pass, its steps run in parallel over blocks of QBLOCK points. The
 * points S of the step: the chunk's own points (slots 0..nown), then their neighbours from the
 * halo (slots nown..ns); region indices in list. */
typedef struct njob {
    build *b;
    region *r;
    const prep_knn *kn;
    prep_knn_scratch **ks;    /* per thread */
    tls **t;                  /* per thread */
    int K;
    uint32_t *list, *nbr;     /* S: region index of each slot; K neighbours (region indices) each */
    int32_t *slot;            /* region index -> slot, or -1 */
    float *kd2, *nn2;         /* squared distance to the K-th and to the nearest neighbour */
    float *r20, *nrm, *svar;
    const uint32_t *qslot;    /* nj_query: the slots to query (NULL: first..first+count) */
    size_t first, count;      /* the step's range of S (or of qslot) */
    int fd_out;               /* the chunk's records go here, each block by its thread */
    size_t nu, ns;            /* nj_pca_known: slots [nu, ns) are read (read_known) */
    double vp[3];
} njob;

static int nj_query(void *ctx, size_t blk, int tid, sd_err *err)
{
    njob *j = ctx;
    int K = j->K;
    tls *t = j->t[tid];
    size_t a = blk * QBLOCK, m = j->count - a < QBLOCK ? j->count - a : QBLOCK;
    uint32_t q[QBLOCK];
    for (size_t i = 0; i < m; i++)
        q[i] = j->list[j->qslot ? j->qslot[a + i] : j->first + a + i];
    /* contiguous slots get their lists in place; scattered ones through the thread's buffer */
    uint32_t *idx = j->qslot ? t->idx : j->nbr + (j->first + a) * K;
    int rc = prep_knn_query(j->kn, q, 0, m, K, idx, t->d2, j->ks[tid], err);
    if (rc != 0) return rc;
    for (size_t i = 0; i < m; i++) {
        size_t s = j->qslot ? j->qslot[a + i] : j->first + a + i;
        if (j->qslot) memcpy(j->nbr + s * K, idx + i * K, (size_t)K * sizeof *idx);
        j->kd2[s] = t->d2[i * K + K - 1];
        if (j->nn2) j->nn2[s] = t->d2[i * K];
    }
    return 0;
}

static int nj_pca(void *ctx, size_t blk, int tid, sd_err *err)
{
    njob *j = ctx;
    (void)tid;
    (void)err;
    size_t a = blk * QBLOCK, e = a + QBLOCK < j->count ? a + QBLOCK : j->count;
    float inv_sqrt_k = (float)(1.0 / sqrt((double)j->K));
    for (size_t i = a; i < e; i++) {
        j->r20[i] = 2.0f * sqrtf(j->kd2[i]) * inv_sqrt_k;
        prep_pca_normal(j->r->pos, j->list[i], j->nbr + i * j->K, j->K, j->nrm + 3 * i, j->svar + i);
        prep_orient_normal(j->nrm + 3 * i, j->r->pos + 3 * (size_t)j->list[i], j->b->centroid,
               j->b->info.has_viewpoint, j->vp);
    }
    return 0;
}

static int nj_own(void *ctx, size_t blk, int tid, sd_err *err)
{
    njob *j = ctx;
    int K = j->K;
    tls *t = j->t[tid];
    size_t a = blk * QBLOCK, e = a + QBLOCK < j->count ? a + QBLOCK : j->count;
    for (size_t i = a; i < e; i++) {
        const uint32_t *nb = j->nbr + i * K;
        const float *ni = j->nrm + 3 * i;
        float s = 0, rn[PREP_MAX_K];
        for (int q = 0; q < K; q++) {
            int32_t sq = j->slot[nb[q]];
            const float *nq = j->nrm + 3 * (size_t)sq;
            float dd = fabsf(ni[0] * nq[0] + ni[1] * nq[1] + ni[2] * nq[2]);
            if (dd > 1) dd = 1;
            float tt = 2 - dd;
            s += tt * tt;
            rn[q] = j->r20[sq];
        }
        arec *o = &t->out[i - a];
        memcpy(o->normal, ni, 12);
        o->r20 = j->r20[i];
        o->capn = PREP_RADIUS_CAP * prep_percentile(rn, (size_t)K, 0.5);
        o->svar = j->svar[i];
        float f = j->r20[i] * s / (float)K;
        o->Fraw = f >= 0 && f <= FLT_MAX ? f : 0.0f;
        o->nnd = sqrtf(j->nn2[i]);
        t->hist[0][fbits(o->r20) >> 16]++;
        t->hist[1][fbits(o->Fraw) >> 16]++;
        t->hist[2][fbits(o->nnd) >> 16]++;
    }
    if (cf_pwrite_all(j->fd_out, t->out, (e - a) * sizeof *t->out, a * sizeof *t->out))
        return sd_errf(err, SD_EIO, "lod: cannot write a scratch file: %s", strerror(errno));
    return 0;
}

static size_t nblocks(size_t n)
{
    return (n + QBLOCK - 1) / QBLOCK;
}

/* The slots s (of nq) whose ball (k-th distance) leaves the region: their count; the halo the
 * balls need (those inside too) grows *need. */
static size_t check_balls(const build *b, const chunk *c, const region *r, const njob *j,
                          size_t first, size_t n, uint8_t *exact, float *need)
{
    size_t bad = 0;
    for (size_t s = first; s < first + n; s++) {
        if (exact && exact[s]) continue;
        const float *pp = r->pos + 3 * (size_t)j->list[s];
        float nd = halo_need(c, pp, j->kd2[s]); /* of every ball: the next chunk's first halo */
        if (nd > *need) *need = nd;
        if (inside(r, pp, j->kd2[s])) {
            if (exact) exact[s] = 1;
            continue;
        }
        bad++;
    }
    (void)b;
    return bad;
}

/* The checks after the chunk's own queries, in parallel over blocks of own slots: whose ball
 * leaves the region (with the halo they need), and the neighbours that are not own points. */
typedef struct cblock {
    size_t bad, n, cap;
    float need;
    uint32_t *x;              /* halo neighbours met in the block (repeats included) */
} cblock;

typedef struct cjob {
    build *b;
    const chunk *c;
    const region *r;
    const njob *j;
    uint8_t *exact;           /* NULL: the region is the whole cloud, every ball is inside */
    cblock *blk;
} cjob;

static int nj_check(void *ctx, size_t blk, int tid, sd_err *err)
{
    cjob *cj = ctx;
    (void)tid;
    const njob *j = cj->j;
    cblock *o = &cj->blk[blk];
    size_t a = blk * QBLOCK, e = a + QBLOCK < j->count ? a + QBLOCK : j->count;
    if (cj->exact) o->bad = check_balls(cj->b, cj->c, cj->r, j, a, e - a, cj->exact, &o->need);
    if (o->bad) return 0;
    for (size_t s = a; s < e; s++)
        for (int q = 0; q < j->K; q++) {
            uint32_t pq = j->nbr[s * (size_t)j->K + q];
            if (cj->r->own[pq]) continue;
            if (o->n == o->cap) {
                size_t nc = o->cap ? 2 * o->cap : 256;
                uint32_t *x = realloc(o->x, nc * sizeof *x);
                if (!x) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
                o->x = x;
                o->cap = nc;
            }
            o->x[o->n++] = pq;
        }
    return 0;
}

/* The chunk's own results across a halo that grew: the neighbours of the own points found
 * exact in the smaller region old, renamed to the indices of the same points in r (a
 * superset, both in (code, file index) order). */
static void remap_own(const region *old, const region *r, njob *j, size_t nown,
                      const uint8_t *exact)
{
    uint32_t *map = (uint32_t *)j->slot; /* free until the slots are assigned */
    for (size_t i = 0, k = 0; i < old->m; i++) {
        while (r->gidx[k] != old->gidx[i]) k++;
        map[i] = (uint32_t)k++;
    }
    for (size_t s = 0; s < nown; s++)
        if (exact[s])
            for (int q = 0; q < j->K; q++) j->nbr[s * j->K + q] = map[j->nbr[s * j->K + q]];
}

/* The normals and radii of slots [nu, ns): halo neighbours whose chunks are done, from those
 * chunks' records (slots in region order: by chunk, then by record; records close together
 * read at once). */
static int read_known(build *b, const region *r, njob *j, size_t nu, size_t ns, sd_err *err)
{
    enum { SPAN = 256 };
    arec buf[SPAN];
    for (size_t s = nu; s < ns;) {
        uint32_t ck = r->chk[j->list[s]], f0 = r->fidx[j->list[s]];
        size_t e = s + 1;
        while (e < ns && r->chk[j->list[e]] == ck && r->fidx[j->list[e]] - f0 < SPAN) e++;
        uint32_t f1 = r->fidx[j->list[e - 1]] + 1;
        if (cf_pread_all(b->chunks[ck].fd_a, buf, (f1 - f0) * sizeof *buf, (uint64_t)f0 * sizeof *buf))
            return sd_errf(err, SD_EIO, "lod: cannot read a scratch file: %s", strerror(errno));
        for (; s < e; s++) {
            const arec *a = &buf[r->fidx[j->list[s]] - f0];
            memcpy(j->nrm + 3 * s, a->normal, 12);
            j->r20[s] = a->r20;
        }
    }
    return 0;
}

/* Block 0: the known halo neighbours' normals and radii (read_known, serial: its reads overlap
 * the normals of the others); blocks 1..: nj_pca's blocks 0... They fill disjoint slots. */
static int nj_pca_known(void *ctx, size_t blk, int tid, sd_err *err)
{
    njob *j = ctx;
    return blk == 0 ? read_known(j->b, j->r, j, j->nu, j->ns, err) : nj_pca(ctx, blk - 1, tid, err);
}

enum { PH_LOAD, PH_INDEX, PH_QOWN, PH_CHECK, PH_QNBR, PH_PCA, PH_F, PH_N };

/* One of the normals pass's arrays, at least bytes long, its contents kept when it grows. The
 * arrays live across chunks (grown, never shrunk): each chunk reuses the pages the previous
 * ones faulted in instead of faulting in fresh ones (at 10M points that was a third of the
 * build's system time). NULL when out of memory. */
static void *keep_buf(build *b, int which, size_t bytes)
{
    if (bytes == 0) bytes = 1;
    if (bytes > b->keepcap[which]) {
        void *p = realloc(b->keep[which], bytes);
        if (!p) return NULL;
        b->keep[which] = p;
        b->keepcap[which] = bytes;
    }
    return b->keep[which];
}

static void phase_end(build *b, int ph, double *t)
{
    double now = now_s();
    b->tph[ph] += now - *t;
    *t = now;
}

/* The halo chunk ci starts from: the one the previous chunk ended with (a good guess for the
 * next one) or the count grid's bound when that is smaller or there is no previous chunk
 * (lod_desc.halo_first replaces the bound). */
static float first_halo(const build *b, size_t ci)
{
    const chunk *c = &b->chunks[ci];
    float hb = b->d->halo_first > 0 ? b->d->halo_first * (c->hi[0] - c->lo[0]) : c->hb;
    return b->halo > 0 && b->halo < hb ? b->halo : hb;
}

/* The normals pass of chunk ci (the chunks run one after the other, each on every thread).
 * When a ball leaves the region, the halo grows to hold it and the region is loaded again; the
 * own points already exact keep their neighbours (renamed to the new region), only the others
 * are queried again. */
static int chunk_normals(void *ctx, size_t ci, int tid_unused, sd_err *err)
{
    build *b = ctx;
    (void)tid_unused;
    chunk *c = &b->chunks[ci];
    if (!c->count) return 0;
    int K = b->K, T = b->threads;
    float h = first_halo(b, ci);
    prep_knn_scratch *ks[64] = {0};
    tls *tl[64] = {0};
    if (T > 64) T = 64;
    int rc = 0;
    for (int t = 0; t < T && rc == 0; t++) {
        ks[t] = prep_knn_scratch_new();
        tl[t] = calloc(1, sizeof *tl[t]);
        if (!ks[t] || !tl[t]) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory");
    }
    size_t nown = c->count;
    njob j;
    memset(&j, 0, sizeof j);
    j.b = b, j.K = K, j.ks = ks, j.t = tl;
    for (int a = 0; a < 3; a++) j.vp[a] = b->info.viewpoint[a] - b->info.offset[a];
    j.nbr = keep_buf(b, KB_NBR, nown * (size_t)K * 4);
    j.kd2 = keep_buf(b, KB_KD2, nown * 4);
    j.nn2 = keep_buf(b, KB_NN2, nown * 4);
    uint8_t *exact = keep_buf(b, KB_EXACT, nown);
    uint32_t *redo = keep_buf(b, KB_REDO, nown * 4);
    if (rc == 0 && (!j.nbr || !j.kd2 || !j.nn2 || !exact || !redo))
        rc = sd_errf(err, SD_ENOMEM, "lod: out of memory");
    if (rc == 0) memset(exact, 0, nown);
    region r, old;
    memset(&r, 0, sizeof r);
    memset(&old, 0, sizeof old);
    int attempt = 0;
    float need_done = 0;      /* the halo the balls needed, once done */
    while (rc == 0) {
        double t = now_s();
        int got = attempt == 0 && b->pf ? prefetch_take(b->pf, ci, h, &r, err) : 1;
        if (got < 0) {
            rc = got;
            break;
        }
        if (got > 0) rc = load_region(b, ci, h, &r, err);
        if (rc < 0) break;
        /* the next chunk's region loads meanwhile, with the halo this one starts from */
        if (attempt == 0 && b->pf && ci + 1 < b->nchunks) prefetch_start(b->pf, b, ci + 1, h);
        phase_end(b, PH_LOAD, &t);
        b->nread += r.nread;
        b->load_cpu += r.cpu;
        size_t m = r.m;
        int full = r.edge[0] && r.edge[1] && r.edge[2] && r.edge[3] && r.edge[4] && r.edge[5];
        j.r = &r;
        prep_knn *kn = NULL;
        int done = 0;
        float need = 0;
        j.slot = keep_buf(b, KB_SLOT, m * sizeof *j.slot);
        j.list = keep_buf(b, KB_LIST, m * sizeof *j.list);
        if (!j.slot || !j.list) { rc = sd_errf(err, SD_ENOMEM, "lod: out of memory"); goto next; }
        if (attempt > 0) remap_own(&old, &r, &j, nown, exact);
        region_put(b, &old);
        size_t ns = 0;
        for (size_t i = 0; i < m; i++) {
            j.slot[i] = -1;
            if (r.own[i]) j.slot[i] = (int32_t)ns, j.list[ns++] = (uint32_t)i;
        }
        if ((size_t)K >= m) { /* too few points to query: the whole cloud, or a bigger halo */
            if (full) rc = sd_errf(err, SD_EINVAL, "lod: %zu points for k = %d", m, K);
            goto next;
        }
        /* in the cloud's frame the region is in Morton order already: no sort, and the
         * queries (region order) run in the index's order */
        prep_knn_opts ko = {.frame = &b->f, .codes = r.code};
        rc = prep_knn_build(r.pos, m, &ko, &kn, err);
        if (rc < 0) goto next;
        phase_end(b, PH_INDEX, &t);
        j.kn = kn;
        size_t nq = 0;
        for (size_t s = 0; s < nown; s++)
            if (!exact[s]) redo[nq++] = (uint32_t)s;
        j.qslot = nq < nown ? redo : NULL, j.first = 0, j.count = nq;
        prep_knn_counters k0[64];
        for (int q = 0; q < T; q++) prep_knn_scratch_counters(ks[q], &k0[q]);
        rc = prep_par_for(T, nblocks(nq), nj_query, &j, NULL, err);
        if (rc < 0) goto next;
        for (int q = 0; q < T; q++) {
            prep_knn_counters k1;
            prep_knn_scratch_counters(ks[q], &k1);
            b->kc.queries += k1.queries - k0[q].queries;
            b->kc.candidates += k1.candidates - k0[q].candidates;
            b->kc.gathers += k1.gathers - k0[q].gathers;
            b->kc.widened += k1.widened - k0[q].widened;
        }
        phase_end(b, PH_QOWN, &t);
        /* A result is exact when its ball lies in the region; else the region grows to the
         * farthest ball (the computed k-th distance bounds the true one from above). */
        if (full) memset(exact, 1, nown);
        cjob cj = {.b = b, .c = c, .r = &r, .j = &j, .exact = full ? NULL : exact};
        j.first = 0, j.count = nown;
        size_t nb = nblocks(nown);
        cj.blk = calloc(nb ? nb : 1, sizeof *cj.blk);
        if (!cj.blk) { rc = sd_errf(err, SD_ENOMEM, "lod: out of memory"); goto next; }
        rc = prep_par_for(T, nb, nj_check, &cj, NULL, err);
        size_t bad = 0;
        for (size_t i = 0; i < nb; i++) {
            bad += cj.blk[i].bad;
            if (cj.blk[i].need > need) need = cj.blk[i].need;
        }
        /* the halo neighbours once each, in region (Morton) order (the grid search is fast
         * for queries in that order only, knn.h): marked in the slot array (-2), then taken
         * in a scan of the region, no sort of the repeats. The neighbours of chunks done
         * already take slots [nu, ns): their normals and radii are in those chunks' records,
         * the same values a query here would give (exact neighbours, the same order, the
         * same arithmetic); the others [nown, nu). The chunks go through this pass one
         * after another in index order (on one thread: prep_par_for(1, ...), which the
         * prefetch of ci + 1 counts on too), so the chunks done are those before ci. */
        size_t nu = ns;
        if (rc == 0 && bad == 0) {
            for (size_t i = 0; i < nb; i++)
                for (size_t q = 0; q < cj.blk[i].n; q++) j.slot[cj.blk[i].x[q]] = -2;
            /* one scan: the others take their slots, the known ones wait in kl */
            uint32_t *kl = keep_buf(b, KB_KNOWN, m * sizeof *kl);
            if (!kl) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory");
            size_t nk = 0;
            for (size_t i = 0; kl && i < m; i++)
                if (j.slot[i] == -2) {
                    if (r.chk[i] < ci) kl[nk++] = (uint32_t)i;
                    else j.slot[i] = (int32_t)ns, j.list[ns++] = (uint32_t)i;
                }
            nu = ns;
            for (size_t q = 0; q < nk; q++) j.slot[kl[q]] = (int32_t)ns, j.list[ns++] = kl[q];
        }
        for (size_t i = 0; i < nb; i++) free(cj.blk[i].x);
        free(cj.blk);
        if (rc < 0 || bad > 0) goto next;
        phase_end(b, PH_CHECK, &t);
        uint32_t *nb2 = keep_buf(b, KB_NBR, ns * (size_t)K * 4);
        float *kd2 = nb2 ? keep_buf(b, KB_KD2, ns * 4) : NULL;
        if (!nb2 || !kd2) { rc = sd_errf(err, SD_ENOMEM, "lod: out of memory"); goto next; }
        j.nbr = nb2, j.kd2 = kd2;
        float *nn2 = j.nn2;
        j.nn2 = NULL, j.qslot = NULL, j.first = nown, j.count = nu - nown;
        if (nu > nown) rc = prep_par_for(T, nblocks(nu - nown), nj_query, &j, NULL, err);
        j.nn2 = nn2;
        if (rc < 0) goto next;
        if (!full && check_balls(b, c, &r, &j, nown, nu - nown, NULL, &need) > 0) goto next;
        phase_end(b, PH_QNBR, &t);
        j.r20 = keep_buf(b, KB_R20, ns * 4);
        j.nrm = keep_buf(b, KB_NRM, ns * 12);
        j.svar = keep_buf(b, KB_SVAR, ns * 4);
        if (!j.r20 || !j.nrm || !j.svar) { rc = sd_errf(err, SD_ENOMEM, "lod: out of memory"); goto next; }
        j.first = 0, j.count = nu;
        j.nu = nu, j.ns = ns;
        rc = prep_par_for(T, 1 + nblocks(nu), nj_pca_known, &j, NULL, err);
        if (rc < 0) goto next;
        phase_end(b, PH_PCA, &t);
        j.count = nown, j.fd_out = c->fd_a;
        rc = prep_par_for(T, nblocks(nown), nj_own, &j, NULL, err);
        if (rc < 0) goto next;
        phase_end(b, PH_F, &t);
        done = 1;
        need_done = need;
    next:
        prep_knn_free(kn);
        if (rc < 0 || done) break;
        /* keep what is exact, grow the halo, load again */
        attempt++;
        c->retried = 1;
        b->halo = 0;
        h = need * 1.05f > h * 1.5f ? need * 1.05f : h * 1.5f;
        old = r;
        memset(&r, 0, sizeof r);
    }
    if (rc < 0 && b->pf) { /* nothing more will take it */
        region tmp;
        memset(&tmp, 0, sizeof tmp);
        if (prefetch_take(b->pf, b->pf->ci, 0, &tmp, NULL) == 0) region_put(b, &tmp);
    }
    /* the next chunk starts from the halo this one grew to, or from the one its balls needed
     * (with a regrown halo's margin) when it did not grow: the count grid's bound is loose */
    if (rc == 0 && c->retried) b->halo = h;
    else if (rc == 0 && need_done * 1.05f > b->halo) b->halo = need_done * 1.05f;
    if (rc == 0) { /* a status line per chunk: the normals pass is most of the build */
        b->normals_done += c->count;
        status(b, "normals", 0.12 + 0.63 * (double)b->normals_done / (double)b->info.n,
               b->normals_done, now_s() - b->t_pass);
    }
    for (int t = 0; t < T; t++) {
        if (rc == 0 && tl[t])
            for (int q = 0; q < 3; q++)
                for (int i = 0; i < 65536; i++) b->hist_hi[q][i] += tl[t]->hist[q][i];
        prep_knn_scratch_free(ks[t]);
        free(tl[t]);
    }
    region_put(b, &r);
    region_put(b, &old);
    return rc; /* the arrays stay in b->keep for the next chunk */
}

/* ---- quantiles ---- */

static float qvalue(const build *b, int q, const arec *a, float radius)
{
    switch (b->qs[q].which) {
    case 0: return a->r20;
    case 1: return a->Fraw;
    case 2: return a->nnd;
    default: return radius;
    }
}

/* The bucket of the wanted rank in hi hist h. */
static void pick_bucket(build *b, int q, const uint64_t *h, uint64_t n)
{
    uint64_t want = (uint64_t)floor(b->qs[q].q * (double)(n - 1) + 0.5), below = 0;
    uint32_t k = 0;
    while (k < 65535 && below + h[k] <= want) below += h[k++];
    b->qs[q].hi = k;
    b->qs[q].rank = want - below;
}

static float pick_value(build *b, int q)
{
    uint64_t below = 0;
    uint32_t k = 0;
    while (k < 65535 && below + b->qs[q].lo[k] <= b->qs[q].rank) below += b->qs[q].lo[k++];
    uint32_t u = b->qs[q].hi << 16 | k;
    float v;
    memcpy(&v, &u, 4);
    return v;
}

enum { AREC_BLOCK = 1 << 16 }; /* records read at a time by the passes after the normals */

typedef void (*arec_fn)(void *ctx, const arec *a, const rec *r, size_t n, size_t first);

/* Calls fn(ctx, records, chunk records (with_rec) or NULL, count, first index) for chunk ci's
 * records, AREC_BLOCK at a time through one buffer (the passes after the normals pass stream
 * the records: no chunk-sized buffer and its fresh pages each pass). */
static int each_arec_block(build *b, size_t ci, int with_rec, arec_fn fn, void *ctx, sd_err *err)
{
    const chunk *c = &b->chunks[ci];
    size_t blk = c->count < AREC_BLOCK ? c->count : AREC_BLOCK;
    arec *a = malloc((blk ? blk : 1) * sizeof *a);
    rec *r = with_rec ? malloc((blk ? blk : 1) * sizeof *r) : NULL;
    if (!a || (with_rec && !r)) {
        free(a);
        free(r);
        return sd_errf(err, SD_ENOMEM, "lod: out of memory for a chunk");
    }
    int rc = 0;
    for (size_t i = 0; i < c->count && rc == 0; i += blk) {
        size_t m = c->count - i < blk ? c->count - i : blk;
        if (cf_pread_all(c->fd_a, a, m * sizeof *a, i * sizeof *a) ||
            (r && cf_pread_all(c->fd_in, r, m * sizeof *r, i * sizeof *r)))
            rc = sd_errf(err, SD_EIO, "lod: cannot read a scratch file: %s", strerror(errno));
        else
            fn(ctx, a, r, m, i);
    }
    free(a);
    free(r);
    return rc;
}

static float final_radius(const build *b, const arec *a)
{
    float cap = a->capn;
    if (a->svar > PREP_SURFACE_VAR_MAX && cap > b->scatter_cap) cap = b->scatter_cap;
    return a->r20 > cap ? cap : a->r20;
}

static float final_F(const build *b, float raw)
{
    float v = b->p99 > 0 ? raw / b->p99 : (raw > 0 ? 1.0f : 0.0f);
    return v < 0 ? 0 : (v > 1 ? 1 : v);
}

/* A counting pass over the normals pass's records: with b->radius_pass 0 the bottom-16-bit
 * histograms of the NQ quantiles' buckets, with 1 the top-16-bit histogram of the final radii. */
typedef struct hctx {
    build *b;
    uint64_t *h;              /* the thread's counters (tcount) */
} hctx;

static void hist_block(void *ctx, const arec *a, const rec *r, size_t n, size_t first)
{
    hctx *x = ctx;
    const build *b = x->b;
    (void)first;
    (void)r;
    for (size_t i = 0; i < n; i++) {
        if (b->radius_pass) {
            x->h[fbits(final_radius(b, &a[i])) >> 16]++;
            continue;
        }
        for (int q = 0; q < NQ; q++) {
            uint32_t u = fbits(qvalue(b, q, &a[i], 0));
            if (u >> 16 == b->qs[q].hi) x->h[(size_t)q << 16 | (u & 0xffff)]++;
        }
    }
}

static int chunk_hist(void *ctx, size_t ci, int tid, sd_err *err)
{
    build *b = ctx;
    hctx x = {.b = b, .h = b->tcount + (size_t)tid * NQ * 65536};
    return each_arec_block(b, ci, 0, hist_block, &x, err);
}

static int by_size(build *b, prep_par_fn fn, prep_progress *pr, sd_err *err);

/* A counting pass over the chunks on every thread, each into counters of its own, then added
 * up (into the NQ bottom histograms, or with radius_pass into the final radii's top one). */
static int hist_pass(build *b, sd_err *err)
{
    size_t per = (size_t)NQ * 65536;
    memset(b->tcount, 0, (size_t)b->threads * per * sizeof *b->tcount);
    int rc = by_size(b, chunk_hist, NULL, err);
    for (int t = 0; rc == 0 && t < b->threads; t++) {
        const uint64_t *h = b->tcount + (size_t)t * per;
        for (size_t i = 0; i < 65536; i++) {
            if (b->radius_pass) {
                b->hist_hi[3][i] += h[i];
                continue;
            }
            for (int q = 0; q < NQ; q++) b->qs[q].lo[i] += h[(size_t)q << 16 | i];
        }
    }
    return rc;
}

/* ---- octree ---- */

typedef struct pt {           /* a point with its final values */
    uint64_t code;
    uint32_t gidx, rgba;
    float pos[3], normal[3], radius, F;
    int surface;              /* its neighbourhood is a surface (prep.h step 4) */
} pt;

static float spacing_of(const build *b, int level)
{
    return (float)(b->f.side / (double)((uint64_t)1 << (level + b->g)));
}

static int add_node(build *b, const lod_node *n, sd_err *err)
{
    pthread_mutex_lock(&b->mu);
    if (b->nnodes == b->capnodes) {
        size_t nc = b->capnodes ? 2 * b->capnodes : 256;
        nodeent *x = realloc(b->nodes, nc * sizeof *x);
        if (!x) {
            pthread_mutex_unlock(&b->mu);
            return sd_errf(err, SD_ENOMEM, "lod: out of memory for the node table");
        }
        b->nodes = x;
        b->capnodes = nc;
    }
    b->nodes[b->nnodes++].n = *n;
    pthread_mutex_unlock(&b->mu);
    return 0;
}

/* Writes one node of cnt points p[idx[i]] (inner: radius_lod covers the spacing). */
/* The order of a node's points in the file: surface points first, then scattered ones (noise,
 * vegetation), each group in a fixed pseudo-random order (a hash of the file index). A frame
 * whose budget ends inside a node draws a prefix of it: so that prefix is a uniform sample
 * of the node, surfaces first, not one corner of it (the Morton order the points come in). */
static uint32_t mix32(uint32_t v)
{
    v ^= v >> 16;
    v *= 0x7feb352dU;
    v ^= v >> 15;
    v *= 0x846ca68bU;
    v ^= v >> 16;
    return v;
}

static int emit(build *b, const pt *p, const uint32_t *idx_in, size_t cnt, int level,
                uint64_t code, int inner, sd_err *err)
{
    size_t len = (size_t)lod_node_bytes((uint32_t)cnt);
    float *buf = malloc(len ? len : 1);
    uint64_t *key = malloc((cnt ? cnt : 1) * sizeof *key);
    uint32_t *idx = malloc((cnt ? cnt : 1) * sizeof *idx);
    if (!buf || !key || !idx) {
        free(buf);
        free(key);
        free(idx);
        return sd_errf(err, SD_ENOMEM, "lod: out of memory for a node");
    }
    for (size_t i = 0; i < cnt; i++) {
        const pt *q = &p[idx_in[i]];
        key[i] = (uint64_t)!q->surface << 63 | (uint64_t)mix32(q->gidx) << 31 | q->gidx;
        idx[i] = idx_in[i];
    }
    int rc = prep_radix_sort64(key, idx, cnt, err); /* the keys differ (file indices do) */
    free(key);
    if (rc < 0) {
        free(buf);
        free(idx);
        return rc;
    }
    float *pos = buf, *nrm = pos + 3 * cnt, *rad = nrm + 3 * cnt, *rl = rad + cnt, *F = rl + cnt;
    uint32_t *rgba = (uint32_t *)(F + cnt);
    float sp = spacing_of(b, level);
    lod_node n;
    memset(&n, 0, sizeof n);
    for (int a = 0; a < 3; a++) n.bmin[a] = INFINITY, n.bmax[a] = -INFINITY;
    for (size_t i = 0; i < cnt; i++) {
        const pt *q = &p[idx[i]];
        memcpy(pos + 3 * i, q->pos, 12);
        memcpy(nrm + 3 * i, q->normal, 12);
        rad[i] = q->radius;
        /* scattered points (noise, vegetation) stay points: a disc of the spacing of a
         * coarse level would cover the scene with their random orientations */
        rl[i] = inner && q->surface && q->radius < sp ? sp : q->radius;
        F[i] = q->F;
        rgba[i] = q->rgba;
        for (int a = 0; a < 3; a++) {
            if (q->pos[a] < n.bmin[a]) n.bmin[a] = q->pos[a];
            if (q->pos[a] > n.bmax[a]) n.bmax[a] = q->pos[a];
        }
    }
    n.count = (uint32_t)cnt;
    n.level = (uint8_t)level;
    n.code = code;
    n.spacing = sp;
    n.hash = sd_hash64(buf, len, 0);
    rc = lod__writer_append(&b->w, buf, len, &n.offset, err);
    free(buf);
    free(idx);
    return rc < 0 ? rc : add_node(b, &n, err);
}

typedef struct octx {
    build *b;
    pt *p;
    uint32_t *scratch;
    int cdepth;
    urec *up;
    size_t nup, capup;
} octx;

static int keep_upper(octx *o, const uint32_t *idx, size_t cnt, int level, uint64_t code,
                      sd_err *err)
{
    if (o->nup + cnt > o->capup) {
        size_t nc = (o->nup + cnt) * 2;
        urec *x = realloc(o->up, nc * sizeof *x);
        if (!x) return sd_errf(err, SD_ENOMEM, "lod: out of memory for the upper levels");
        o->up = x;
        o->capup = nc;
    }
    for (size_t i = 0; i < cnt; i++) {
        const pt *q = &o->p[idx[i]];
        urec *u = &o->up[o->nup++];
        memset(u, 0, sizeof *u);
        u->code = q->code;
        u->node = code;
        u->gidx = q->gidx;
        u->level = (uint32_t)level;
        memcpy(u->pos, q->pos, 12);
        memcpy(u->normal, q->normal, 12);
        u->radius = q->radius;
        u->F = q->F;
        u->rgba = q->rgba;
        u->surface = (uint32_t)q->surface;
    }
    return 0;
}

/* The node (level, code) over the points idx[0..cnt) (ascending order), top down. */
static int process(octx *o, uint32_t *idx, size_t cnt, int level, uint64_t code, sd_err *err)
{
    build *b = o->b;
    int inside = level >= o->cdepth;
    if (inside && (cnt <= b->d->leaf_max || level == LOD_MAX_LEVEL))
        return emit(b, o->p, idx, cnt, level, code, 0, err);
    int depth = level + b->g;
    int shift = 3 * (PREP_MORTON_BITS - depth);
    double cell = b->f.side / (double)((uint64_t)1 << depth);
    size_t nsel = 0, nrest = 0;
    uint32_t *rest = o->scratch;
    for (size_t i = 0; i < cnt;) {
        uint64_t cc = o->p[idx[i]].code >> shift;
        size_t j = i;
        uint32_t x, y, z;
        prep_morton_decode(cc, &x, &y, &z);
        double cen[3] = {b->f.origin[0] + (x + 0.5) * cell, b->f.origin[1] + (y + 0.5) * cell,
                         b->f.origin[2] + (z + 0.5) * cell};
        /* the surface point nearest the centre; where the cell has none, the scattered one
         * nearest it among those a hash lets through (one in LOD_SCATTER_KEEP) */
        size_t best = SIZE_MAX;
        int best_surf = 0;
        double bd = INFINITY;
        while (j < cnt && o->p[idx[j]].code >> shift == cc) {
            const pt *q = &o->p[idx[j]];
            if (q->surface || mix32(q->gidx) % LOD_SCATTER_KEEP == 0) {
                double d = 0;
                for (int a = 0; a < 3; a++) d += (q->pos[a] - cen[a]) * (q->pos[a] - cen[a]);
                if ((q->surface && !best_surf) || (q->surface == best_surf && d < bd))
                    bd = d, best = j, best_surf = q->surface;
            }
            j++;
        }
        for (size_t k = i; k < j; k++)
            if (k != best) rest[nrest++] = idx[k];
        if (best != SIZE_MAX) idx[nsel++] = idx[best];
        i = j;
    }
    if (!nsel && nrest) { /* a node has a point at least: the first one */
        idx[nsel++] = rest[0];
        memmove(rest, rest + 1, --nrest * sizeof *rest);
    }
    /* idx = [selected | rest], both in order */
    memcpy(idx + nsel, rest, nrest * sizeof *idx);
    int rc = inside ? emit(b, o->p, idx, nsel, level, code, nrest > 0, err)
                    : keep_upper(o, idx, nsel, level, code, err);
    if (rc < 0) return rc;
    uint32_t *r = idx + nsel;
    int cshift = 3 * (PREP_MORTON_BITS - (level + 1));
    for (size_t i = 0; i < nrest && rc == 0;) {
        uint64_t cc = o->p[r[i]].code >> cshift;
        size_t j = i;
        while (j < nrest && o->p[r[j]].code >> cshift == cc) j++;
        rc = process(o, r + i, j - i, level + 1, cc, err);
        i = j;
    }
    return rc;
}

typedef struct final_job {
    build *b;
    pt *p;
    uint32_t *idx, *lo;
} final_job;

/* A block of a chunk's records with their final values, into the octree pass's points. */
static void final_block(void *ctx, const arec *a, const rec *r, size_t n, size_t first)
{
    final_job *f = ctx;
    build *b = f->b;
    for (size_t k = 0; k < n; k++) {
        pt *q = &f->p[first + k];
        q->code = prep_morton_code(&b->f, r[k].pos);
        q->gidx = r[k].gidx;
        q->rgba = r[k].rgba;
        memcpy(q->pos, r[k].pos, 12);
        memcpy(q->normal, a[k].normal, 12);
        q->radius = final_radius(b, &a[k]);
        q->F = final_F(b, a[k].Fraw);
        /* a surface point: a planar neighbourhood, and not a stray point whose radius the
         * neighbours' radii had to limit (prep.h step 4): noise above a plane has planar
         * neighbours, but its own eq. 20 radius reaches down to them */
        q->surface = !(a[k].svar > PREP_SURFACE_VAR_MAX) && !(a[k].r20 > a[k].capn);
        f->idx[first + k] = (uint32_t)(first + k);
        uint32_t u = fbits(q->radius);
        if (u >> 16 == b->qs[NQ].hi) f->lo[u & 0xffff]++;
    }
}

static int chunk_octree(void *ctx, size_t ci, int tid, sd_err *err)
{
    build *b = ctx;
    chunk *c = &b->chunks[ci];
    int rc = 0;
    uint64_t n = c->count;
    pt *p = tkeep(b, tid, 0, n * sizeof *p);
    uint32_t *idx = tkeep(b, tid, 1, n * 4), *scr = tkeep(b, tid, 2, n * 4);
    uint32_t *lo = calloc(65536, 4);
    if (!p || !idx || !scr || !lo) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory for a chunk");
    final_job fj = {.b = b, .p = p, .idx = idx, .lo = lo};
    if (rc == 0) rc = each_arec_block(b, ci, 1, final_block, &fj, err);
    /* the chunk's scratch files are not read again: their pages go now */
    close(c->fd_in);
    close(c->fd_a);
    c->fd_in = c->fd_a = -1;
    octx o = {.b = b, .p = p, .scratch = scr, .cdepth = (int)c->depth};
    if (rc == 0 && n) rc = process(&o, idx, n, 0, 0, err);
    pthread_mutex_lock(&b->mu);
    for (int i = 0; lo && i < 65536; i++) b->qs[NQ].lo[i] += lo[i];
    if (rc == 0 && o.nup) {
        if (b->nup + o.nup > b->capup) {
            size_t nc = (b->nup + o.nup) * 2;
            urec *x = realloc(b->up, nc * sizeof *x);
            if (!x) rc = sd_errf(err, SD_ENOMEM, "lod: out of memory for the upper levels");
            else b->up = x, b->capup = nc;
        }
        if (rc == 0) {
            memcpy(b->up + b->nup, o.up, o.nup * sizeof *o.up);
            b->nup += o.nup;
        }
    }
    pthread_mutex_unlock(&b->mu);
    free(o.up);
    free(lo);
    return rc;
}

static int cmp_urec(const void *x, const void *y)
{
    const urec *a = x, *b = y;
    if (a->level != b->level) return a->level < b->level ? -1 : 1;
    if (a->node != b->node) return a->node < b->node ? -1 : 1;
    if (a->code != b->code) return a->code < b->code ? -1 : 1;
    return a->gidx < b->gidx ? -1 : a->gidx > b->gidx;
}

static int emit_upper(build *b, sd_err *err)
{
    if (b->nup) qsort(b->up, b->nup, sizeof *b->up, cmp_urec);
    pt *p = malloc((b->nup ? b->nup : 1) * sizeof *p);
    uint32_t *idx = malloc((b->nup ? b->nup : 1) * 4);
    if (!p || !idx) {
        free(p);
        free(idx);
        return sd_errf(err, SD_ENOMEM, "lod: out of memory for the upper levels");
    }
    int rc = 0;
    for (size_t i = 0; i < b->nup; i++) {
        const urec *u = &b->up[i];
        p[i].code = u->code;
        p[i].gidx = u->gidx;
        p[i].rgba = u->rgba;
        memcpy(p[i].pos, u->pos, 12);
        memcpy(p[i].normal, u->normal, 12);
        p[i].radius = u->radius;
        p[i].F = u->F;
        p[i].surface = (int)u->surface;
        idx[i] = (uint32_t)i;
    }
    for (size_t i = 0; i < b->nup && rc == 0;) {
        size_t j = i;
        while (j < b->nup && b->up[j].level == b->up[i].level && b->up[j].node == b->up[i].node) j++;
        rc = emit(b, p, idx + i, j - i, (int)b->up[i].level, b->up[i].node, 1, err);
        i = j;
    }
    free(p);
    free(idx);
    return rc;
}

static int cmp_node(const void *x, const void *y)
{
    const lod_node *a = x, *b = y;
    if (a->level != b->level) return a->level < b->level ? -1 : 1;
    return a->code < b->code ? -1 : a->code > b->code;
}

/* The table: breadth-first order, links, subtree bounds and counts. */
static int link_table(build *b, lod_cloud *c, sd_err *err)
{
    size_t nn = b->nnodes;
    lod_node *t = malloc((nn ? nn : 1) * sizeof *t);
    if (!t) return sd_errf(err, SD_ENOMEM, "lod: out of memory for the node table");
    for (size_t i = 0; i < nn; i++) t[i] = b->nodes[i].n;
    qsort(t, nn, sizeof *t, cmp_node);
    if (!nn || t[0].level != 0) {
        free(t);
        return sd_errf(err, SD_EFORMAT, "lod: the octree has no root");
    }
    uint32_t depth = 0;
    for (size_t i = 0; i < nn; i++) {
        t[i].parent = UINT32_MAX;
        t[i].first_child = 0;
        t[i].nchildren = 0;
        if (t[i].level + 1u > depth) depth = t[i].level + 1u;
    }
    for (size_t i = 1; i < nn; i++) {
        lod_node key = {.level = (uint8_t)(t[i].level - 1), .code = t[i].code >> 3};
        lod_node *par = bsearch(&key, t, i, sizeof *t, cmp_node);
        if (!par) {
            int lv = t[i].level;
            free(t);
            return sd_errf(err, SD_EFORMAT, "lod: node at level %d has no parent", lv);
        }
        uint32_t pi = (uint32_t)(par - t);
        t[i].parent = pi;
        if (!par->nchildren) par->first_child = (uint32_t)i;
        par->nchildren++;
    }
    for (size_t i = 0; i < nn; i++) {
        t[i].subtree_points = t[i].count;
        memcpy(t[i].sbmin, t[i].bmin, 12);
        memcpy(t[i].sbmax, t[i].bmax, 12);
    }
    for (size_t i = nn; i-- > 1;) {
        lod_node *par = &t[t[i].parent];
        par->subtree_points += t[i].subtree_points;
        for (int a = 0; a < 3; a++) {
            if (t[i].sbmin[a] < par->sbmin[a]) par->sbmin[a] = t[i].sbmin[a];
            if (t[i].sbmax[a] > par->sbmax[a]) par->sbmax[a] = t[i].sbmax[a];
        }
    }
    c->nodes = t;
    c->nnodes = nn;
    c->depth = depth;
    return 0;
}

static int cmp_size(const void *x, const void *y, void *ctx)
{
    const chunk *c = ctx;
    size_t i = *(const size_t *)x, j = *(const size_t *)y;
    if (c[i].count != c[j].count) return c[i].count > c[j].count ? -1 : 1;
    return i < j ? -1 : i > j;
}

typedef struct by_size_ctx {
    build *b;
    prep_par_fn fn;           /* called with the chunk's index */
} by_size_ctx;

static int by_size_fn(void *ctx, size_t i, int tid, sd_err *err)
{
    const by_size_ctx *x = ctx;
    return x->fn(x->b, x->b->order[i], tid, err);
}

/* prep_par_for over the chunks, the largest handed out first: chunks of unequal sizes in
 * file (Morton) order can leave a thread alone on a big last one; largest first bounds the
 * pass by max(largest, mean + largest / threads) or so. fn gets the chunk's index. */
static int by_size(build *b, prep_par_fn fn, prep_progress *pr, sd_err *err)
{
    if (!b->order) {
        b->order = malloc((b->nchunks ? b->nchunks : 1) * sizeof *b->order);
        if (!b->order) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
        for (size_t i = 0; i < b->nchunks; i++) b->order[i] = i;
        qsort_r(b->order, b->nchunks, sizeof *b->order, cmp_size, b->chunks);
    }
    by_size_ctx x = {.b = b, .fn = fn};
    return prep_par_for(b->threads, b->nchunks, by_size_fn, &x, pr, err);
}

static int run_build(build *b, const char *src, lod_src *s, lod_result *res, sd_err *err)
{
    const lod_desc *d = b->d;
    lod_src_get_info(s, &b->info);
    uint64_t n = b->info.n;
    b->K = (uint64_t)d->k < n ? d->k : (int)(n - 1);
    if (n < 2) return sd_errf(err, SD_EEMPTY, "%s: the LOD form needs 2 points or more", src);
    if (n >= ((uint64_t)1 << 32) - 1)
        return sd_errf(err, SD_ELIMIT, "%s: %llu points is over the LOD limit of 2^32 - 1", src,
                       (unsigned long long)n);
    float fb[6];
    for (int a = 0; a < 3; a++) {
        fb[a] = (float)(b->info.bmin[a] - b->info.offset[a]);
        fb[3 + a] = (float)(b->info.bmax[a] - b->info.offset[a]);
    }
    prep_morton_frame_of(fb, 2, &b->f);
    b->g = d->grid_bits;
    b->cdepth = d->grid_bits < COUNT_DEPTH_MAX ? d->grid_bits : COUNT_DEPTH_MAX;
    for (int q = 0; q < 4; q++) {
        b->hist_hi[q] = calloc(65536, sizeof(uint64_t));
        if (!b->hist_hi[q]) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
    }
    b->tk = calloc((size_t)b->threads * TK_N, sizeof *b->tk);
    b->tkcap = calloc((size_t)b->threads * TK_N, sizeof *b->tkcap);
    if (!b->tk || !b->tkcap) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
    int rc = count_and_distribute(b, s, err);
    if (rc == 0) {
        double ts = now_s();
        rc = by_size(b, chunk_sort, NULL, err);
        tkeep_free(b); /* not held through the normals pass */
        if (rc == 0) status(b, "sort", 0.14, b->info.n, now_s() - ts);
    }
    if (rc < 0) return rc;
    res->chunks = b->nchunks;
    prep_progress pr;
    double t = now_s();
    prep_progress_begin(&pr, d->progress, d->user, PROTO_PHASE_NORMALS);
    b->t_pass = t;
    prefetch pf;
    memset(&pf, 0, sizeof pf);
    b->pf = b->threads > 1 ? &pf : NULL;
    b->rpool = calloc(RPOOL, sizeof *b->rpool); /* NULL: every region has its own arrays */
    rc = prep_par_for(1, b->nchunks, chunk_normals, b, &pr, err); /* each chunk on every thread */
    b->pf = NULL;
    for (int i = 0; i < KB_N; i++) { /* the normals pass's arrays: not needed after it */
        free(b->keep[i]);
        b->keep[i] = NULL;
        b->keepcap[i] = 0;
    }
    region left;
    memset(&left, 0, sizeof left);
    if (prefetch_take(&pf, pf.ci, 0, &left, NULL) == 0) region_put(b, &left);
    for (int i = 0; i < RPOOL; i++) rbuf_free(&b->rpool[i]); /* not needed after the pass */
    free(b->rpool);
    b->rpool = NULL;
    if (rc < 0) return rc;
    prep_progress_end(&pr);
    size_t retried = 0;
    for (size_t i = 0; i < b->nchunks; i++) retried += b->chunks[i].retried;
    res->halo_retries = b->nchunks ? (double)retried / (double)b->nchunks : 0;
    if (d->status) { /* where the normals pass went, wall seconds */
        char line[384];
        double nq = b->kc.queries ? (double)b->kc.queries : 1.0; /* per query */
        snprintf(line, sizeof line,
                 "lod normals: region loads %.2f s (%.1fM records read, %.2f CPU s), indexes "
                 "%.2f, kNN of the chunks %.2f (%.0f candidates, %.3f gathers, %.4f widened a "
                 "query), ball checks %.2f, kNN of halo neighbours %.2f, normals %.2f, F %.2f "
                 "(with the scratch writes)",
                 b->tph[PH_LOAD], (double)b->nread / 1e6, b->load_cpu, b->tph[PH_INDEX],
                 b->tph[PH_QOWN], (double)b->kc.candidates / nq, (double)b->kc.gathers / nq,
                 (double)b->kc.widened / nq, b->tph[PH_CHECK], b->tph[PH_QNBR], b->tph[PH_PCA],
                 b->tph[PH_F]);
        d->status(d->user, line);
    }
    /* quantiles: r20 median, sigma, F p99 and the reported F percentiles */
    static const struct { int which; double q; } want[NQ] = {
        {0, 0.5}, {2, 0.5}, {1, 0.99}, {1, 0.01}, {1, 0.25}, {1, 0.5}, {1, 0.75}};
    for (int q = 0; q <= NQ; q++) {
        b->qs[q].which = q < NQ ? want[q].which : 3;
        b->qs[q].q = q < NQ ? want[q].q : 0.5;
        b->qs[q].lo = calloc(65536, sizeof(uint64_t));
        if (!b->qs[q].lo) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
        if (q < NQ) pick_bucket(b, q, b->hist_hi[b->qs[q].which], n);
    }
    t = now_s();
    prep_progress_begin(&pr, d->progress, d->user, PROTO_PHASE_FIELD);
    b->tcount = malloc((size_t)b->threads * NQ * 65536 * sizeof *b->tcount);
    if (!b->tcount) return sd_errf(err, SD_ENOMEM, "lod: out of memory");
    rc = hist_pass(b, err);
    if (rc < 0) return rc;
    for (int q = 0; q < NQ; q++) b->qs[q].value = pick_value(b, q);
    b->scatter_cap = PREP_SCATTER_CAP * b->qs[0].value;
    b->p99 = b->qs[2].value;
    b->radius_pass = 1;
    rc = hist_pass(b, err);
    if (rc < 0) return rc;
    pick_bucket(b, NQ, b->hist_hi[3], n);
    prep_progress_end(&pr);
    status(b, "quantiles", 0.82, n, now_s() - t);
    t = now_s();
    prep_progress_begin(&pr, d->progress, d->user, PROTO_PHASE_REORDER);
    rc = by_size(b, chunk_octree, &pr, err);
    tkeep_free(b);
    if (rc == 0) rc = emit_upper(b, err);
    if (rc < 0) return rc;
    prep_progress_end(&pr);
    status(b, "octree", 0.97, n, now_s() - t);

    lod_cloud c;
    memset(&c, 0, sizeof c);
    rc = link_table(b, &c, err);
    if (rc < 0) return rc;
    c.n = n;
    c.k = (uint32_t)d->k;
    c.attrs = (b->info.attrs & PC_ATTR_RGB) | PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F;
    c.grid_bits = (uint32_t)b->g;
    c.leaf_max = d->leaf_max;
    memcpy(c.offset, b->info.offset, sizeof c.offset);
    memcpy(c.bmin, b->info.bmin, sizeof c.bmin);
    memcpy(c.bmax, b->info.bmax, sizeof c.bmax);
    memcpy(c.origin, b->f.origin, sizeof c.origin);
    c.side = b->f.side;
    memcpy(c.centroid, b->centroid, sizeof c.centroid);
    c.sigma = b->qs[1].value;
    c.F_raw_p99 = b->p99;
    for (int i = 0; i < 5; i++) {
        static const int qi[5] = {3, 4, 5, 6, 2};
        c.F_pct[i] = final_F(b, b->qs[qi[i]].value);
    }
    c.radius_median = pick_value(b, NQ);
    c.n_dropped = b->info.n_dropped;
    memcpy(c.format, b->info.format, sizeof c.format);
    c.has_sensor_q = b->info.has_viewpoint;
    memcpy(c.sensor_q, b->info.viewpoint_q, sizeof c.sensor_q);
    lod_src_key key;
    rc = lod__src_key(src, &key, err);
    if (rc == 0) rc = lod__writer_commit(&b->w, &c, &key, err);
    free((void *)c.nodes);
    return rc;
}

int lod_open_cloud(const char *src, const lod_desc *desc, lod_cloud *out, lod_result *res,
                   sd_err *err)
{
    lod_desc d = desc ? *desc : (lod_desc){0};
    if (d.k <= 0) d.k = PREP_DEFAULT_K;
    if (d.k > PREP_MAX_K) return sd_errf(err, SD_EINVAL, "lod: k = %d is over %d", d.k, PREP_MAX_K);
    if (d.threads <= 0) d.threads = prep_default_threads();
    if (!d.memory) d.memory = (uint64_t)2 << 30;
    if (d.grid_bits <= 0) d.grid_bits = LOD_DEFAULT_GRID_BITS;
    if (d.grid_bits > 7) d.grid_bits = 7;
    if (!d.leaf_max) d.leaf_max = LOD_DEFAULT_LEAF_MAX;
    if (!d.chunk_max) {
        uint64_t cm = d.memory / BYTES_PER_CHUNK_POINT; /* one chunk at a time */
        d.chunk_max = cm > UINT32_MAX ? UINT32_MAX : (cm < 100000 ? 100000 : (uint32_t)cm);
    }
    lod_result rr;
    memset(&rr, 0, sizeof rr);
    rr.chunk_max = d.chunk_max;
    memset(out, 0, sizeof *out);
    double t0 = now_s();
    int rc = lod_cache_path(src, d.dir, d.k, rr.path, sizeof rr.path, err);
    if (rc < 0) return rc;
    int got = d.force ? 0 : lod_load_file(rr.path, src, &d, out, rr.why, sizeof rr.why);
    if (cf_loaded(d.force, got, "LOD cache", rr.path, rr.why, sizeof rr.why, d.warn, d.user)) {
        rr.hit = 1;
        rr.t_total = now_s() - t0;
        if (res) *res = rr;
        return 0;
    }
    build b;
    memset(&b, 0, sizeof b);
    b.d = &d;
    b.threads = d.threads;
    b.t0 = t0;
    pthread_mutex_init(&b.mu, NULL);
    lod_src *s = NULL;
    prep_progress pr;
    prep_progress_begin(&pr, d.progress, d.user, PROTO_PHASE_LOAD);
    rc = lod__writer_open(&b.w, rr.path, &d, err);
    if (rc == 0) rc = lod_src_open(src, &s, err);
    if (rc == 0) {
        prep_progress_end(&pr);
        rc = run_build(&b, src, s, &rr, err);
    }
    lod_src_close(s);
    for (size_t i = 0; i < b.nchunks; i++) {
        if (b.chunks[i].fd_in >= 0) close(b.chunks[i].fd_in);
        if (b.chunks[i].fd_a >= 0) close(b.chunks[i].fd_a);
    }
    free(b.chunks);
    free(b.cell_chunk);
    free(b.cell_pre);
    free(b.order);
    free(b.tcount);
    tkeep_free(&b);
    free(b.tk);
    free(b.tkcap);
    for (int q = 0; q < 4; q++) free(b.hist_hi[q]);
    for (int q = 0; q <= NQ; q++) free(b.qs[q].lo);
    free(b.nodes);
    free(b.up);
    for (int i = 0; i < KB_N; i++) free(b.keep[i]);
    pthread_mutex_destroy(&b.mu);
    if (rc < 0) rc = lod__build_failed(&b.w, rc, err);
    char why[256];
    if (rc == 0 && lod__load_built(&b.w, src, &d, out, why, sizeof why) != 1)
        rc = sd_errf(err, SD_ESTALE, "LOD cache %s was written but does not load: %s", rr.path,
                     why);
    lod__writer_abort(&b.w); /* after the load: a temporary file is read through its fd */
    if (rc < 0) return rc;
    rr.t_total = now_s() - t0;
    if (res) *res = rr;
    return 0;
}
