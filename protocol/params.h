/* params.h — every render/frame parameter a client can set: name, type, range, default.
 *
 * One X-macro list is the single source for the struct, the defaults, validation, the
 * `--set key=value` text syntax of both commands and the PARAMS records on the wire.
 * Enum values are given as a '|'-separated list; the stored value is the index. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "pipelines.h"

typedef enum { SP_T_ENUM = 1, SP_T_FLOAT = 2, SP_T_INT = 3, SP_T_VEC3 = 4 } sp_type;

/*      id            name            type        field         min   max       default   enum values */
#define SP_PARAM_LIST(X)                                                                             \
    X(PIPELINE,     "pipeline",     SP_T_ENUM,  pipeline,     0,    0,        "splat",  SP_PIPELINE_VALUES) \
    X(SPLAT_SCALE,  "splat_scale",  SP_T_FLOAT, splat_scale,  0.01, 100,      "1",      NULL)     \
    X(LOWPASS,      "lowpass",      SP_T_FLOAT, lowpass,      0,    16,       "1",      NULL)     \
    X(EWA,          "ewa",          SP_T_ENUM,  ewa,          0,    0,        "auto",   "auto|exact|split") \
    X(POINT_SIZE,   "point_size",   SP_T_FLOAT, point_size,   1,    64,       "1",      NULL)     \
    X(POINT_BUDGET, "point_budget", SP_T_INT,   point_budget, 0,    4e9,      "0",      NULL)     \
    X(COLOR,        "color",        SP_T_ENUM,  color,        0,    0,        "rgb",    "rgb|field|normal|depth|intensity|scan") \
    X(LIGHT,        "light",        SP_T_VEC3,  light,        -1,   1,        "0.3,0.4,1", NULL)  \
    X(BACKGROUND,   "background",   SP_T_VEC3,  background,   0,    1,        "0,0,0",  NULL)     \
    X(FORMAT,       "format",       SP_T_ENUM,  format,       0,    0,        "jpeg",   "jpeg|png|lz4|raw|exr") \
    X(QUALITY,      "quality",      SP_T_INT,   quality,      1,    100,      "85",     NULL)     \
    X(SUBSAMPLING,  "subsampling",  SP_T_ENUM,  subsampling,  0,    0,        "420",    "444|422|420|gray") \
    X(KAWATA_RHO_SCALE, "kawata_rho_scale", SP_T_FLOAT, kawata_rho_scale, 0.25, 16, "3.5", NULL) \
    X(KAWATA_GAMMA, "kawata_gamma", SP_T_FLOAT, kawata_gamma, 0,    0.5,      "0.0075", NULL)   \
    X(SHADING,      "shading",      SP_T_ENUM,  shading,      0,    0,        "lambert", "lambert|edl") \
    X(EDL_STRENGTH, "edl_strength", SP_T_FLOAT, edl_strength, 0,    100,      "1",      NULL)     \
    X(EDL_RADIUS,   "edl_radius",   SP_T_FLOAT, edl_radius,   0.5,  16,       "1",      NULL)     \
    X(MODEL,        "model",        SP_T_ENUM,  model,        0,    0,        "express", "express|base|concentric") \
    X(LAMBDA,       "lambda",       SP_T_FLOAT, lambda,       0,    1,        "0.5",    NULL)     \
    X(T,            "t",            SP_T_FLOAT, t,            0,    1,        "0.5",    NULL)     \
    X(L_M,          "l_m",          SP_T_FLOAT, l_m,          0,    1,        "0",      NULL)     \
    X(FIELD,        "field",        SP_T_ENUM,  field,        0,    0,        "uncertainty", "uncertainty|height|intensity|scalar|quality|confidence|class|axis-distance|scan") \
    X(ORDER,        "order",        SP_T_ENUM,  order,        0,    0,        "auto",   "axis|tile|auto") \
    X(CLASSES,      "classes",      SP_T_INT,   classes,      0,    4294967295, "0",    NULL)     \
    X(AXIS_A,       "axis_a",       SP_T_VEC3,  axis_a,       -1e9, 1e9,      "0,0,0",  NULL)     \
    X(AXIS_B,       "axis_b",       SP_T_VEC3,  axis_b,       -1e9, 1e9,      "0,0,1",  NULL)     \
    X(SOFT_FRAG_MIB, "soft_frag_mib", SP_T_INT, soft_frag_mib, 1,   65536,    "512",    NULL) \
    X(LOD_FIRST,    "lod_first",    SP_T_INT,   lod_first,    0,    1,        "0",      NULL) \
    X(PROVISIONAL,  "provisional",  SP_T_INT,   provisional,  0,    1,        "0",      NULL)

