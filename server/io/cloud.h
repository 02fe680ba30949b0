/* cloud.h — the in-memory point cloud, from file to GPU.
 *
 * Data flows one way:  file --io_*.c--> pc_raw (double xyz) --pc_finalize--> pc_cloud
 * (float32, re-centred on the bounding-box centre) --prep.c--> pc_prepared (Morton order,
 * normals, radii, F, batches) --cache.c--> mmapped file --renderer--> GPU buffers.
 *
 * Per-point attributes are separate arrays (structure of arrays), NULL when absent; the
 * attrs bit mask says which are present. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "attrs.h"
#include "sd_err.h"

/* The attribute bits are the protocol's (protocol/attrs.h), under the cloud module's prefix. */
enum pc_attr {
    PC_ATTR_RGB = SP_ATTR_RGB,
    PC_ATTR_NORMAL = SP_ATTR_NORMAL,
    PC_ATTR_INTENSITY = SP_ATTR_INTENSITY,
    PC_ATTR_CLASS = SP_ATTR_CLASS,
    PC_ATTR_RADIUS = SP_ATTR_RADIUS,
    PC_ATTR_SCALAR = SP_ATTR_SCALAR,
    PC_ATTR_F = SP_ATTR_F,
    PC_ATTR_SCAN = SP_ATTR_SCAN,
};

/* The per-point attributes besides the position, one row each, in one table that every
 * structure below takes its fields from and the generic code (reserve, free, compaction, the
 * hand-over to the finalized cloud, the prepared cloud's sections) loops over:
 *   id (PC_ATTR_<id>), field name, element type, elements per point.
 * The prepared cloud adds F (prep's uncertainty) and always has normal and radius. */
#define PC_ATTR_FIELDS(X)                  \
    X(RGB, rgba, uint8_t, 4)               \
    X(NORMAL, normal, float, 3)            \
    X(INTENSITY, intensity, float, 1)      \
    X(CLASS, cls, uint8_t, 1)              \
    X(RADIUS, radius, float, 1)            \
    X(SCALAR, scalar, float, 1)            \
    X(SCAN, scan, uint16_t, 1)

typedef struct pc_attr_info {
    uint32_t bit;            /* PC_ATTR_* */
    const char *field;       /* the field's name in the structures */
    size_t elem;             /* bytes per element */
    int per_point;           /* elements per point */
} pc_attr_info;

enum {
#define PC_ATTR_COUNT_(id, field, type, k) PC_ATTR_ROW_##id,
    PC_ATTR_FIELDS(PC_ATTR_COUNT_)
#undef PC_ATTR_COUNT_
    PC_ATTR_NFIELDS
};
extern const pc_attr_info pc_attr_table[PC_ATTR_NFIELDS];

/* The attribute arrays of the table as fields (pc_raw, pc_cloud, pc_prepared). */
#define PC_ATTR_ARRAYS                                  \
    PC_ATTR_FIELDS(PC_ATTR_ARRAY_)
#define PC_ATTR_ARRAY_(id, field, type, k) type *field; /* k per point when PC_ATTR_##id */

/* A cloud as read from a file, coordinates still in double precision. Readers fill it with
 * pc_raw_reserve + writes at index n; non-finite points may be written, pc_finalize drops them. */
typedef struct pc_raw {
    size_t n, cap;
    uint32_t attrs;          /* set before the first pc_raw_reserve */
    double *xyz;             /* 3 * cap */
    PC_ATTR_ARRAYS           /* rgba, normal, intensity, cls, radius, scalar, scan: cap */
    char scalar_name[32];    /* which file property scalar holds */
    char format[64];         /* "PLY binary_little_endian 1.0", "LAS 1.2 format 3", ... */
    int has_viewpoint;       /* the file gives the sensor's pose (PCD VIEWPOINT) */
    double viewpoint[3];     /* its position, file coordinates */
    double viewpoint_q[4];   /* its rotation, w x y z (framing.h's sensor rule) */
} pc_raw;

/* pc_raw_reserve: grows every array named in raw->attrs (and xyz) to hold cap points.
 * Callers bound cap by what the file can hold before calling. Returns 0 or SD_ENOMEM. */
int pc_raw_reserve(pc_raw *raw, size_t cap, sd_err *err);
void pc_raw_free(pc_raw *raw);

