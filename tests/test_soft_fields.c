/* test_soft_fields.c — every source of `field` (the solid/soft split of the soft and olt
 * pipelines) on real files, against F computed here from the file's own attributes:
 *   - LAS classification as a class set, intensity, height and axis-distance on
 *     file_with_both_wkt_and_geotiff_vlrs.las (LAS 1.4, classes 2-7, intensity 996-57345);
 *   - the PLY scalar property (scalar, quality, and confidence refused naming the property)
 *     on a PLY file with a `quality` property written here and read by the PLY reader.
 * The check for each: `soft` with lambda = 0 draws exactly the solid points, so its frame must
 * equal `splat` of a cloud of the points whose F (computed here, independently of
 * soft_field.c) is <= t, in the same order, offset and camera. Tolerance as test_render_soft's
 * test_field_height: at most 1 level in at most 0.5 % of the pixels (the subset cloud's batches
 * differ, so the splat lists run in another order and float sums may round differently). Each
 * split is required to be real: between 3 % and 97 % of the points soft. On the LAS (trees over
 * ground) the same split through `olt` with lambda = 0 hides the first soft layer only and shows
 * what lies behind it, so it must differ from soft's. All sources change live on one upload. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cloud.h"
#include "prep.h"
#include "render.h"
#include "rndtest.h"
#include "testutil.h"

enum { S = 256 };

/* load_prepared: file name in tests/data (or a path) loaded and prepared. */
static void load_prepared(const char *path, pc_prepared *pc)
{
    sd_err err = {0};
    pc_cloud cl;
    if (pc_load(path, &cl, &err) < 0) fail_msg("%s", err.msg);
    prep_desc pd = {0};
    if (prep_run(&cl, &pd, pc, &err) < 0) fail_msg("%s", err.msg);
    pc_cloud_free(&cl);
}

/* solid_subset: the points of pc with soft[i] == 0, same order and offset. */
static uint32_t upload_solid(const pc_prepared *pc, const uint8_t *soft)
{
    uint64_t m = 0;
    for (uint64_t i = 0; i < pc->n; i++) m += !soft[i];
    pc_prepared s;
    tu_new_cloud(&s, m ? m : 1, 0);
    for (uint64_t i = 0, j = 0; i < pc->n; i++) {
        if (soft[i]) continue;
        memcpy(&s.pos[3 * j], &pc->pos[3 * i], 12);
        memcpy(&s.normal[3 * j], &pc->normal[3 * i], 12);
        if (pc->rgba && (pc->attrs & PC_ATTR_RGB)) memcpy(&s.rgba[4 * j], &pc->rgba[4 * i], 4);
        s.radius[j] = pc->radius[i], s.F[j] = pc->F[i];
        j++;
    }
    tu_finish_cloud(&s, pc->offset);
    uint32_t id = tu_upload(tu_ctx, &s);
    pc_prepared_free(&s);
    return id;
}

/* check_split: soft (lambda 0) of cloud id with p's field against splat of pc's points whose
 * F (f[i], computed by the caller) is <= p->t; and, for a scene with something behind the soft
 * points (layered), olt (lambda 0) shows that and so differs from it. */
