/* lod.h — the level-of-detail form of a cloud: an additive octree built out of core, cached in
 * one file per source and mapped back.
 *
 * The octree. Levels 0 (the root: the cloud's Morton cube, morton.h) down to at most
 * LOD_MAX_LEVEL. A node at level l is the Morton cell of depth l with code prefix `code`; its
 * spacing is the edge of the cells of depth l + grid_bits (side / 2^(l + grid_bits)): the node
 * holds, of the points of its cell that no ancestor took, one per such sub-cell: the surface
 * point nearest the sub-cell's centre (ties: the first in (Morton code, file index) order), or
 * where the sub-cell has no surface point, the scattered point nearest it among those a hash
 * of the file index lets through (1 in LOD_SCATTER_KEEP; "surface": PCA surface variation at
 * most PREP_SURFACE_VAR_MAX and an eq. 20 radius that prep did not limit as a stray point's), and passes the rest on to its children, so every point is
 * stored exactly once and spacing halves per level. Without the hash, scattered noise fills
 * every sampling cell of the upper levels (1 % of noise in 100M points made a root of 1.3M
 * points, mostly noise, that hid the surfaces); with it they reach the levels where they are
 * as dense as the cells, and the leaves. A node takes one point at least. A node
 * whose remaining points number at most leaf_max takes them all and is a leaf. Nodes above the
 * build's chunks (see lod_build.c) are always inner nodes. With grid_bits = 7 a node of a
 * surface holds one point per occupied cell of a 128^3 grid over its cube: about 128^2 x a
 * small factor, 15k-60k points, and leaves hold at most leaf_max = 50000: nodes large enough
 * that one draw call and one upload per node cost little against the points, small enough that
 * the budget is spent where the view needs it (Potree uses the same grid of 128).
 *
 * Per point: position (local, as prepared.h), normal, radius, F and colour computed exactly as
 * prep.h's in-memory prep does from the k nearest neighbours among ALL points of the cloud (the
 * build works on chunks with a halo of neighbours grown until every kNN is exact), and a second
 * radius, radius_lod = max(radius, spacing of the node's level) for the surface points (as
 * below) of inner nodes (other points, noise and vegetation, keep their radius), used when the
 * node is drawn without its children so that coarse levels cover the surfaces without holes.
 *
 * Within a node, points are stored surface points first (PCA surface variation at most
 * PREP_SURFACE_VAR_MAX), then the others, each group in a fixed pseudo-random order: a frame
 * whose budget ends inside a node draws a uniform sample of it.
 *
 * The file (host byte order):
 *   [0, 4096)               lod_header (lod_file.c), checksummed
 *   [4096, table_off)       node data, each node 64-byte aligned, structure of arrays:
 *                           pos 3c floats | normal 3c | radius c | radius_lod c | F c | rgba c u32
 *   [table_off, file_len)   nnodes lod_node records, breadth-first: root first, children of a
 *                           node consecutive; checksummed as a whole
 * Each node's data has its own checksum, checked when the node is loaded (not at open, so a
 * 10^9-point cache opens in milliseconds). The header page, the key and the writing are
 * cachefile.h's: written unnamed (O_TMPFILE) or under a random name, fsynced, then renamed:
 * kill -9 at any moment leaves no file that loads. The node table is read into memory at open;
 * node data is read through cachefile.h's guarded mapping, so a cache file cut or changed in
 * place under the daemon makes the node's load fail (lod_node_copy: SD_ESTALE naming the
 * file), never a SIGBUS. When the cache directory cannot be written, the build goes to an
 * unnamed file in the temporary directory ($TMPDIR, else /tmp), served while the cloud is open
 * and rebuilt at its next open. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "progress.h"
#include "sd_err.h"

#define LOD_EXT ".splod"

enum { LOD_MAX_LEVEL = 14 };          /* grid_bits + level <= 21 Morton bits */
enum { LOD_DEFAULT_GRID_BITS = 7 };   /* 128^3 sampling grid per node */
enum { LOD_DEFAULT_LEAF_MAX = 50000 };
enum { LOD_NODE_ALIGN = 64 };
enum { LOD_SCATTER_KEEP = 64 };       /* inner nodes take 1 in 64 of the scattered points' cells */

typedef struct lod_node {
    uint64_t offset;          /* file offset of the node's data */
    uint64_t hash;            /* sd_hash64 of its 40 * count bytes */
    uint64_t code;            /* Morton prefix of depth level */
    uint64_t subtree_points;  /* points of the node and every descendant */
    uint32_t count;           /* points of this node */
    uint32_t parent;          /* index; 0xffffffff for the root */
    uint32_t first_child;     /* index of the first child (children are consecutive) */
    uint8_t level, nchildren, pad[6];
    float spacing;            /* of its level (local units) */
    float bmin[3], bmax[3];   /* bounds of its own points */
    float sbmin[3], sbmax[3]; /* bounds of its subtree's points */
} lod_node;                   /* 104 bytes, stored verbatim */

/* The points of one node, pointing into the mapping. */
typedef struct lod_node_data {
    const float *pos, *normal, *radius, *radius_lod, *F;
    const uint32_t *rgba;     /* RGBA8, r in the low byte (white when the file had no colour) */
} lod_node_data;

