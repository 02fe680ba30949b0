/* preview.c — a provisional prepared cloud from a loaded cloud, nothing computed (preview.h). */
#include "preview.h"

#include <stdio.h>
#include <string.h>

int prep_preview(const pc_cloud *in, pc_prepared *out, sd_err *err)
{
    memset(out, 0, sizeof *out);
    if (!in->n) return sd_errf(err, SD_EEMPTY, "a preview of a cloud without points");
    if (in->n >= ((uint64_t)1 << 31))
        return sd_errf(err, SD_ELIMIT, "a preview of %zu points: at most 2^31 - 1", in->n);
    const uint32_t keep = PC_ATTR_RGB | PC_ATTR_INTENSITY | PC_ATTR_CLASS | PC_ATTR_SCALAR | PC_ATTR_SCAN;
    out->n = in->n;
    out->attrs = in->attrs & keep;
    out->nbatches = (in->n + PC_BATCH_POINTS - 1) / PC_BATCH_POINTS;
    int rc = pc_prepared_alloc(out, err);
    if (rc) {
        memset(out, 0, sizeof *out);
        return rc;
    }
    memcpy(out->pos, in->pos, sizeof(float) * 3 * in->n);
#define COPY_(id, fld, type, k)                                                  \
    if ((out->attrs & PC_ATTR_##id) && in->fld && out->fld)                      \
        memcpy(out->fld, in->fld, sizeof(type) * (k) * in->n);
    PC_ATTR_FIELDS(COPY_)
#undef COPY_
    pc_prepared_make_batches(out, PC_BATCH_POINTS);
    memcpy(out->offset, in->offset, sizeof out->offset);
    memcpy(out->bmin, in->bmin, sizeof out->bmin);
    memcpy(out->bmax, in->bmax, sizeof out->bmax);
    out->n_dropped = in->n_dropped;
    snprintf(out->format, sizeof out->format, "%s", in->format);
    snprintf(out->scalar_name, sizeof out->scalar_name, "%s", in->scalar_name);
    out->has_sensor_q = in->has_viewpoint;
    memcpy(out->sensor_q, in->viewpoint_q, sizeof out->sensor_q);
    return 0;
}