static void check_split(const char *what, const pc_prepared *pc, uint32_t id, sp_params p,
                        const float *f, const rnd_camera *cam, int layered)
{
    uint8_t *soft = malloc(pc->n);
    assert_non_null(soft);
    uint64_t nsoft = 0;
    for (uint64_t i = 0; i < pc->n; i++) nsoft += soft[i] = f[i] > p.t;
    printf("%s: %llu of %llu points soft at t = %.2f\n", what, (unsigned long long)nsoft,
           (unsigned long long)pc->n, p.t);
    assert_true(nsoft * 100 >= 3 * pc->n && nsoft * 100 <= 97 * pc->n);
    uint32_t sid = upload_solid(pc, soft);
    free(soft);
    sp_params ps;
    sp_params_defaults(&ps);
    rnd_frame ref = {0}, got = {0}, olt = {0};
    tu_render(tu_ctx, sid, cam, &ps, 0, &ref);
    p.pipeline = SP_PIPE_SOFT, p.lambda = 0.0f, p.l_m = 0.0f;
    tu_render(tu_ctx, id, cam, &p, 0, &got);
    p.pipeline = SP_PIPE_OLT;
    tu_render(tu_ctx, id, cam, &p, 0, &olt);
    int worst = 0, ndiff = 0, nolt = 0;
    for (size_t i = 0; i < (size_t)S * S; i++) {
        int any = 0, anyo = 0;
        for (int c = 0; c < 3; c++) {
            int d = abs(ref.rgba8[4 * i + c] - got.rgba8[4 * i + c]);
            worst = d > worst ? d : worst;
            any |= d != 0;
            anyo |= olt.rgba8[4 * i + c] != got.rgba8[4 * i + c];
        }
        ndiff += any, nolt += anyo;
    }
    printf("%s: soft lambda 0 vs splat of the solid points: max %d levels, %d pixels differ; "
           "olt lambda 0 differs from it in %d pixels\n", what, worst, ndiff, nolt);
    assert_true(worst <= 1 && ndiff <= S * S / 200);
    if (layered) assert_true(nolt > 100);
    rnd_frame_free(&ref), rnd_frame_free(&got), rnd_frame_free(&olt);
    rnd_release(tu_ctx, sid);
}

/* The LAS sources on one upload: class (classes 3, 4, 5: low, medium and high vegetation),
 * intensity, height, axis-distance (a vertical axis). Airborne lidar with trees over ground:
 * layered, so olt differs. */
static void test_las_sources(void **state)
{
    (void)state;
    char path[4096];
    tu_data("file_with_both_wkt_and_geotiff_vlrs.las", path, sizeof path);
    pc_prepared pc;
    load_prepared(path, &pc);
    assert_true(pc.attrs & PC_ATTR_CLASS);
    assert_true(pc.attrs & PC_ATTR_INTENSITY);
    uint32_t id = tu_upload(tu_ctx, &pc);
    rnd_camera cam;
    rnd_camera_frame(pc.bmin, pc.bmax, S, S, &cam);
    float *f = malloc(pc.n * sizeof *f);
    assert_non_null(f);
    sp_params p;
    sp_params_defaults(&p);

    p.field = SP_FIELD_CLASS, p.classes = (1 << 3) | (1 << 4) | (1 << 5), p.t = 0.5f;
    for (uint64_t i = 0; i < pc.n; i++) f[i] = pc.cls[i] >= 3 && pc.cls[i] <= 5;
    check_split("class 3,4,5", &pc, id, p, f, &cam, 1);

    float lo = INFINITY, hi = -INFINITY;
    for (uint64_t i = 0; i < pc.n; i++) lo = fminf(lo, pc.intensity[i]), hi = fmaxf(hi, pc.intensity[i]);
    for (uint64_t i = 0; i < pc.n; i++) f[i] = (pc.intensity[i] - lo) / (hi - lo);
    p.field = SP_FIELD_INTENSITY, p.t = 0.1f;
    check_split("intensity", &pc, id, p, f, &cam, 1);

    double z0 = pc.bmin[2] - pc.offset[2], z1 = pc.bmax[2] - pc.offset[2];
    for (uint64_t i = 0; i < pc.n; i++) f[i] = (float)((pc.pos[3 * i + 2] - z0) / (z1 - z0));
    p.field = SP_FIELD_HEIGHT, p.t = 0.2f;
    check_split("height", &pc, id, p, f, &cam, 1);

    /* axis-distance: the vertical axis through the local point (10, -20, 0) */
    const float ax = 10.0f, ay = -20.0f;
    float dmax = 0;
    for (uint64_t i = 0; i < pc.n; i++) {
        f[i] = hypotf(pc.pos[3 * i] - ax, pc.pos[3 * i + 1] - ay);
        dmax = fmaxf(dmax, f[i]);
    }
    for (uint64_t i = 0; i < pc.n; i++) f[i] /= dmax;
    p.field = SP_FIELD_AXIS, p.t = 0.5f;
    p.axis_a[0] = ax, p.axis_a[1] = ay, p.axis_a[2] = 0.0f;
    p.axis_b[0] = ax, p.axis_b[1] = ay, p.axis_b[2] = 5.0f;
    check_split("axis-distance", &pc, id, p, f, &cam, 1);

    /* a degenerate axis and a source the file has not are refused with the reason */
    p.axis_b[2] = 0.0f, p.pipeline = SP_PIPE_SOFT;
    rnd_frame fr = {0};
    sd_err err = {0};
    assert_true(rnd_render(tu_ctx, (uint32_t)id, &cam, &p, 0, &fr, &err) < 0);
    printf("degenerate axis: %s\n", err.msg);
    assert_non_null(strstr(err.msg, "same point"));
    p.field = SP_FIELD_QUALITY;
    assert_true(rnd_render(tu_ctx, (uint32_t)id, &cam, &p, 0, &fr, &err) < 0);
    printf("quality on a LAS: %s\n", err.msg);
    assert_non_null(strstr(err.msg, "quality"));
    rnd_frame_free(&fr);
    free(f);
    rnd_release(tu_ctx, id);
    pc_prepared_free(&pc);
}

