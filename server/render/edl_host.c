/* edl_host.c — Eye-Dome Lighting on the host (edl.h, edl_pass=cpu): the shade of edl.frag,
 * computed over the read-back frame instead of by a fragment pass.
 *
 * Why: on llvmpipe the fragment pass costs ~12 ns of CPU a pixel (Guanyin.ply's 345k-pixel
 * rectangle: ~4.1 ms; edl.c's comment says where it goes), about ten times what the same
 * arithmetic costs here in 8-wide vectors on one core, and the frame is read back anyway. On a
 * GPU the pass is free beside the read-back, so edl_pass=auto keeps gl there.
 *
 * The arithmetic is edl.frag's: per pixel, prod = the product over the 4 neighbours at r pixels
 * of z / clamp(z_n, z / 2^15, z), shade = exp(-k log2 prod), 1 for a background pixel. log2 and
 * exp are computed here with polynomials (below) whose relative error is under 1e-6, far below
 * one step of an 8-bit channel; the shade multiplies the colour, rounded to nearest. The depth is
 * read into a buffer framed by r rows and columns of +inf (as edl.c's copy), so that a
 * neighbour outside the rectangle reads as background without a bounds test, and 8 floats
 * of +inf after the last row let the vector loop read past a row's end. */
#include "edl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "progress.h"
#include "sd_half.h"
#include "simd.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define LITTLE_ENDIAN_RGBA 1
#else
#define LITTLE_ENDIAN_RGBA 0
#endif

typedef prep_v8f v8f;
typedef prep_v8i v8i;

/* Helpers work in place through pointers: an 8-wide vector passed or returned by value changes
 * the ABI between the AVX2 and the baseline clones (-Wpsabi). */
#define VSEL(m, a, b) ((v8f)(((v8i)(a) & (m)) | ((v8i)(b) & ~(m))))
#define VMIN(a, b) VSEL((a) < (b), a, b)
#define VMAX(a, b) VSEL((a) > (b), a, b)

static inline void vload(v8f *v, const float *p)
{
    memcpy(v, p, sizeof *v);
}

/* *x = log2 *x for a positive normal *x: x = 2^e m with m in [sqrt(1/2), sqrt(2)), log2 m =
 * (2 / ln 2) atanh(s), s = (m - 1) / (m + 1), |s| <= 0.172: the series to s^9 leaves < 1e-9. */
static inline void vlog2(v8f *x)
{
    const v8f one = (v8f){0} + 1.0f;
    v8i b = (v8i)*x;
    v8i e = ((b >> 23) & 0xff) - 127;
    v8f m = (v8f)((b & 0x007fffff) | 0x3f800000);
    v8i big = m > 1.41421356f;
    m = VSEL(big, m * 0.5f, m);
    e -= big; /* big is -1 where true */
    v8f s = (m - one) / (m + one), s2 = s * s;
    v8f p = one * (2.0f / 9.0f);
    p = p * s2 + 2.0f / 7.0f;
    p = p * s2 + 2.0f / 5.0f;
    p = p * s2 + 2.0f / 3.0f;
    p = p * s2 + 2.0f;
    *x = __builtin_convertvector(e, v8f) + p * s * 1.44269504088896341f;
}

/* *x = exp *x for *x <= 0: 2^(x log2 e) = 2^n 2^f, n = floor, f in [0, 1); 2^f = e^(f ln 2) by
 * its series to the 8th power (f ln 2 < 0.694: < 1e-7 relative); below 2^-126 the shade is 0
 * in every channel format, so the argument is clamped there. */
static inline void vexp_neg(v8f *x)
{
    const v8f one = (v8f){0} + 1.0f, lo = (v8f){0} - 126.0f;
    v8f v = *x * 1.44269504088896341f;
    v = VMAX(v, lo);
    v8i n = __builtin_convertvector(v, v8i); /* truncates: one too many where v < 0 */
    v8f nf = __builtin_convertvector(n, v8f);
    n += nf > v; /* -1 where true */
    nf = __builtin_convertvector(n, v8f);
    v8f y = (v - nf) * 0.693147180559945309f;
    v8f p = one * (1.0f / 40320.0f);
    p = p * y + 1.0f / 5040.0f;
    p = p * y + 1.0f / 720.0f;
    p = p * y + 1.0f / 120.0f;
    p = p * y + 1.0f / 24.0f;
    p = p * y + 1.0f / 6.0f;
    p = p * y + 0.5f;
    p = p * y + 1.0f;
    p = p * y + 1.0f;
    *x = (v8f)((v8i)p + (n << 23));
}