enum {
#define SP_ID_(id, name, type, field, lo, hi, def, vals) SP_##id,
    SP_PARAM_LIST(SP_ID_)
#undef SP_ID_
    SP_PARAM_COUNT
};

/* Enum values by index, matching the lists above (pipelines: SP_PIPE_* in pipelines.h). */
/* ewa: the splat footprint filter. exact: J V_r J^T + lowpass I per splat, every splat
 * rasterised; split: lowpass/4 per splat, sub-pixel splats deposited in one pixel, the rest of
 * the low-pass in the resolve (pipe_splat.c); auto: exact on a GPU, split on a software
 * renderer. */
enum { SP_EWA_AUTO = 0, SP_EWA_EXACT, SP_EWA_SPLIT };
/* color=scan: the scan index (E57 files of several scans) through color=field's colour map,
 * scan / the largest scan index; one colour for a cloud of one scan. */
enum { SP_COLOR_RGB = 0, SP_COLOR_FIELD, SP_COLOR_NORMAL, SP_COLOR_DEPTH, SP_COLOR_INTENSITY,
       SP_COLOR_SCAN };
enum { SP_FMT_JPEG = 0, SP_FMT_PNG, SP_FMT_LZ4, SP_FMT_RAW, SP_FMT_EXR };
enum { SP_SUB_444 = 0, SP_SUB_422, SP_SUB_420, SP_SUB_GRAY };
/* shading: lambert = each pipeline's own shading only (splat: Lambert from the file's or
 * prep's normals; kawata: Lambert from its per-frame normals; points: none, flat colour);
 * edl = that, times Eye-Dome Lighting over the frame's eye depth (render.c, edl.c), for every
 * pipeline: the depth cue that needs no normals at all. */
enum { SP_SHADING_LAMBERT = 0, SP_SHADING_EDL };
/* model: the Soft Transparency density model: express = view-facing discs with eq. 19 (the
 * default, pipe_soft.c); base = spheres with the exact density integral (eq. 4-12); concentric =
 * N concentric spheres of constant density (eq. 13-18); the last two through per-pixel fragment
 * lists (soft_lists.h). */
enum { SP_MODEL_EXPRESS = 0, SP_MODEL_BASE, SP_MODEL_CONCENTRIC };
/* field: the scalar F of the solid/soft split, each in [0, 1] (soft_field.c computes them):
 *   uncertainty   prep's eq. 21, normalised by the cloud's 99th percentile and clamped;
 *   height        (z - zmin) / (zmax - zmin) over the cloud's bounds;
 *   intensity     (I - Imin) / (Imax - Imin) over the cloud (render.c, at upload);
 *   scalar        the file's scalar property (PLY: quality, else confidence, else the first
 *                 scalar_*), (s - smin) / (smax - smin) over the cloud;
 *   quality, confidence  that property when it has this name, 1 - the normalised value (low
 *                 quality or confidence is soft); refused naming the property when not;
 *   class         1 for LAS classes in the bit mask `classes` (bit c: class c, 0-31), else 0;
 *                 the text form field=class:3,4,5 (sp_param_set_text) sets both parameters;
 *   axis-distance the distance to the line through axis_a and axis_b divided by the largest
 *                 such distance of any point of the cloud;
 *   scan          the index of the scan a point came from (E57) over the largest index (scans
 *                 up to t * largest are solid); refused for a cloud without scan indices. */
