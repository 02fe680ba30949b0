/* soft_proj.c — soft_bin.comp's PASS 0 on the host (soft_proj.h). */
#include "soft_proj.h"

#include <math.h>
#include <string.h>

#include "params.h"
#include "progress.h"
#include "simd.h"

enum { BLOCK = 1 << 14 }; /* discs a chunk of the parallel loop */

/* project_block: PASS 0's loop body for soft points j in [a, b), operation for operation as
 * the shader writes it (lib_shade.glsl's shade included), 8 points at a time in 8-wide vectors
 * (GCC vector extensions, compiled for AVX2 and the baseline by PREP_CLONES; ISO C: no
 * contraction, so each lane computes what the scalar code would); the last group's missing
 * lanes repeat its first point and are not written. pow(ndh, 32) is five squarings (powf was a
 * tenth of the projection's time; llvmpipe's pow is exp2(32 log2 ndh) with its own
 * approximations, which neither repeats exactly: the squarings are within ~2e-6 of the true
 * power, powf within 6e-8). */
typedef float v8f __attribute__((vector_size(32)));
typedef int v8i __attribute__((vector_size(32)));
/* m ? a : b lane by lane (m all ones or all zeros) */
#define SEL(m, a, b) ((v8f)(((v8i)(a) & (m)) | ((v8i)(b) & ~(m))))
/* clamp01 lane by lane, as the scalar one (NaN stays NaN) */
#define CLAMP01(v) SEL((v) < 0.0f, zero, SEL((v) > 1.0f, one, (v)))

