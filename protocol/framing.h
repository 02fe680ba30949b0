/* framing.h — the default camera, shared by the daemon (a frame with no camera) and the client
 * (`splat render` without --eye, `splat path --orbit`), so both frame a cloud the same way.
 * All coordinates are the cloud file's (doubles). */
#pragma once

/* The frame size used when none is asked for (splat's --size, a daemon frame before any
 * CAMERA, splatd render). */
enum { SP_DEFAULT_WIDTH = 1280, SP_DEFAULT_HEIGHT = 720 };

/* sp_default_up: the up axis guessed from the bounding box: +y when the box is flat in z (an
 * airborne scan or terrain, seen from above with north up) or tallest along y (the y-up
 * convention of most graphics and photogrammetry exports); +z otherwise. */
void sp_default_up(const double bmin[3], const double bmax[3], double up[3]);

/* sp_frame_box: a camera of vertical field of view fov_deg for a width x height frame that
 * shows the whole box: looking at its centre from a fixed diagonal (from above, for a box flat
 * in z) at the distance where the box's bounding sphere fits. Fills eye, target and up. */
void sp_frame_box(const double bmin[3], const double bmax[3], int width, int height,
                  double fov_deg, double eye[3], double target[3], double up[3]);

/* sp_frame_orbit: camera i of n on a circle around the box centre, 25 degrees above the plane
 * perpendicular to up (NULL: sp_default_up), at sp_frame_box's distance. */
void sp_frame_orbit(const double bmin[3], const double bmax[3], const double *up_in, int i, int n,
                    int width, int height, double fov_deg, double eye[3], double target[3],
                    double up[3]);
