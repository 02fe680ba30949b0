/* test_render_params.c — no state survives a parameter change: for EVERY parameter of the
 * parameter table (protocol/params.h SP_PARAM_LIST, read at run time, so a new parameter is
 * covered without a line here), in every pipeline, a frame drawn right after that one
 * parameter changed (by a renderer whose caches hold the frame before: soft's and olt's F per
 * point, keyed by field, classes and the axis; soft's split, keyed by t; the pipelines' own
 * state) equals, byte for byte, the frame a renderer draws for those parameters with no history
 * on that cloud (a fresh upload: every per-cloud cache made anew), and going back to the
 * first parameters gives the first frame again. A cache that misses one of its keys (a field
 * cache not made anew when only `classes` changes) shows as a difference.
 *
 * The frame must also change where the parameter matters: each parameter must change some
 * pipeline's frame in some base, but for those listed in NOT_RENDERED (encoding, protocol, and
 * a memory cap), and the cache keys must change soft's and olt's frames (REQUIRED). A new
 * parameter that changes no frame fails here until it is shown to matter or listed.
 *
 * The scene: 3,600 points on a noisy plane with a few lifted, LAS classes 0-4, intensities, a
 * scalar named `quality` and random F, so that every `field` source differs from the others;
 * three bases (color=field with field=class; field=axis-distance with shading=edl and the
 * modulation on; model=concentric with order=tile), each parameter moved to one other value derived from its
 * row (the next enum value; a float or vector half of itself further from its default, inside
 * its range; an integer a quarter more, at least 1). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "params.h"
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "rng.h"
#include "testutil.h"

enum { W = 64, H = 64, NX = 60, NBASE = 3 };
static const double OFF[3] = {500000.0, 4100000.0, 120.0};

/* Parameters exempt from "must change a frame": those that are no input of a frame (how it is
 * encoded, protocol behaviour), and soft_frag_mib, a memory cap that changes a frame only when
 * soft samples are dropped, where which samples go depends on the order the GPU's threads come
 * in, so that such frames cannot be compared byte for byte (test_render_soft_models's
 * test_memory_cap checks the cap). */
static const char *const NOT_RENDERED[] = {"format",    "quality",     "subsampling",
                                           "lod_first", "provisional", "pipeline",
                                           "soft_frag_mib"};

/* (parameter, pipeline, base) whose change must show in that pipeline's frame: the keys of
 * the pipelines' caches. */
static const struct {
    const char *param;
    int pipe, base;
} REQUIRED[] = {
    {"classes", SP_PIPE_SOFT, 0}, {"classes", SP_PIPE_OLT, 0},
    {"field", SP_PIPE_SOFT, 0},   {"field", SP_PIPE_OLT, 0},
    {"axis_a", SP_PIPE_SOFT, 1},  {"axis_a", SP_PIPE_OLT, 1},
    {"axis_b", SP_PIPE_SOFT, 1},  {"axis_b", SP_PIPE_OLT, 1},
    {"t", SP_PIPE_SOFT, 1},       {"t", SP_PIPE_OLT, 1},
};

static int listed(const char *name)
{
    for (size_t i = 0; i < sizeof NOT_RENDERED / sizeof *NOT_RENDERED; i++)
        if (!strcmp(name, NOT_RENDERED[i])) return 1;
    return 0;
}

static void scene(pc_prepared *pc)
{
    memset(pc, 0, sizeof *pc);
    pc->n = (uint64_t)NX * NX;
    pc->attrs = PC_ATTR_RGB | PC_ATTR_NORMAL | PC_ATTR_RADIUS | PC_ATTR_F | PC_ATTR_INTENSITY |
                PC_ATTR_CLASS | PC_ATTR_SCALAR;
    pc->nbatches = 4;
    sd_err err = {0};
    if (pc_prepared_alloc(pc, &err) != 0) fail_msg("pc_prepared_alloc: %s", err.msg);
    snprintf(pc->scalar_name, sizeof pc->scalar_name, "quality");
    rng g;
    g.s = 27;
    const float h = 0.02f;
    for (uint64_t k = 0; k < pc->n; k++) {
        int i = (int)(k % NX), j = (int)(k / NX);
        float *p = pc->pos + 3 * k;
        p[0] = (i - 0.5f * (NX - 1)) * h, p[1] = (j - 0.5f * (NX - 1)) * h;
        p[2] = (float)(0.003 * (uni(&g) - 0.5)) + (k % 7 == 0 ? 0.1f : 0.0f);
        pc->normal[3 * k + 2] = 1.0f;
        pc->radius[k] = 1.5f * h;
        for (int c = 0; c < 3; c++) pc->rgba[4 * k + c] = (uint8_t)(40 + 200 * uni(&g));
        pc->rgba[4 * k + 3] = 255;
        pc->F[k] = (float)uni(&g);
        pc->intensity[k] = (float)uni(&g);
        pc->scalar[k] = (float)uni(&g);
        pc->cls[k] = (uint8_t)((i / 12 + j / 12) % 5);
    }
    pc->sigma = h;
    tu_finish_cloud(pc, OFF);
}