enum {
    SP_FIELD_UNCERTAINTY = 0, SP_FIELD_HEIGHT, SP_FIELD_INTENSITY, SP_FIELD_SCALAR,
    SP_FIELD_QUALITY, SP_FIELD_CONFIDENCE, SP_FIELD_CLASS, SP_FIELD_AXIS, SP_FIELD_SCAN
};
/* order: every value composites the soft discs back to front in the order of the axis-sorted
 * index arrays (pipe_soft.c); axis = as GL point sprites blended in primitive order, tile = a
 * compute compositor that bins them into 8x8 pixel tiles keeping that order and blends per
 * pixel; auto = the host compositor where the renderer has host paths (a software renderer,
 * where the GL is the CPU: pipe.h rnd_host, soft_cpu.h), axis elsewhere. */
enum { SP_ORDER_AXIS = 0, SP_ORDER_TILE, SP_ORDER_AUTO };

typedef struct sp_params {
    int32_t pipeline;
    float splat_scale;
    float lowpass;
    int32_t ewa;
    float point_size;
    int64_t point_budget;   /* 0: every point */
    int32_t color;
    float light[3];         /* direction towards the light, camera space (x right, y up, z back) */
    float background[3];    /* linear RGB in [0,1] */
    int32_t format;
    int64_t quality;
    int32_t subsampling;
    float kawata_rho_scale; /* kawata: factor on the image buffer's pixel size rho (eq. 1-3) */
    float kawata_gamma;     /* kawata: depth range of pass 2, a fraction of the box diagonal */
    int32_t shading;        /* SP_SHADING_* */
    float edl_strength;     /* EDL: 0 leaves the frame unchanged */
    float edl_radius;       /* EDL: neighbour distance in pixels */
    int32_t model;          /* soft: SP_MODEL_* */
    float lambda;           /* soft, olt: opacity scale lambda (Soft Transparency eq. 19) */
    float t;                /* soft, olt: points with field value F <= t are solid */
    float l_m;              /* soft: transparency modulation range (eq. 22); <= t: off */
    int32_t field;          /* soft, olt: SP_FIELD_*, the source of F */
    int32_t order;          /* soft: SP_ORDER_*, how the soft discs are composited */
    int64_t classes;        /* soft, olt with field=class: bit c makes LAS class c soft */
    float axis_a[3];        /* soft, olt with field=axis-distance: two points of the axis, */
    float axis_b[3];        /*   file coordinates minus the cloud's bounding-box centre */
    int64_t soft_frag_mib;  /* soft base/concentric: fragment memory cap, MiB (soft_lists.h) */
    int64_t lod_first;      /* 1: a RENDER of a LOD cloud answers its first frame, even when
                               nodes were still missing; 0: the complete frame */
    int64_t provisional;    /* 1: an OPEN of a cloud being prepared answers INFO of a provisional
                               cloud (COPC: its top levels) first, then the full INFO
                               (PROTOCOL.md, OPEN); 0: INFO once the full cloud is ready */
} sp_params;

typedef struct sp_param_info {
    const char *name;
    sp_type type;
    double min, max;
    const char *def;        /* default, in the text syntax */
    const char *values;     /* enum values "a|b|c", NULL for numbers */
} sp_param_info;

extern const sp_param_info sp_param_table[SP_PARAM_COUNT];

/* sp_params_defaults: fills p with every default. */
void sp_params_defaults(sp_params *p);

/* sp_param_find: the id of a parameter name, or -1. */
int sp_param_find(const char *name);

/* sp_param_set_text: sets one parameter from text ("splat_scale", "1.5"; "light", "0,1,1";
 * "pipeline", "points"). Returns 0, or -1 with err naming the parameter and its range or
 * values (unknown name, unparsable value, out of range). */
int sp_param_set_text(sp_params *p, const char *name, const char *value, char *err, size_t errlen);

/* sp_param_set_kv: the same for "name=value". */
int sp_param_set_kv(sp_params *p, const char *kv, char *err, size_t errlen);

/* sp_param_get_text: writes parameter id's current value of p in the text syntax. */
void sp_param_get_text(const sp_params *p, int id, char *buf, size_t len);

/* sp_enum_name: the name of value v of enum parameter id, or NULL when out of range. */
const char *sp_enum_name(int id, int v, char *buf, size_t len);