static inline uint8_t shade8(uint8_t c, float s)
{
    return (uint8_t)((float)c * s + 0.5f);
}

PREP_CLONES
void rnd__edl_host_shade(const float *z, int pw, int r, int w, int h, float k, uint8_t *rgba8,
                         uint16_t *rgba16f, int stride)
{
    const size_t up = (size_t)r * (size_t)pw;
    for (int y = 0; y < h; y++) {
        const float *row = z + (size_t)(y + r) * (size_t)pw + (size_t)r;
        uint8_t *p8 = rgba8 ? rgba8 + (size_t)y * (size_t)stride * 4 : NULL;
        uint16_t *p16 = rgba16f ? rgba16f + (size_t)y * (size_t)stride * 4 : NULL;
        for (int x = 0; x < w; x += 8) {
            const float *c = row + x;
            const v8f one = (v8f){0} + 1.0f;
            v8f zc, n0, n1, n2, n3;
            vload(&zc, c);
            v8i fin = zc < 3.0e38f;
            uint64_t any[4];
            memcpy(any, &fin, sizeof any);
            if (!(any[0] | any[1] | any[2] | any[3])) continue; /* 8 background pixels */
            vload(&n0, c + r);
            vload(&n1, c + up);
            vload(&n2, c - r);
            vload(&n3, c - up);
            /* q_n = clamp(z_n, z / 2^15, z) / z, exactly 1 where z_n >= z; the shade is
             * exp(k log2(q_0 q_1 q_2 q_3)), edl.frag's exp(-k log2 prod z / z_n) with one
             * division instead of four (the product stays >= 2^-60, a normal float) */
            v8f rz = one / zc, lo = zc * (1.0f / 32768.0f);
            n0 = VMAX(n0, lo), n1 = VMAX(n1, lo), n2 = VMAX(n2, lo), n3 = VMAX(n3, lo);
            n0 = VSEL(n0 < zc, n0 * rz, one), n1 = VSEL(n1 < zc, n1 * rz, one);
            n2 = VSEL(n2 < zc, n2 * rz, one), n3 = VSEL(n3 < zc, n3 * rz, one);
            v8f q = (n0 * n1) * (n2 * n3);
            v8i bg = ~fin; /* +inf (and a NaN, never written) */
            q = VSEL(bg, one, q);
            v8i flat = q == 1.0f;
            v8f s = q;
            vlog2(&s);
            s *= k;
            vexp_neg(&s);
            s = VSEL(flat, one, s);
            int n = w - x < 8 ? w - x : 8;
            if (LITTLE_ENDIAN_RGBA && p8 && n == 8) {
                /* 8 whole pixels as 32-bit lanes (R the low byte): each channel c * s + 0.5
                 * truncated, as shade8; alpha, the high byte, kept */
                v8i px;
                memcpy(&px, p8 + (size_t)x * 4, sizeof px);
                v8f cr = __builtin_convertvector(px & 0xff, v8f) * s + 0.5f;
                v8f cg = __builtin_convertvector((px >> 8) & 0xff, v8f) * s + 0.5f;
                v8f cb = __builtin_convertvector((px >> 16) & 0xff, v8f) * s + 0.5f;
                px = (px & ((v8i){0} - 16777216)) | __builtin_convertvector(cr, v8i) |
                     __builtin_convertvector(cg, v8i) << 8 | __builtin_convertvector(cb, v8i) << 16;
                memcpy(p8 + (size_t)x * 4, &px, sizeof px);
            }
            if (LITTLE_ENDIAN_RGBA && !p16 && n == 8) continue;
            for (int j = 0; j < n; j++) {
                float sj = s[j];
                if (sj == 1.0f) continue; /* a plane facing the camera stays bit for bit */
                size_t i = (size_t)(x + j) * 4;
                if (p8 && (!LITTLE_ENDIAN_RGBA || n < 8)) {
                    p8[i] = shade8(p8[i], sj);
                    p8[i + 1] = shade8(p8[i + 1], sj);
                    p8[i + 2] = shade8(p8[i + 2], sj);
                }
                if (p16)
                    for (int ch = 0; ch < 3; ch++)
                        p16[i + (size_t)ch] =
                            sd_float_to_half(sd_half_to_float(p16[i + (size_t)ch]) * sj);
            }
        }
    }
}