/* The three bases (see the top). */
static void base_params(int b, sp_params *p)
{
    sp_params_defaults(p);
    p->color = SP_COLOR_FIELD;
    if (b == 0) p->field = SP_FIELD_CLASS, p->classes = 22; /* classes 1, 2 and 4 soft */
    if (b == 1) {
        p->field = SP_FIELD_AXIS, p->shading = SP_SHADING_EDL;
        p->l_m = 0.7f; /* the modulation on (l_m > t) */
        p->axis_a[0] = -0.3f, p->axis_b[0] = -0.3f, p->axis_b[1] = 1.0f;
    }
    if (b == 2) p->model = SP_MODEL_CONCENTRIC, p->order = SP_ORDER_TILE, p->color = SP_COLOR_RGB;
}

/* Moves number a in [lo, hi] half of itself further (delta0 when it is 0), inside. */
static double further(double a, double lo, double hi, double delta0)
{
    double d = a != 0 ? 0.5 * fabs(a) : delta0;
    return a + d <= hi ? a + d : a - d >= lo ? a - d : 0.5 * (lo + hi);
}

/* alt: p with parameter i moved to another value derived from its row of the table. */
static void alt(const sp_params *p, int i, sp_params *q)
{
    *q = *p;
    const sp_param_info *in = &sp_param_table[i];
    char text[128], emsg[160];
    int rc = 0;
    if (in->type == SP_T_ENUM) {
        int32_t v = 0, nv = 1;
        for (const char *c = in->values; *c; c++) nv += *c == '|';
        char cur[64];
        sp_param_get_text(p, i, cur, sizeof cur);
        for (int k = 0; k < nv; k++) {
            sp_enum_name(i, k, text, sizeof text);
            if (!strcmp(text, cur)) v = k;
        }
        sp_enum_name(i, (v + 1) % nv, text, sizeof text);
    } else if (in->type == SP_T_FLOAT) {
        double a = strtod((sp_param_get_text(p, i, text, sizeof text), text), NULL);
        snprintf(text, sizeof text, "%.9g", further(a, in->min, in->max, 0.1));
    } else if (in->type == SP_T_INT) {
        double a = strtod((sp_param_get_text(p, i, text, sizeof text), text), NULL);
        double d = fmax(1.0, floor(0.25 * a));
        snprintf(text, sizeof text, "%.0f", a + d <= in->max ? a + d : a - d);
    } else {
        char cur[128];
        sp_param_get_text(p, i, cur, sizeof cur);
        double v[3];
        if (sscanf(cur, "%lf,%lf,%lf", &v[0], &v[1], &v[2]) != 3) fail_msg("%s: '%s'", in->name, cur);
        for (int k = 0; k < 3; k++) v[k] = further(v[k], in->min, in->max, 0.25);
        snprintf(text, sizeof text, "%.9g,%.9g,%.9g", v[0], v[1], v[2]);
    }
    rc = sp_param_set_text(q, in->name, text, emsg, sizeof emsg);
    if (rc != 0) fail_msg("%s=%s: %s", in->name, text, emsg);
}

/* One frame, or its error code (frames that both fail with one code are the same outcome). */
static int frame(rnd_ctx *r, uint32_t id, const rnd_camera *cam, const sp_params *p,
                 rnd_frame *f)
{
    sd_err err = {0};
    return rnd_render(r, id, cam, p, 0, f, &err);
}

static int same(int ra, const rnd_frame *a, int rb, const rnd_frame *b)
{
    if (ra != rb) return 0;
    return ra < 0 || !memcmp(a->rgba8, b->rgba8, (size_t)W * H * 4);
}

