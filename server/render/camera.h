/* camera.h — the view of one frame (internal to the renderer): matrices in the cloud's local
 * coordinates, near/far from the bounds, and frustum culling of batches into point ranges.
 * rnd_camera_frame (the default camera) is declared in render.h. */
#pragma once
#include <stdint.h>

#include "pipe.h"
#include "prepared.h"
#include "render.h"

/* rnd__view_setup: fills v's matrices, eye, fov, size and near/far from cam, for a cloud whose
 * local coordinates are file coordinates - offset and whose local bounds are [bmin, bmax].
 * cam->znear/zfar <= 0 are derived from the bounds: near = max(depth of the nearest box corner
 * along the view axis * 0.99, diagonal * 1e-4), far = distance to the farthest corner * 1.01.
 * The ranges of v are left empty. Returns 0, or SD_EINVAL naming a degenerate camera (eye on
 * the target, up parallel to the view axis, fov outside (0, 180), far <= near, bad size). */
int rnd__view_setup(const rnd_camera *cam, const double offset[3], const float bmin[3],
                    const float bmax[3], rnd_view *v, sd_err *err);

/* rnd__cull: writes into out (capacity nc) the chunks of c[0..nc) that intersect v's frustum,
 * in their order, merging chunks adjacent in one buffer set, and truncated so that they hold
 * at most budget points (budget 0: no limit). Returns the number written; *points gets the
 * number of points in them. */
uint32_t rnd__cull(const rnd_view *v, const rnd_chunk *c, uint64_t nc, uint64_t budget,
                   rnd_chunk *out, uint64_t *points);

/* rnd__screen_rect: the pixel rectangle [x0, x1) x [y0, y1) (GL window coordinates, clamped
 * to the frame) that holds the projection of the box [bmin, bmax], grown by margin pixels on
 * each side; the whole frame when part of the box is near or behind the eye. */
void rnd__screen_rect(const rnd_view *v, const float bmin[3], const float bmax[3], int margin,
                      int rect[4]);

/* rnd__aabb_in_frustum: whether the box [bmin, bmax] intersects the frustum of viewproj
 * (conservative: a box near a frustum corner may pass). */
int rnd__aabb_in_frustum(const float viewproj[16], const float bmin[3], const float bmax[3]);
