/* soft_proj.c — soft_bin.comp's PASS 0 on the host (soft_proj.h). */
#include "soft_proj.h"

#include <math.h>
#include <string.h>

#include "params.h"
#include "progress.h"

enum { BLOCK = 1 << 14 }; /* discs a chunk of the parallel loop */

/* lib_shade.glsl's shade(n, l), operation for operation */
static float shade(const float n[3], const float l[3])
{
    float hv[3] = {l[0] + 0.0f, l[1] + 0.0f, l[2] + 1.0f};
    float hl = hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2];
    float ndl = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
    ndl = ndl > 0.0f ? ndl : 0.0f;
    float ndh = 0.0f;
    if (hl > 0.0f) {
        float is = 1.0f / sqrtf(hl);
        ndh = n[0] * (hv[0] * is) + n[1] * (hv[1] * is) + n[2] * (hv[2] * is);
        ndh = ndh > 0.0f ? ndh : 0.0f;
    }
    /* pow(ndh, 32) as five squarings (powf was a tenth of the projection's time; llvmpipe's
     * pow is exp2(32 log2 ndh) with its own approximations, which neither repeats exactly: the
     * squarings are within ~2e-6 of the true power, powf within 6e-8) */
    float p2 = ndh * ndh, p4 = p2 * p2, p8 = p4 * p4, p16 = p8 * p8, p32 = p16 * p16;
    return 0.2f + 0.7f * ndl + 0.1f * p32;
}

static float clamp01(float v)
{
    return v < 0.0f ? 0.0f : v > 1.0f ? 1.0f : v;
}

/* PASS 0's loop body for soft point j */
static void project_one(const soft_proj_job *job, uint32_t j)
{
    const float *V = job->view, *P = job->proj;
    uint32_t i = job->idx[j];
    const float *p = job->pos + 3 * (size_t)i;
    float e[4];
    for (int k = 0; k < 4; k++) e[k] = V[k] * p[0] + V[4 + k] * p[1] + V[8 + k] * p[2] + V[12 + k];
    float depth = -e[2];
    float r = job->rad[i] * job->scale;
    float c[4];
    for (int k = 0; k < 4; k++)
        c[k] = P[k] * e[0] + P[4 + k] * e[1] + P[8 + k] * e[2] + P[12 + k] * e[3];
    int persp = P[15] == 0.0f;
    float rscale = P[5] * 0.5f * (float)job->height;
    float rpx = depth > job->znear ? r * rscale / depth : 0.0f;
    float px = -1e9f, py = -1e9f;
    if (depth > job->znear) {
        px = (c[0] / c[3] * 0.5f + 0.5f) * (float)job->width;
        py = (c[1] / c[3] * 0.5f + 0.5f) * (float)job->height;
    }
    float t = job->t, lm = job->lm;
    float w = lm > t ? clamp01((job->f[i] - t) / (lm - t)) : 1.0f;
    float col[3];
    uint32_t s = job->src[i];
    int color = job->color;
    if (color == SP_COLOR_RGB) {
        for (int k = 0; k < 3; k++) col[k] = (float)(s >> (8 * k) & 0xffu) / 255.0f;
    } else if (color == SP_COLOR_INTENSITY) {
        float v;
        memcpy(&v, &s, sizeof v);
        col[0] = col[1] = col[2] = clamp01(v);
    } else if (color == SP_COLOR_DEPTH) {
        col[0] = col[1] = col[2] = 1.0f - clamp01((depth - job->znear) / (job->zfar - job->znear));
    } else {
        col[0] = 0.5f, col[1] = 0.5f, col[2] = 1.0f;
    }
    if (color == SP_COLOR_RGB || color == SP_COLOR_INTENSITY) {
        const float *q = job->nrm + 3 * (size_t)i;
        float nn[3];
        for (int k = 0; k < 3; k++) nn[k] = V[k] * q[0] + V[4 + k] * q[1] + V[8 + k] * q[2];
        float nl2 = nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2];
        if (nl2 > 0.0f) {
            float is = 1.0f / sqrtf(nl2);
            for (int k = 0; k < 3; k++) nn[k] *= is;
        } else {
            nn[0] = 0.0f, nn[1] = 0.0f, nn[2] = 1.0f;
        }
        float toward = persp ? nn[0] * e[0] + nn[1] * e[1] + nn[2] * e[2] : -nn[2];
        if (toward > 0.0f)
            for (int k = 0; k < 3; k++) nn[k] = -nn[k];
        float sh = shade(nn, job->light);
        for (int k = 0; k < 3; k++) col[k] *= sh;
    }
    float *o = job->out + 8 * (size_t)j;
    o[0] = px, o[1] = py, o[2] = rpx, o[3] = depth;
    o[4] = col[0], o[5] = col[1], o[6] = col[2], o[7] = w;
}

static int block_task(void *ctx, size_t chunk, int tid, sd_err *err)
{
    const soft_proj_job *job = ctx;
    uint64_t a = (uint64_t)chunk * BLOCK, b = a + BLOCK < job->n ? a + BLOCK : job->n;
    for (uint64_t j = a; j < b; j++) project_one(job, (uint32_t)j);
    return 0;
}

void soft_proj_run(const soft_proj_job *job)
{
    size_t nblocks = ((size_t)job->n + BLOCK - 1) / BLOCK;
    int nt = job->threads < 1 ? 1 : job->threads;
    if ((size_t)nt > nblocks) nt = nblocks ? (int)nblocks : 1;
    prep_par_for(nt, nblocks, block_task, (void *)job, NULL, NULL);
}