/* The PLY scalar property: a binary PLY of a wavy 120 x 120 sheet with a float `quality`
 * property (a ramp along x), written here and read by the PLY reader. field=scalar is the
 * normalised quality, field=quality 1 minus it (low quality soft), field=confidence refused
 * naming the file's property. */
static void test_ply_quality(void **state)
{
    (void)state;
    enum { N = 120 };
    char dir[4096], path[4200];
    tu_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/quality.ply", dir);
    char head[256];
    int hl = snprintf(head, sizeof head, "ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      "property float quality\nend_header\n", N * N);
    size_t len = (size_t)hl + (size_t)N * N * 16;
    uint8_t *buf = malloc(len);
    assert_non_null(buf);
    memcpy(buf, head, (size_t)hl);
    float *v = (float *)(void *)(buf + hl);
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++) {
            float x = i * 0.01f, y = j * 0.01f, q = 3.0f + 7.0f * i / (N - 1);
            float rec[4] = {x, y, 0.05f * sinf(9.0f * x) * cosf(7.0f * y), q};
            memcpy((uint8_t *)v + 16 * ((size_t)j * N + i), rec, 16);
        }
    assert_int_equal(tu_write_file(path, buf, len), 0);
    free(buf);
    pc_prepared pc;
    load_prepared(path, &pc);
    tu_rm_rf(dir);
    assert_true(pc.attrs & PC_ATTR_SCALAR);
    assert_string_equal(pc.scalar_name, "quality");
    uint32_t id = tu_upload(tu_ctx, &pc);
    rnd_camera cam;
    rnd_camera_frame(pc.bmin, pc.bmax, S, S, &cam);
    float *f = malloc(pc.n * sizeof *f);
    assert_non_null(f);
    sp_params p;
    sp_params_defaults(&p);
    /* the ramp: (q - 3) / 7 from the points' x, reordered by prep */
    double x0 = pc.bmin[0] - pc.offset[0], x1 = pc.bmax[0] - pc.offset[0];
    for (uint64_t i = 0; i < pc.n; i++) f[i] = (float)((pc.pos[3 * i] - x0) / (x1 - x0));
    p.field = SP_FIELD_SCALAR, p.t = 0.6f;
    check_split("scalar (quality)", &pc, id, p, f, &cam, 0);
    for (uint64_t i = 0; i < pc.n; i++) f[i] = 1.0f - f[i];
    p.field = SP_FIELD_QUALITY, p.t = 0.3f;
    check_split("quality (inverted)", &pc, id, p, f, &cam, 0);
    p.field = SP_FIELD_CONFIDENCE, p.pipeline = SP_PIPE_SOFT;
    rnd_frame fr = {0};
    sd_err err = {0};
    assert_true(rnd_render(tu_ctx, id, &cam, &p, 0, &fr, &err) < 0);
    printf("confidence on a quality PLY: %s\n", err.msg);
    assert_non_null(strstr(err.msg, "'confidence'"));
    assert_non_null(strstr(err.msg, "quality"));
    rnd_frame_free(&fr);
    free(f);
    rnd_release(tu_ctx, id);
    pc_prepared_free(&pc);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_las_sources),
        cmocka_unit_test(test_ply_quality),
    };
    return cmocka_run_group_tests(tests, tu_egl_group_setup, tu_egl_group_teardown);
}