static void test_every_parameter(void **state)
{
    (void)state;
    pc_prepared pc;
    scene(&pc);
    /* splat's accumulation in fixed point: float atomics add in the order the threads come,
     * which moves a byte by one between two draws of the same frame where large splats overlap
     * (seen here in olt with splat_scale 4); integer sums do not depend on the order */
    rnd_desc d = {.backend = RND_BACKEND_EGL, .shader_dir = getenv("SPLATD_SHADERS"),
                  .pipe = {.splat_fixed = 1}};
    sd_err err = {0};
    rnd_ctx *warm = rnd_create(&d, &err), *cold = warm ? rnd_create(&d, &err) : NULL;
    if (!cold) fail_msg("rnd_create: %s", err.msg);
    uint32_t wid = tu_upload(warm, &pc);
    rnd_camera cam;
    tu_camera_box(pc.bmin, pc.bmax, W, H, &cam);
    cam.eye[0] += 0.3, cam.eye[1] -= 0.4; /* oblique: layers overlap */
    int changed[SP_PARAM_COUNT] = {0}, stale = 0;
    int changed_at[SP_PARAM_COUNT][NBASE][SP_PIPE_COUNT];
    memset(changed_at, 0, sizeof changed_at);
    rnd_frame f0 = {0}, f1 = {0}, f2 = {0}, fc = {0};
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        const char *name = sp_param_table[i].name;
        if (!strcmp(name, "pipeline")) continue; /* every pipeline is drawn anyway */
        uint32_t cid = tu_upload(cold, &pc);
        for (int b = 0; b < NBASE; b++)
            for (int pi = 0; pi < SP_PIPE_COUNT; pi++) {
                sp_params p, q;
                base_params(b, &p);
                p.pipeline = pi;
                alt(&p, i, &q);
                int r0 = frame(warm, wid, &cam, &p, &f0);
                int r1 = frame(warm, wid, &cam, &q, &f1);
                int r2 = frame(warm, wid, &cam, &p, &f2);
                int rc = frame(cold, cid, &cam, &q, &fc);
                if (r0 < 0) fail_msg("base %d, pipeline %d: the base frame fails (%d)", b, pi, r0);
                int ok = same(r1, &f1, rc, &fc) && same(r0, &f0, r2, &f2);
                if (!ok) {
                    stale++;
                    printf("STALE: %s changed alone, base %d, pipeline %d: after the change %s "
                           "the fresh frame, back again %s the first\n", name, b, pi,
                           same(r1, &f1, rc, &fc) ? "equals" : "DIFFERS FROM",
                           same(r0, &f0, r2, &f2) ? "equals" : "DIFFERS FROM");
                }
                if (!same(r0, &f0, r1, &f1)) changed[i] = 1, changed_at[i][b][pi] = 1;
            }
        rnd_release(cold, cid);
        int nch = 0;
        for (int b = 0; b < NBASE; b++)
            for (int pi = 0; pi < SP_PIPE_COUNT; pi++) nch += changed_at[i][b][pi];
        printf("%-16s changes the frame in %2d of %d (base, pipeline)\n", name, nch,
               NBASE * SP_PIPE_COUNT);
    }
    int unseen = 0;
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        const char *name = sp_param_table[i].name;
        if (!changed[i] && !listed(name)) {
            printf("UNSEEN: %s changes no frame in any base and pipeline\n", name);
            unseen++;
        }
    }
    for (size_t k = 0; k < sizeof REQUIRED / sizeof *REQUIRED; k++) {
        int i = sp_param_find(REQUIRED[k].param);
        assert_true(i >= 0);
        if (!changed_at[i][REQUIRED[k].base][REQUIRED[k].pipe]) {
            printf("UNSEEN: %s in pipeline %d, base %d\n", REQUIRED[k].param, REQUIRED[k].pipe,
                   REQUIRED[k].base);
            unseen++;
        }
    }
    rnd_frame_free(&f0), rnd_frame_free(&f1), rnd_frame_free(&f2), rnd_frame_free(&fc);
    rnd_release(warm, wid);
    rnd_destroy(warm);
    rnd_destroy(cold);
    pc_prepared_free(&pc);
    assert_int_equal(stale, 0);
    assert_int_equal(unseen, 0);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_parameter),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
