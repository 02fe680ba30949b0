/* framing.h — a cloud's default view and the cameras made from it, shared by the daemon (a
 * frame with no camera, INFO's view) and the clients (`splat render` without --eye, `splat path
 * --orbit`, `splat view`; web/viewer.js mirrors sp_frame_fit), so every program starts from the
 * same view. All coordinates are the cloud file's (doubles).
 *
 * World up, by rule (sp_view_default):
 *   z-up      LAS, LAZ, COPC and E57 (their specifications' convention), and any cloud whose
 *             coordinates are georeferenced (SP_GEOREF_MIN: a map projection's eastings and
 *             northings), whatever the format;
 *   sensor    a PCD whose VIEWPOINT is not georeferenced: the view PCL's viewer shows, the
 *             cloud placed by the sensor's pose and looked at along -z with +y up, which in the
 *             file's coordinates is direction R^T (0,0,-1) and up R^T (0,1,0) (R the VIEWPOINT's
 *             rotation; the identity looks along -z);
 *   guess     PLY, XYZ, PTS: the axis of least extent when the cloud is clearly flat (that
 *             extent under SP_FLAT_RATIO of both others: a terrain, a wall, a facade), else +y,
 *             the convention of the graphics and photogrammetry exports these formats come from
 *             (the Stanford scans, Sketchfab, Meshlab).
 * The first view looks down SP_ELEVATION_DEG at the cloud (sensor views keep the sensor's
 * direction), from the side that shows its larger horizontal extent across the frame, turned
 * SP_YAW_DEG off that axis so that walls and buildings show depth; the camera then moves along
 * that direction until the bounds fill the frame (sp_frame_fit). */
#pragma once
#include <stdint.h>

/* The frame size used when none is asked for (splat's --size, a daemon frame before any
 * CAMERA, splatd render). */
enum { SP_DEFAULT_WIDTH = 1280, SP_DEFAULT_HEIGHT = 720 };
#define SP_DEFAULT_FOV 45.0          /* vertical field of view, degrees */
#define SP_ELEVATION_DEG 30.0        /* first view and orbits: degrees above the horizon */
#define SP_YAW_DEG 20.0              /* first view: degrees off the shorter horizontal axis */
#define SP_FLAT_RATIO 0.2            /* guess rule: flat when one extent < this x the others */
#define SP_GEOREF_MIN 1.0e4          /* georeferenced: |x| or |y| of the box centre at least this
                                        and at least 10x the box's horizontal extent */
#define SP_FILL_MARGIN 0.04          /* sp_frame_fit leaves this fraction of the frame free */

/* How the up rule is chosen (the reader's file family; sp_view_default). */
enum { SP_UP_GUESS = 0, SP_UP_Z = 1, SP_UP_SENSOR = 2 };

/* The most points a view's hull has: the cloud's extreme points along the 26 directions of a
 * 3 x 3 x 3 grid's neighbours (the 6 axes, 12 edge and 8 corner diagonals). */
enum { SP_VIEW_PTS = 26 };

/* A cloud's default view (INFO carries it). The eye is not part of it: it follows from the
 * frame's size through sp_frame_fit. */
typedef struct sp_view {
    double up[3];            /* world up, unit length */
    double dir[3];           /* unit direction the camera looks along, not parallel to up */
    double bmin[3], bmax[3]; /* the box the view frames: the cloud's bounds without its
                                farthest outliers (the server's robust bounds), file coordinates */
    uint32_t npts;           /* 0, or the points below: the cloud's extreme points within the
                                box, which the camera fits instead of the box's corners (a round
                                statue's or a terrain's silhouette is well inside its box's) */
    double pts[SP_VIEW_PTS][3];
} sp_view;

/* sp_georeferenced: 1 when a box looks like map-projected coordinates (SP_GEOREF_MIN). */
int sp_georeferenced(const double bmin[3], const double bmax[3]);

/* sp_view_default: the default view of a cloud whose bounds are bmin..bmax (used as the framed
 * box too) by rule (SP_UP_*); q is the sensor's rotation (w, x, y, z; any length) for
 * SP_UP_SENSOR, ignored otherwise (NULL: identity). */
void sp_view_default(const double bmin[3], const double bmax[3], int rule, const double q[4],
                     sp_view *v);

/* sp_frame_fit: the camera looking along v->dir with v->up that shows the cloud whole in a
 * width x height frame of vertical field of view fov_deg, as large as SP_FILL_MARGIN allows:
 * the target is the box's centre moved so that the projection is centred, and the eye is on
 * the line through the target along -dir, where v's points (the box's eight corners when it
 * has none) just fit. Fills eye, target and up (world up, unless dir is parallel to it). */
void sp_frame_fit(const sp_view *v, int width, int height, double fov_deg, double eye[3],
                  double target[3], double up[3]);

/* sp_frame_orbit: camera i of n on a circle about v->up through the box's centre,
 * SP_ELEVATION_DEG above the horizon, starting at the default view's azimuth and turning
 * counter-clockwise seen from above; every camera at the same distance, the largest at which v's
 * points (or the box's corners), centred on the box's centre, fit from any of the n
 * directions, so that no frame cuts the cloud and the distance never jumps. up_in (NULL:
 * v->up) replaces the axis. */
void sp_frame_orbit(const sp_view *v, const double *up_in, int i, int n, int width, int height,
                    double fov_deg, double eye[3], double target[3], double up[3]);

/* sp_view_hull: sets v->pts to the extreme points of the n points p (3 doubles each, file
 * coordinates) along the SP_VIEW_PTS directions (scaled by the box's extents), counting only
 * points inside v's box (none inside: npts 0, and the box's corners serve). */
void sp_view_hull(sp_view *v, const double *p, uint64_t n);
