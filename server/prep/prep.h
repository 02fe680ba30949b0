/* prep.h — preprocessing: a pc_cloud becomes a pc_prepared (prepared.h).
 *
 * Steps, in this order:
 *  1. Morton order: 63-bit codes over the cloud's bounding cube, stable radix sort, and every
 *     attribute permuted alongside (colour and the rest stay with their point). Then batches of
 *     PC_BATCH_POINTS consecutive points with tight bounding boxes. Doing this first makes the
 *     kNN queries below run in Morton order, which keeps their memory accesses local.
 *  2. k nearest neighbours of every point (knn.h: the Morton-cell grid by default, FLANN's
 *     exact single kd-tree on request), on desc.threads threads, in chunks of 16384 queries.
 *  3. Normals, only when the file has none: PCA of the point and its k neighbours (eigenvector
 *     of the covariance's smallest eigenvalue, pca.h). Orientation rule: towards the sensor s
 *     when the file gives its position (pc_cloud.has_viewpoint: a PCD VIEWPOINT other than
 *     PCL's identity default), n . (s - p) >= 0; otherwise away from the cloud's centroid c,
 *     n . (p - c) >= 0. Where that says little (n within 10 degrees of perpendicular to the
 *     direction, e.g. any plane through c) the normal faces up instead: n_z >= 0, or when
 *     |n_z| < 0.1 (near-vertical surfaces) n_y >= 0, or when |n_y| < 0.1 too, n_x >= 0.
 *  4. Radius, only when the file has none: r = 2 R / sqrt(K), R = distance to the farthest of
 *     the K neighbours (Soft Transparency eq. 20 as DESIGN.md interprets it), then limited to
 *     PREP_RADIUS_CAP times the median radius of the point's neighbours (after F is computed
 *     with the unlimited value): a stray point's R reaches to the surface it strayed from and
 *     would otherwise be drawn as a disc covering that surface. Density changes across a scan
 *     (terrestrial scans thin out with distance) move the neighbours' radii too, so the limit
 *     follows them, unlike a cap on the cloud's global median.
 *     Eq. 20 shares the area of a surface among its points. Where the neighbourhood is no
 *     surface, PCA surface variation lambda_min / (l0 + l1 + l2) above PREP_SURFACE_VAR_MAX
 *     (0 on a plane, 1/3 for points scattered through a volume; a 90-degree edge gives
 *     ~0.085), the radius is also limited to PREP_SCATTER_CAP times the cloud's median eq. 20
 *     radius: scattered noise (birds, mixed pixels) and volumetric vegetation then render like
 *     points instead of as discs the size of their empty neighbourhoods, which hid whole scenes
 *     (the synthetic bench cloud's 1 % noise covered its ground and buildings). Planar regions
 *     keep eq. 20 however sparse they are. The PCA runs for this even when the file has
 *     normals (unless it has radii too).
 *  5. F (eq. 21 with |n_i . n_j|, PCA normals being unoriented):
 *     F_i = r_i * sum_j (2 - |n_i . n_j|)^2 / K, divided by the cloud's 99th percentile of F
 *     (F_raw_p99) and clamped to [0, 1].
 *  6. sigma = the median distance to the nearest other point; radius_median; F percentiles.
 * Neighbour lists are kept between steps 3 and 5 (K * 4 bytes a point: 96 MB for 1M points,
 * k = 24) when they fit desc.max_nbr_bytes; otherwise step 5 runs the kNN a second time.
 * Results do not depend on the thread count. */
#pragma once
#include <stddef.h>

#include "cloud.h"
#include "knn.h"
#include "prepared.h"
#include "progress.h"
#include "sd_err.h"

enum { PREP_MAX_K = 256 };       /* most neighbours per point */
enum { PREP_DEFAULT_K = 24 };    /* neighbours when none are asked for (the paper's k) */
#define PREP_RADIUS_CAP 2.0f     /* computed radius <= this x the neighbours' median radius */
#define PREP_SURFACE_VAR_MAX 0.10f /* above: the neighbourhood is no surface (step 4) */
#define PREP_SCATTER_CAP 1.0f    /* there, radius <= this x the cloud's median eq. 20 radius */

typedef struct prep_desc {
    int k;                 /* default PREP_DEFAULT_K: neighbours, 1..256 (fewer when the cloud
                              has no more than k points: then n - 1) */
    int threads;           /* default 0: every online core */
    prep_knn_method knn;   /* default PREP_KNN_GRID; PREP_KNN_FLANN: FLANN's kd-tree */
    int knn_leaf;          /* default 0: the method's default leaf size (knn.h) */
    size_t max_nbr_bytes;  /* default 0: 1 GiB. Neighbour lists above this are recomputed for F
                              instead of kept */
    prep_progress_fn progress; /* default none; called on the calling thread with the phases
                              PROTO_PHASE_REORDER, KNN, NORMALS, FIELD, increasing multiples
                              of 1/20 from 0 to 1 (progress.h) */
    void *user;
} prep_desc;

/* prep_run: preprocesses in (unchanged) into out, a heap pc_prepared (free it with
 * pc_prepared_free). out is zeroed first. Returns 0, or SD_EINVAL (bad desc or cloud: no points,
 * an attribute bit without its array), SD_ELIMIT (2^31 points or more) or SD_ENOMEM, with err
 * filled and out empty. */
int prep_run(const pc_cloud *in, const prep_desc *desc, pc_prepared *out, sd_err *err);

/* prep_orient_normal: step 3's orientation rule for the unit normal n of the point p (local
 * coordinates): towards the sensor vp when has_vp, else away from the centroid c, else up. */
void prep_orient_normal(float n[3], const float p[3], const double c[3], int has_vp,
                        const double vp[3]);

/* prep_percentile: the q-quantile (0..1, nearest rank on the sorted values: index
 * round(q * (n - 1))) of the n values v, which it reorders (selection, not a full sort).
 * 0 when n is 0. */
float prep_percentile(float *v, size_t n, double q);