PREP_CLONES
static void project_block(const soft_proj_job *job, uint64_t a, uint64_t b)
{
    const float *V = job->view, *P = job->proj;
    const v8f zero = {0}, one = zero + 1.0f;
    const int color = job->color, persp = P[15] == 0.0f;
    const int shaded = color == SP_COLOR_RGB || color == SP_COLOR_INTENSITY;
    const float rscale = P[5] * 0.5f * (float)job->height;
    const float t = job->t, lm = job->lm, W = (float)job->width, H = (float)job->height;
    /* shade()'s half vector: the same for every point */
    const float *l = job->light;
    float hv[3] = {l[0] + 0.0f, l[1] + 0.0f, l[2] + 1.0f};
    float hl = hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2];
    float hs[3] = {0.0f, 0.0f, 0.0f};
    if (hl > 0.0f) {
        float is = 1.0f / sqrtf(hl);
        for (int k = 0; k < 3; k++) hs[k] = hv[k] * is;
    }
    for (uint64_t j0 = a; j0 < b; j0 += 8) {
        int nl = b - j0 < 8 ? (int)(b - j0) : 8;
        v8f p[3], q[3], rad, f;
        uint32_t src[8];
        for (int ln = 0; ln < 8; ln++) {
            uint32_t i = job->idx[j0 + (uint64_t)(ln < nl ? ln : 0)];
            for (int k = 0; k < 3; k++) p[k][ln] = job->pos[3 * (size_t)i + k];
            for (int k = 0; k < 3; k++) q[k][ln] = job->nrm[3 * (size_t)i + k];
            rad[ln] = job->rad[i];
            f[ln] = job->f[i];
            src[ln] = job->src[i];
        }
        v8f e[4], c[4];
        for (int k = 0; k < 4; k++) e[k] = V[k] * p[0] + V[4 + k] * p[1] + V[8 + k] * p[2] + V[12 + k];
        v8f depth = -e[2];
        v8f r = rad * job->scale;
        for (int k = 0; k < 4; k++)
            c[k] = P[k] * e[0] + P[4 + k] * e[1] + P[8 + k] * e[2] + P[12 + k] * e[3];
        v8i front = depth > job->znear;
        v8f rpx = SEL(front, r * rscale / depth, zero);
        v8f px = SEL(front, (c[0] / c[3] * 0.5f + 0.5f) * W, zero - 1e9f);
        v8f py = SEL(front, (c[1] / c[3] * 0.5f + 0.5f) * H, zero - 1e9f);
        v8f w = one;
        if (lm > t) {
            v8f u = (f - t) / (lm - t);
            w = CLAMP01(u);
        }
        v8f col[3];
        if (color == SP_COLOR_RGB) {
            for (int k = 0; k < 3; k++)
                for (int ln = 0; ln < 8; ln++) col[k][ln] = (float)(src[ln] >> (8 * k) & 0xffu);
            for (int k = 0; k < 3; k++) col[k] = col[k] / 255.0f;
        } else if (color == SP_COLOR_INTENSITY) {
            v8f v;
            memcpy(&v, src, sizeof v);
            col[0] = col[1] = col[2] = CLAMP01(v);
        } else if (color == SP_COLOR_DEPTH) {
            v8f u = (depth - job->znear) / (job->zfar - job->znear);
            col[0] = col[1] = col[2] = one - CLAMP01(u);
        } else {
            col[0] = zero + 0.5f, col[1] = zero + 0.5f, col[2] = one;
        }
        if (shaded) {
            v8f nn[3];
            for (int k = 0; k < 3; k++) nn[k] = V[k] * q[0] + V[4 + k] * q[1] + V[8 + k] * q[2];
            v8f nl2 = nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2], is;
            for (int ln = 0; ln < 8; ln++) is[ln] = nl2[ln] > 0.0f ? 1.0f / sqrtf(nl2[ln]) : 0.0f;
            v8i pos = nl2 > 0.0f;
            nn[0] = SEL(pos, nn[0] * is, zero);
            nn[1] = SEL(pos, nn[1] * is, zero);
            nn[2] = SEL(pos, nn[2] * is, one);
            v8f toward = persp ? nn[0] * e[0] + nn[1] * e[1] + nn[2] * e[2] : -nn[2];
            v8i flip = toward > 0.0f;
            for (int k = 0; k < 3; k++) nn[k] = SEL(flip, -nn[k], nn[k]);
            /* shade(nn, light) */
            v8f ndl = nn[0] * l[0] + nn[1] * l[1] + nn[2] * l[2];
            ndl = SEL(ndl > 0.0f, ndl, zero);
            v8f ndh = zero;
            if (hl > 0.0f) {
                ndh = nn[0] * hs[0] + nn[1] * hs[1] + nn[2] * hs[2];
                ndh = SEL(ndh > 0.0f, ndh, zero);
            }
            v8f p2 = ndh * ndh, p4 = p2 * p2, p8 = p4 * p4, p16 = p8 * p8, p32 = p16 * p16;
            v8f sh = 0.2f + 0.7f * ndl + 0.1f * p32;
            for (int k = 0; k < 3; k++) col[k] *= sh;
        }
        for (int ln = 0; ln < nl; ln++) {
            float *o = job->out + 8 * (size_t)(j0 + (uint64_t)ln);
            o[0] = px[ln], o[1] = py[ln], o[2] = rpx[ln], o[3] = depth[ln];
            o[4] = col[0][ln], o[5] = col[1][ln], o[6] = col[2][ln], o[7] = w[ln];
        }
    }
}

static int block_task(void *ctx, size_t chunk, int tid, sd_err *err)
{
    const soft_proj_job *job = ctx;
    uint64_t a = (uint64_t)chunk * BLOCK, b = a + BLOCK < job->n ? a + BLOCK : job->n;
    project_block(job, a, b);
    return 0;
}

void soft_proj_run(const soft_proj_job *job)
{
    size_t nblocks = ((size_t)job->n + BLOCK - 1) / BLOCK;
    int nt = job->threads < 1 ? 1 : job->threads;
    if ((size_t)nt > nblocks) nt = nblocks ? (int)nblocks : 1;
    prep_par_for(nt, nblocks, block_task, (void *)job, NULL, NULL);
}
