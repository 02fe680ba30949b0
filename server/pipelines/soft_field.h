/* soft_field.h — the scalar F of the solid/soft split for the `soft` and `olt` pipelines: every
 * source of the parameter `field` (params.h SP_FIELD_*), computed per point on the CPU from the
 * cloud's buffers (read back once when the cloud attaches) and uploaded as one float buffer a
 * buffer set, which the shaders read on RND_T_SOFT_F. A change of field, classes or the axis
 * recomputes F and uploads that buffer again; the cloud's own buffers are never re-uploaded.
 * Internal to the renderer. */
#pragma once
#include <stdint.h>

#include "pipe.h"

typedef struct soft_fset {
    uint32_t n;
    float *pos;                /* 3n, local coordinates */
    float *unc, *inten, *sca;  /* n each: uncertainty, intensity, scalar (normalised) */
    uint32_t *cls;             /* n LAS classes; NULL when the cloud has none */
    float *scan;               /* n scan indices over the largest; NULL when the cloud has none */
    float *f;                  /* n: F for the current source */
    GLuint f_buf;              /* f as float bits (R32UI buffer texture source) */
} soft_fset;

typedef struct soft_fields {
    uint32_t nsets;
    soft_fset *sets;
    int have;                  /* f holds the source below */
    int field;
    int64_t classes;
    float axis_a[3], axis_b[3];
    char scalar_name[32];
} soft_fields;

/* soft_fields_attach: reads back what every source needs from cloud c's buffers. Returns 0 or
 * SD_ENOMEM (then *fs is freed). */
int soft_fields_attach(const gl_api *gl, const rnd_gpu_cloud *c, soft_fields *fs, sd_err *err);
void soft_fields_free(const gl_api *gl, soft_fields *fs);

/* soft_fields_update: makes every set's f (and f_buf) the source p asks for, when it is not
 * already. Returns 1 when F changed, 0 when it was current, or SD_EINVAL (a source the cloud
 * cannot give: quality/confidence naming another property, class without classes, a degenerate
 * axis) / SD_ENOMEM with err filled. */
int soft_fields_update(const gl_api *gl, const rnd_gpu_cloud *c, soft_fields *fs,
                       const sp_params *p, sd_err *err);