enum { EDL_BAND_ROWS = 32 };

typedef struct edl_band {
    const float *z;
    int pw, r, w, h;
    float k;
    uint8_t *rgba8;
    uint16_t *rgba16f;
    int stride;
} edl_band;

/* prep_par_for's work: rows [EDL_BAND_ROWS b, + EDL_BAND_ROWS) of the rectangle. */
static int edl_band_run(void *ctx, size_t b, int tid, sd_err *err)
{
    const edl_band *j = ctx;
    int y0 = (int)b * EDL_BAND_ROWS, n = j->h - y0 < EDL_BAND_ROWS ? j->h - y0 : EDL_BAND_ROWS;
    size_t px = (size_t)y0 * (size_t)j->stride * 4;
    rnd__edl_host_shade(j->z + (size_t)y0 * (size_t)j->pw, j->pw, j->r, j->w, n, j->k,
                        j->rgba8 + px, j->rgba16f ? j->rgba16f + px : NULL, j->stride);
    return 0;
}

int rnd__edl_host(rnd_edl *e, const gl_api *gl, const rnd_target *t, const int rect[4],
                  float strength, float radius, uint8_t *rgba8, uint16_t *rgba16f, int width,
                  sd_err *err)
{
    if (!(strength > 0.0f)) return 0; /* strength 0: the frame stays bit for bit */
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) return 0;
    int r = (int)floorf(radius + 0.5f);
    r = r > 1 ? r : 1;
    int w = rect[2] - rect[0], h = rect[3] - rect[1], pw = w + 2 * r;
    size_t n = (size_t)pw * (size_t)(h + 2 * r) + 8;
    if (e->host_cap < n) {
        float *p = realloc(e->host, n * sizeof *p);
        if (!p)
            return sd_errf(err, SD_ENOMEM, "out of memory for the EDL pass's %dx%d depth", w, h);
        e->host = p;
        e->host_cap = n;
    }
    float *z = e->host;
    const float inf = INFINITY;
    for (size_t i = 0; i < (size_t)r * (size_t)pw; i++) z[i] = inf;
    for (size_t i = (size_t)(h + r) * (size_t)pw; i < n; i++) z[i] = inf;
    for (int y = r; y < h + r; y++) {
        float *row = z + (size_t)y * (size_t)pw;
        for (int x = 0; x < r; x++) row[x] = row[w + r + x] = inf;
    }
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    gl->BindFramebuffer(GL_READ_FRAMEBUFFER, t->fbo);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, pw);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT1);
    gl->ReadPixels(rect[0], rect[1], w, h, GL_RED, GL_FLOAT, z + (size_t)r * (size_t)pw + r);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, 0);
    size_t at = ((size_t)rect[1] * (size_t)width + (size_t)rect[0]) * 4;
    edl_band job = {.z = z, .pw = pw, .r = r, .w = w, .h = h,
                    .k = RND_EDL_SCALE * strength / 4.0f, .rgba8 = rgba8 + at,
                    .rgba16f = rgba16f ? rgba16f + at : NULL, .stride = width};
    /* Bands of EDL_BAND_ROWS rows on every core: a thread costs ~50 us to start, a band of
     * 1280 pixels x 32 rows ~0.2 ms on one. */
    size_t nb = (size_t)(h + EDL_BAND_ROWS - 1) / EDL_BAND_ROWS;
    return prep_par_for(nb > 1 ? prep_default_threads() : 1, nb, edl_band_run, &job, NULL, err);
}