/* A loaded LOD cloud (read-only mapping). */
typedef struct lod_cloud {
    uint64_t n, nnodes;
    uint32_t k, attrs;        /* PC_ATTR_*: NORMAL | RADIUS | F, RGB when the file had it */
    uint32_t grid_bits, leaf_max, depth; /* depth: deepest level + 1 */
    double offset[3], bmin[3], bmax[3];  /* file coordinates */
    double origin[3], side;   /* the Morton cube (local) */
    double centroid[3];       /* mean of the local positions */
    float sigma, F_raw_p99, F_pct[5], radius_median;
    uint64_t n_dropped;
    char format[64];
    int has_sensor_q;         /* as pc_prepared's: the sensor's rotation, w x y z */
    double sensor_q[4];
    const lod_node *nodes;    /* nnodes, breadth-first (a copy in memory, owned) */
    const uint8_t *map;       /* the file, mapped read-only (file) */
    size_t map_len;
    struct cf_map *file;      /* cachefile.h: owns map; says whether the file became shorter */
} lod_cloud;

/* lod_node_bytes: bytes of a node of count points (before alignment). */
uint64_t lod_node_bytes(uint32_t count);

/* lod_node_get: the arrays of node i, in the mapping (unchecked: lod_node_copy checks). */
void lod_node_get(const lod_cloud *c, uint64_t i, lod_node_data *d);
/* lod_node_bind: the arrays of a node of count points stored at data (the layout above). */
void lod_node_bind(const void *data, uint32_t count, lod_node_data *d);

/* lod_node_verify: 1 when node i's data matches its checksum (and the file is whole), else 0. */
int lod_node_verify(const lod_cloud *c, uint64_t i);

/* lod_node_copy: copies node i's data (lod_node_bytes(count) bytes) into dst and checks it.
 * Returns 0, or SD_ESTALE with err naming the cache file when the file became shorter or the
 * node does not match its checksum (the file changed under the reader). */
int lod_node_copy(const lod_cloud *c, uint64_t i, void *dst, sd_err *err);

void lod_cloud_free(lod_cloud *c);

typedef struct lod_desc {
    const char *dir;          /* cache directory: default as cache.h's */
    int k;                    /* default PREP_DEFAULT_K */
    int threads;              /* default every core */
    uint64_t memory;          /* default 2 GiB: the build's memory cap (chunk size follows) */
    int grid_bits;            /* default LOD_DEFAULT_GRID_BITS (tests use fewer) */
    uint32_t leaf_max;        /* default LOD_DEFAULT_LEAF_MAX */
    uint32_t chunk_max;       /* default 0: from memory; tests force small chunks */
    float halo_first;         /* default 0: the first chunk's halo from the count grid; else
                                 this fraction of its cube's side (tests: halos that grow) */
    int force;                /* rebuild even when a valid cache exists */
    prep_progress_fn progress;/* phases PROTO_PHASE_READ, REORDER, KNN, NORMALS, FIELD */
    void (*status)(void *user, const char *line); /* default none: one line per pass with
                                 points/s and the ETA of the build */
    void (*warn)(void *user, const char *msg);
    void *user;
} lod_desc;

typedef struct lod_result {
    int hit;                  /* 1: loaded from the cache */
    char path[4096];
    char why[256];
    double t_total;           /* seconds */
    uint64_t chunks;          /* build: chunks of the input */
    uint32_t chunk_max;       /* build: points per chunk at most (from memory) */
    double halo_retries;      /* build: chunks whose halo had to grow, fraction */
} lod_result;

/* lod_open_cloud: the LOD form of the file src: from a valid LOD cache (mapped), or built out
 * of core, written and mapped. Returns 0 or a negative SD_E*. */
int lod_open_cloud(const char *src, const lod_desc *d, lod_cloud *out, lod_result *res,
                   sd_err *err);

/* lod_cache_path: the LOD cache path of src under dir (NULL: default). */
int lod_cache_path(const char *src, const char *dir, int k, char *buf, size_t len, sd_err *err);

/* lod_load_file: loads and checks the LOD cache at path for source src (size, mtime, a hash
 * of its first and last MiB, version, and d's k, grid_bits and leaf_max with their defaults;
 * d may be NULL). Returns 1 loaded, 0 absent or stale, -1 damaged (why). */
int lod_load_file(const char *path, const char *src, const lod_desc *d, lod_cloud *out,
                  char *why, size_t whylen);

/* lod__seal: makes the LOD cache file at path describe the source src for the options of d
 * (NULL: the defaults) and gives it valid checksums over what it holds (the node table's, the
 * header's; not the nodes'), so that a fuzzer's bytes reach the checks behind them. Internal
 * (tests/fuzz); returns 0 or -1. */
int lod__seal(const char *path, const char *src, const lod_desc *d);

/* lod_want: 1 when a cloud file of size bytes gets the LOD form under mode (LOD_AUTO: files
 * of LOD_AUTO_BYTES or more, about 4M points of binary PLY; LOD_ALWAYS; LOD_NEVER). */
enum { LOD_AUTO = 0, LOD_ALWAYS = 1, LOD_NEVER = 2 };
#define LOD_AUTO_BYTES ((uint64_t)64 << 20)
int lod_want(int mode, uint64_t size);
