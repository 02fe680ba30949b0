/* rndtest.h — renderer calls for the rendering tests that fail the running cmocka test with the
 * renderer's message instead of returning a code. */
#pragma once
#include <stdint.h>

#include "render.h"

/* tu_ctx: the EGL renderer (shaders from $SPLATD_SHADERS) of a test binary's group, made by
 * tu_egl_group_setup (which prints the error and returns -1 when it cannot) and destroyed by
 * tu_egl_group_teardown: pass both to cmocka_run_group_tests. */
extern rnd_ctx *tu_ctx;
int tu_egl_group_setup(void **state);
int tu_egl_group_teardown(void **state);

/* tu_prep_data: the file tests/data/name loaded and prepared with prep's defaults into *pc;
 * fails the test on an error. */
void tu_prep_data(const char *name, pc_prepared *pc);

/* tu_upload: rnd_upload of pc; fails the test when it returns no id. */
uint32_t tu_upload(rnd_ctx *r, const pc_prepared *pc);

/* Two real scans prepared with prep's defaults (Guanyin.ply and bunnyData.pts), each framed by
 * rnd_camera_frame at w x h, and a close-up of Guanyin (the eye at 0.3 of its distance, so
 * that the frustum cuts the scan): the fixture of the host-against-GL tests. */
typedef struct tu_scans {
    pc_prepared g, b;
    rnd_camera cg, cb, close;
} tu_scans;
void tu_scans_load(tu_scans *s, int w, int h);
void tu_scans_free(tu_scans *s);

/* tu_upload_intensities: tu_upload of pc with intensities i % 1000 put in for point i (so that
 * color=intensity has more than one value to show); pc itself is left as it was (its arrays
 * live in one block: a separate array is put in for the upload and freed). */
uint32_t tu_upload_intensities(rnd_ctx *r, pc_prepared *pc);

/* tu_render: rnd_render of cloud id; fails the test on an error. */
void tu_render(rnd_ctx *r, uint32_t id, const rnd_camera *cam, const sp_params *p,
               int want_float, rnd_frame *f);

/* tu_new_cloud: a prepared cloud of n points with every attribute (unit +z normals, white,
 * radius 0.01) in nb batches (0: as many as PC_BATCH_POINTS needs); the caller sets the
 * positions (local coordinates) and calls tu_finish_cloud. */
void tu_new_cloud(pc_prepared *pc, uint64_t n, uint64_t nb);

/* tu_finish_cloud: batches of consecutive points of equal size (the last may be shorter) with
 * their bounds, the cloud's bounds in file coordinates, and its offset off. */
void tu_finish_cloud(pc_prepared *pc, const double off[3]);

/* tu_camera_box: the framing the rendering tests' expectations were computed with (fixed here
 * so that a change of the default view does not move them): fov 45 at w x h, looking at the
 * box's centre from the direction (0.55, 1, 0.45) with up +z (or, for a box flat in z, from
 * (0, -0.35, 1) with up +y; for a box tallest in y, from (0.55, 0.45, 1) with up +y), at the
 * distance where the box's bounding sphere fits with 2 % to spare. */
void tu_camera_box(const double bmin[3], const double bmax[3], int w, int h, rnd_camera *cam);