/* The finalized cloud: float32 coordinates relative to offset (the double bounding-box centre
 * of the finite points), non-finite points removed. */
typedef struct pc_cloud {
    size_t n;
    uint32_t attrs;
    float *pos;              /* 3 * n, file coordinates minus offset */
    PC_ATTR_ARRAYS           /* rgba, normal, intensity, cls, radius, scalar, scan: n */
    double offset[3];        /* add to pos to get the file's coordinates */
    double bmin[3], bmax[3]; /* bounding box in the file's coordinates */
    uint64_t n_dropped;      /* non-finite points removed */
    char scalar_name[32];
    char format[64];
    int has_viewpoint;       /* the sensor's pose is known (prep orients normals to it) */
    double viewpoint[3];     /* its position, file coordinates */
    double viewpoint_q[4];   /* its rotation, w x y z */
} pc_cloud;

/* pc_finalize: moves raw into out: drops points with a non-finite coordinate (counted in
 * n_dropped), computes the bounding box in double, re-centres on its centre and converts to
 * float. raw is emptied. Returns 0, SD_EEMPTY when no finite point remains, or SD_ENOMEM. */
int pc_finalize(pc_raw *raw, pc_cloud *out, const char *path, sd_err *err);
void pc_cloud_free(pc_cloud *c);

/* ---- readers: each fills raw from one file format. Errors name the file and the byte
 * offset (binary) or line (text). None allocates more than the file's size can hold. ---- */
int pc_read_ply(const char *path, pc_raw *raw, sd_err *err);
int pc_read_pcd(const char *path, pc_raw *raw, sd_err *err);
int pc_read_las(const char *path, pc_raw *raw, sd_err *err);
int pc_read_xyz(const char *path, pc_raw *raw, sd_err *err); /* .xyz, .pts, .txt */
/* pc_read_e57: every scan of an E57 file (ASTM E2807; io_e57.c, e57_stream.h), posed, invalid
 * points dropped, colours and intensities normalised by their limits, PC_ATTR_SCAN with more
 * than one scan. */
int pc_read_e57(const char *path, pc_raw *raw, sd_err *err);
/* pc_read_laz: LAZ and COPC (.laz, .copc.laz; also a .las whose format byte marks LAZ), chunks
 * decoded on threads threads (pc_read_laz: one per online CPU). io_laz.c. */
int pc_read_laz(const char *path, pc_raw *raw, sd_err *err);
int pc_read_laz_threads(const char *path, pc_raw *raw, int threads, sd_err *err);
/* pc_read_copc_levels: only the octree nodes of level max_level or less of a COPC file (its
 * hierarchy read page by page, deeper pages left unread): a uniform preview of the whole
 * extent for a first image. SD_EFORMAT when the file is not COPC. io_copc.c. */
int pc_read_copc_levels(const char *path, int max_level, pc_raw *raw, sd_err *err);
/* pc_read_copc_budget: the top levels 0..L of a COPC file's octree, L the deepest level whose
 * nodes together with all shallower ones hold at most budget points (at least level 0, even
 * when the root alone holds more); *level (may be NULL) gets L. The daemon's first image of a
 * COPC file (its provisional cloud). io_copc.c. */
int pc_read_copc_budget(const char *path, uint64_t budget, pc_raw *raw, int *level, sd_err *err);

/* pc_load: picks the reader from the file's extension (ply, pcd, las, laz, xyz, pts, txt, e57;
 * any case; .copc.laz is laz), or, for another extension, from the signature "ASTM-E57" at
 * the start (E57), reads and finalizes. Returns 0 or a negative SD_E* code with err filled. */
int pc_load(const char *path, pc_cloud *out, sd_err *err);
/* pc_load_threads: pc_load with threads threads for the readers that use them (LAZ: chunks in
 * parallel); 0: one per online CPU, as pc_load. */
int pc_load_threads(const char *path, int threads, pc_cloud *out, sd_err *err);

/* pc_supported_ext: 1 when the file name has an extension pc_load reads. */
int pc_supported_ext(const char *name);
/* pc_ext: the extension pc_load picks the reader by: what follows the last '.' of the file
 * name ("laz" for x.copc.laz), "" when there is none. */
const char *pc_ext(const char *name);
