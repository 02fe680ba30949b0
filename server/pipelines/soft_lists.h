/* soft_lists.h — model=base and model=concentric of the `soft` pipeline: the soft points as
 * spheres of non-uniform density through per-pixel fragment lists (count with atomics, prefix
 * sum, store with ray-sphere intersections, per-pixel sort and blend; soft_frag.comp,
 * soft_scan.comp, soft_fblend.comp), composited over the solid frame. Internal to the renderer.
 *
 * Length unit. The paper's density rho = r - sqrt(z^2 + d^2) (eq. 5) has the unit of a length,
 * so its integral (eq. 7) that of an area and lambda that of 1 / area; the paper leaves the
 * unit open. Here lengths are measured in u = the cloud's median splat radius times
 * splat_scale (1 when the cloud has no median, e.g. test clouds made in memory): a soft point of
 * the median radius has the optical depth lambda (1 - exp(-lambda) opacity) through its centre,
 * comparable with the Express-Model's lambda there. In the Concentric-Model the density between
 * shell i and shell i + 1 is mu'_i = R / (N r_i) (1 - d / r_i) (eq. 13, 15; the innermost shell
 * only, as eq. 16-18 write it), times kappa = R K[N], where K[N] (soft_lists_kappa) makes the
 * sphere's total density (its optical depth integrated over its screen disc) the Base-Model's;
 * the paper leaves that scale to lambda. The profiles still differ: eq. 13-15 put more density
 * near the centre ray (there its optical depth is 2-4x the Base-Model's) and less half way out.
 *
 * Memory. The fragment buffer grows to what the frame needs, up to the cap: the parameter
 * soft_frag_mib, and never more than one storage block (llvmpipe: 128 MiB, 8M samples of 16
 * bytes). A stripe whose samples exceed the cap is cut into bands of rows that fit, each stored,
 * sorted and blended in turn (the image is unchanged, only slower). A single row that alone
 * exceeds the cap keeps the samples that fit, in the order the store pass wrote them (the rest of
 * the row loses soft samples: wrong there), and the frame carries RND_FRAME_SOFT_TRUNCATED; so
 * does a Base-Model pixel where more than 32 spheres overlap (the spheres past 32 are left out
 * of that pixel), and a pixel past 2^31 / (the stripe's pixels) samples (2330 at 1280x720,
 * 1165 Base spheres; the counts are 32-bit; the spheres past it are left out of that pixel).
 * Never a silent wrong image, never a crash. */
#pragma once
#include <stdint.h>

#include "pipe.h"

typedef struct soft_lists {
    GLuint prog[5];            /* count, store, scan, blend (base or concentric), resolve */
    GLuint blend[2];           /* blend programs: [0] base, [1] concentric */
    GLuint vao;
    GLuint counts_buf, fill_buf, frags_buf, layer_buf, layer_tex;
    uint64_t counts_bytes, fill_bytes, frags_bytes, layer_bytes;
    uint32_t *offs;            /* the scanned offsets, read back when bands are needed */
    uint64_t offs_cap;
    uint64_t samples;          /* samples counted since creation (before the cap) */
    float kappa[65];           /* K[N], N = 1..64 concentric shells (index 0 unused) */
} soft_lists;

/* soft_lists_kappa: K[N] for N = 1..64 (k[0] = 0): the ratio of the Base-Model's integral of
 * the optical depth over a unit sphere's disc (1/6 of 2 pi) to the Concentric-Model's with N
 * shells, by the midpoint rule over 1000 rings. */
void soft_lists_kappa(float k[65]);

/* soft_light: the unit light direction of p (eye space, +z when p->light is zero): splat's. */
void soft_light(const sp_params *p, float light[3]);

int soft_lists_create(rnd_kit *k, soft_lists *s, sd_err *err);
void soft_lists_destroy(rnd_kit *k, soft_lists *s);

/* soft_lists_draw: composites nsoft soft points (the first nsoft indices of the buffer texture
 * on RND_T_SOFT_IDX; the set's buffers bound by rnd_kit_bind_set) over rows [y0, y0 + n) of
 * d->target. keys: whether the splat keys on RND_T_SPLAT_KEYS hold the solid surface for rows
 * [yb, yb + nb). concentric: 0 Base, 1 Concentric. Adds RND_FRAME_* bits to d->out->flags.
 * Returns 0 or SD_E*. */
int soft_lists_draw(rnd_kit *k, soft_lists *s, const rnd_draw *d, uint32_t nsoft, int concentric,
                    int keys, int y0, int n, int yb, int nb, sd_err *err);
