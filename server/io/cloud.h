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
};

/* A cloud as read from a file, coordinates still in double precision. Readers fill it with
 * pc_raw_reserve + writes at index n; non-finite points may be written, pc_finalize drops them. */
typedef struct pc_raw {
    size_t n, cap;
    uint32_t attrs;          /* set before the first pc_raw_reserve */
    double *xyz;             /* 3 * cap */
    uint8_t *rgba;           /* 4 * cap */
    float *normal;           /* 3 * cap */
    float *intensity;        /* cap */
    uint8_t *cls;            /* cap */
    float *radius;           /* cap */
    float *scalar;           /* cap */
    char scalar_name[32];    /* which file property scalar holds */
    char format[64];         /* "PLY binary_little_endian 1.0", "LAS 1.2 format 3", ... */
    int has_viewpoint;       /* the file gives the sensor's position (PCD VIEWPOINT) */
    double viewpoint[3];     /* that position, file coordinates */
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
    uint8_t *rgba;           /* 4 * n */
    float *normal;           /* 3 * n */
    float *intensity;        /* n */
    uint8_t *cls;            /* n */
    float *radius;           /* n */
    float *scalar;           /* n */
    double offset[3];        /* add to pos to get the file's coordinates */
    double bmin[3], bmax[3]; /* bounding box in the file's coordinates */
    uint64_t n_dropped;      /* non-finite points removed */
    char scalar_name[32];
    char format[64];
    int has_viewpoint;       /* the sensor's position is known (prep orients normals to it) */
    double viewpoint[3];     /* that position, file coordinates */
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

/* pc_load: picks the reader from the file's extension (ply, pcd, las, xyz, pts, txt; any case),
 * reads and finalizes. Returns 0 or a negative SD_E* code with err filled. */
int pc_load(const char *path, pc_cloud *out, sd_err *err);

/* pc_supported_ext: 1 when the file name has an extension pc_load reads. */
int pc_supported_ext(const char *name);
