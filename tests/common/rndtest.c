/* rndtest.c — see rndtest.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "rndtest.h"

#include "prep.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

rnd_ctx *tu_ctx;

int tu_egl_group_setup(void **state)
{
    (void)state;
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS")};
    sd_err err = {0};
    tu_ctx = rnd_create(&d, &err);
    if (!tu_ctx) fprintf(stderr, "rnd_create: %s\n", err.msg);
    return tu_ctx ? 0 : -1;
}

int tu_egl_group_teardown(void **state)
{
    (void)state;
    rnd_destroy(tu_ctx);
    tu_ctx = NULL;
    return 0;
}

uint32_t tu_upload(rnd_ctx *r, const pc_prepared *pc)
{
    sd_err err = {0};
    int64_t id = rnd_upload(r, pc, &err);
    if (id <= 0) fail_msg("upload: %s", err.msg);
    return (uint32_t)id;
}

void tu_scans_load(tu_scans *s, int w, int h)
{
    tu_prep_data("Guanyin.ply", &s->g);
    tu_prep_data("bunnyData.pts", &s->b);
    tu_camera_box(s->g.bmin, s->g.bmax, w, h, &s->cg);
    tu_camera_box(s->b.bmin, s->b.bmax, w, h, &s->cb);
    s->close = s->cg;
    for (int a = 0; a < 3; a++)
        s->close.eye[a] = s->cg.target[a] + 0.3 * (s->cg.eye[a] - s->cg.target[a]);
}

void tu_scans_free(tu_scans *s)
{
    pc_prepared_free(&s->g);
    pc_prepared_free(&s->b);
}

uint32_t tu_upload_intensities(rnd_ctx *r, pc_prepared *pc)
{
    float *inten = malloc(pc->n * sizeof *inten), *had = pc->intensity;
    assert_non_null(inten);
    uint32_t attrs = pc->attrs;
    for (uint64_t i = 0; i < pc->n; i++) inten[i] = (float)(i % 1000);
    pc->intensity = inten, pc->attrs |= PC_ATTR_INTENSITY;
    uint32_t id = tu_upload(r, pc);
    pc->intensity = had, pc->attrs = attrs;
    free(inten);
    return id;
}

void tu_render(rnd_ctx *r, uint32_t id, const rnd_camera *cam, const sp_params *p,
               int want_float, rnd_frame *f)
{
    sd_err err = {0};
    int rc = rnd_render(r, id, cam, p, want_float, f, &err);
    if (rc < 0) fail_msg("render: %s", err.msg);
}

void tu_new_cloud(pc_prepared *pc, uint64_t n, uint64_t nb)
{
    memset(pc, 0, sizeof *pc);
    pc->n = n;
    pc->attrs = PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F | PC_ATTR_INTENSITY;
    pc->nbatches = nb ? nb : (n + PC_BATCH_POINTS - 1) / PC_BATCH_POINTS;
    sd_err err = {0};
    if (pc_prepared_alloc(pc, &err) != 0) fail_msg("pc_prepared_alloc: %s", err.msg);
    for (uint64_t i = 0; i < n; i++) {
        pc->normal[3 * i + 2] = 1;
        pc->radius[i] = 0.01f;
        for (int k = 0; k < 4; k++) pc->rgba[4 * i + k] = 255;
    }
}

void tu_finish_cloud(pc_prepared *pc, const double off[3])
{
    pc_prepared_make_batches(pc, (uint32_t)((pc->n + pc->nbatches - 1) / pc->nbatches));
    for (int k = 0; k < 3; k++) {
        pc->bmin[k] = INFINITY, pc->bmax[k] = -INFINITY;
        for (uint64_t b = 0; b < pc->nbatches; b++) {
            pc->bmin[k] = fmin(pc->bmin[k], pc->batches[b].bmin[k] + off[k]);
            pc->bmax[k] = fmax(pc->bmax[k], pc->batches[b].bmax[k] + off[k]);
        }
    }
    memcpy(pc->offset, off, 3 * sizeof *off);
}

void tu_prep_data(const char *name, pc_prepared *pc)
{
    char path[4096];
    tu_data(name, path, sizeof path);
    sd_err err = {0};
    pc_cloud cl;
    if (pc_load(path, &cl, &err) < 0) fail_msg("%s: %s", name, err.msg);
    prep_desc pd = {0};
    int rc = prep_run(&cl, &pd, pc, &err);
    pc_cloud_free(&cl);
    if (rc < 0) fail_msg("%s: %s", name, err.msg);
}

void tu_camera_box(const double bmin[3], const double bmax[3], int w, int h, rnd_camera *cam)
{
    memset(cam, 0, sizeof *cam);
    cam->width = w;
    cam->height = h;
    cam->fov_deg = 45.0f;
    double ctr[3], ext[3];
    for (int i = 0; i < 3; i++) ctr[i] = 0.5 * (bmin[i] + bmax[i]), ext[i] = bmax[i] - bmin[i];
    double r = 0.5 * sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
    if (!(r > 0)) r = 1.0;
    int flat = ext[2] < 0.1 * fmax(ext[0], ext[1]);
    int y_up = flat || (ext[1] > ext[0] && ext[1] > ext[2]);
    double dir[3] = {0.55, 1, 0.45};
    if (flat) dir[0] = 0, dir[1] = -0.35, dir[2] = 1;
    else if (y_up) dir[0] = 0.55, dir[1] = 0.45, dir[2] = 1;
    cam->up[1] = y_up ? 1 : 0;
    cam->up[2] = y_up ? 0 : 1;
    double l = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    double fy = 45.0 * M_PI / 180, aspect = h > 0 ? (double)w / h : 1.0;
    double fx = 2 * atan(tan(fy / 2) * aspect);
    double dist = r / sin(0.5 * fmin(fx, fy)) * 1.02;
    for (int i = 0; i < 3; i++) {
        cam->target[i] = ctr[i];
        cam->eye[i] = ctr[i] + dir[i] / l * dist;
    }
}
