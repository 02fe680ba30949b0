/* preview.h — a provisional prepared cloud: what can be drawn with the `points` pipeline before
 * the real preparation (prep.h) is done, e.g. from a COPC file's top octree levels.
 *
 * Positions and the file's own attributes (colour, intensity, class, scalar) are copied in
 * the cloud's order; nothing is computed: no Morton order, no kNN, no normal, radius or F
 * (their sections exist, zeroed, and attrs does not name them), sigma 0. Batches are runs of
 * PC_BATCH_POINTS consecutive points with their bounds. Linear in n, no threads. */
#pragma once
#include "cloud.h"
#include "prepared.h"
#include "sd_err.h"

/* prep_preview: in (unchanged) as a heap pc_prepared in out (free with pc_prepared_free).
 * out is zeroed first. Returns 0, SD_EEMPTY (no points), SD_ELIMIT (2^31 points or more) or
 * SD_ENOMEM, with err filled and out empty. */
int prep_preview(const pc_cloud *in, pc_prepared *out, sd_err *err);
