/* test_params.c — the parameter table: defaults, text syntax, validation messages. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "params.h"
#include "render.h"
#include "testutil.h"

static void test_defaults_valid_and_round_trip(void **state)
{
    (void)state;
    sp_params p, q;
    sp_params_defaults(&p);
    char buf[128], err[256];
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        /* every default must parse (sp_params_defaults ignores errors, so check here) */
        assert_int_equal(sp_param_set_text(&q, sp_param_table[i].name, sp_param_table[i].def,
                                           err, sizeof err), 0);
        sp_param_get_text(&p, i, buf, sizeof buf);
        sp_params r = p;
        assert_int_equal(sp_param_set_text(&r, sp_param_table[i].name, buf, err, sizeof err), 0);
        assert_memory_equal(&r, &p, sizeof p);
    }
    assert_int_equal(p.pipeline, SP_PIPE_SPLAT);
    assert_true(p.splat_scale == 1.0f);
    assert_int_equal(p.quality, 85);
    assert_int_equal(p.subsampling, SP_SUB_420);
    assert_true(p.light[2] == 1.0f && p.light[0] == 0.3f);
}

static void test_set_and_errors(void **state)
{
    (void)state;
    sp_params p;
    sp_params_defaults(&p);
    char err[256];
    assert_int_equal(sp_param_set_kv(&p, "pipeline=points", err, sizeof err), 0);
    assert_int_equal(p.pipeline, SP_PIPE_POINTS);
    assert_int_equal(sp_param_set_kv(&p, "splat_scale=2.5", err, sizeof err), 0);
    assert_true(p.splat_scale == 2.5f);
    assert_int_equal(sp_param_set_kv(&p, "background=0.1,0.2,0.3", err, sizeof err), 0);
    assert_true(p.background[1] == 0.2f);

    assert_int_equal(sp_param_set_kv(&p, "nosuch=1", err, sizeof err), -1);
    assert_non_null(strstr(err, "unknown parameter 'nosuch'"));
    assert_int_equal(sp_param_set_kv(&p, "quality=101", err, sizeof err), -1);
    assert_non_null(strstr(err, "'quality'"));
    assert_non_null(strstr(err, "[1, 100]"));
    assert_int_equal(p.quality, 85); /* unchanged on error */
    assert_int_equal(sp_param_set_kv(&p, "quality=8.5", err, sizeof err), -1);
    assert_non_null(strstr(err, "integer"));
    assert_int_equal(sp_param_set_kv(&p, "pipeline=raytrace", err, sizeof err), -1);
    assert_non_null(strstr(err, "points|splat"));
    assert_int_equal(sp_param_set_kv(&p, "lowpass=nan", err, sizeof err), -1);
    assert_int_equal(sp_param_set_kv(&p, "lowpass=", err, sizeof err), -1);
    assert_int_equal(sp_param_set_kv(&p, "light=1,2", err, sizeof err), -1);
    assert_non_null(strstr(err, "three numbers"));
    assert_int_equal(sp_param_set_kv(&p, "light=0,0,1,4", err, sizeof err), -1);
    assert_int_equal(sp_param_set_kv(&p, "background=0,0,2", err, sizeof err), -1);
    assert_non_null(strstr(err, "out of range"));
    assert_int_equal(sp_param_set_kv(&p, "=3", err, sizeof err), -1);
    assert_int_equal(sp_param_set_kv(&p, "splat_scale", err, sizeof err), -1);
    assert_non_null(strstr(err, "key=value"));
}

/* field=class:3,4,5 (the text form) sets field=class and classes = bits 3, 4, 5 = 56; a class
 * past 31, an empty list or junk are refused naming the form. */
static void test_field_class_list(void **state)
{
    (void)state;
    sp_params p;
    sp_params_defaults(&p);
    char err[256];
    assert_int_equal(sp_param_set_kv(&p, "field=class:3,4,5", err, sizeof err), 0);
    assert_int_equal(p.field, SP_FIELD_CLASS);
    assert_int_equal(p.classes, 56);
    assert_int_equal(sp_param_set_kv(&p, "field=class:0,31", err, sizeof err), 0);
    assert_int_equal(p.classes, (int64_t)1 | ((int64_t)1 << 31));
    const char *bad[4] = {"field=class:32", "field=class:", "field=class:3,,4", "field=class:x"};
    for (int i = 0; i < 4; i++) {
        sp_params q = p;
        assert_int_equal(sp_param_set_kv(&q, bad[i], err, sizeof err), -1);
        assert_non_null(strstr(err, "class:3,4,5"));
        assert_memory_equal(&q, &p, sizeof p);
    }
}

static void test_enum_names(void **state)
{
    (void)state;
    char buf[32];
    assert_string_equal(sp_enum_name(SP_FORMAT, SP_FMT_EXR, buf, sizeof buf), "exr");
    assert_string_equal(sp_enum_name(SP_COLOR, SP_COLOR_INTENSITY, buf, sizeof buf), "intensity");
    assert_null(sp_enum_name(SP_FORMAT, 99, buf, sizeof buf));
    assert_null(sp_enum_name(SP_QUALITY, 0, buf, sizeof buf));
    assert_int_equal(sp_param_find("l_m_nonexistent"), -1);
    assert_int_equal(sp_param_find("lowpass"), SP_LOWPASS);
}

/* The pipeline parameter, the C enum and the renderer's table come from one list
 * (protocol/pipelines.h): every value name is the name its implementation gives itself, in
 * the same order, and neither side has an extra entry. */
static void test_pipeline_list_matches_table(void **state)
{
    (void)state;
    char buf[64];
    int n = 0;
    for (int i = 0; sp_enum_name(SP_PIPELINE, i, buf, sizeof buf); i++, n++) {
        const char *impl = rnd_pipeline_name(i);
        assert_non_null(impl);
        assert_string_equal(buf, impl);
    }
    assert_int_equal(n, SP_PIPE_COUNT);
    assert_null(rnd_pipeline_name(SP_PIPE_COUNT));
    assert_null(rnd_pipeline_name(-1));
    assert_true(n >= 2);
    sp_params p;
    sp_params_defaults(&p);
    char err[200];
    for (int i = 0; i < n; i++) {
        assert_int_equal(sp_param_set_text(&p, "pipeline", rnd_pipeline_name(i), err, sizeof err), 0);
        assert_int_equal(p.pipeline, i);
    }
}

/* The numeric ranges are those PROTOCOL.md publishes, both ends inclusive: each end is
 * accepted and the nearest value beyond it refused (floats compared as f32, so the next f32
 * past the end; integers one past; vec3 per component, each component in turn). The values
 * come from the protocol text, not from sp_param_table. */
static void test_ranges_match_protocol_md(void **state)
{
    (void)state;
    static const struct { const char *name; double lo, hi; } ranges[] = {
        {"splat_scale", 0.01, 100}, {"lowpass", 0, 16}, {"point_size", 1, 64},
        {"point_budget", 0, 4e9},   {"quality", 1, 100}, {"light", -1, 1},
        {"background", 0, 1},
    };
    char v[128], err[256];
    for (size_t i = 0; i < sizeof ranges / sizeof ranges[0]; i++) {
        const char *name = ranges[i].name;
        int id = sp_param_find(name);
        assert_true(id >= 0);
        sp_type t = sp_param_table[id].type;
        for (int end = 0; end < 2; end++) {
            double at = end ? ranges[i].hi : ranges[i].lo;
            double past;
            if (t == SP_T_INT) past = end ? at + 1 : at - 1;
            else past = nextafterf((float)at, end ? INFINITY : -INFINITY);
            for (int comp = 0; comp < (t == SP_T_VEC3 ? 3 : 1); comp++) {
                for (int beyond = 0; beyond < 2; beyond++) {
                    double x = beyond ? past : at;
                    if (t == SP_T_VEC3) {
                        /* the other components at the range's middle */
                        double mid = 0.5 * (ranges[i].lo + ranges[i].hi), c[3] = {mid, mid, mid};
                        c[comp] = x;
                        snprintf(v, sizeof v, "%.9g,%.9g,%.9g", c[0], c[1], c[2]);
                    } else {
                        snprintf(v, sizeof v, t == SP_T_INT ? "%.0f" : "%.9g", x);
                    }
                    sp_params p;
                    sp_params_defaults(&p);
                    int rc = sp_param_set_text(&p, name, v, err, sizeof err);
                    if (rc != (beyond ? -1 : 0))
                        fail_msg("%s=%s: got %d, want %s", name, v, rc,
                                 beyond ? "refused" : "accepted");
                    if (beyond) assert_non_null(strstr(err, "out of range"));
                }
            }
        }
    }
}

/* Enum values match whole names only: an abbreviation, an extension or an empty value is not
 * a value, even when it is a prefix of one. */
static void test_enum_exact_names(void **state)
{
    (void)state;
    sp_params p;
    sp_params_defaults(&p);
    char err[256];
    static const char *bad[] = {"pipeline=poi", "pipeline=p", "pipeline=", "color=rg",
                                "format=pn", "subsampling=44", "ewa=ex", "pipeline=pointsx"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        if (sp_param_set_kv(&p, bad[i], err, sizeof err) != -1)
            fail_msg("'%s' was accepted", bad[i]);
        assert_non_null(strstr(err, "is not one of"));
    }
    assert_int_equal(p.pipeline, SP_PIPE_SPLAT); /* unchanged */
    assert_int_equal(sp_param_set_kv(&p, "subsampling=444", err, sizeof err), 0);
    assert_int_equal(p.subsampling, SP_SUB_444);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_defaults_valid_and_round_trip),
        cmocka_unit_test(test_set_and_errors),
        cmocka_unit_test(test_enum_names),
        cmocka_unit_test(test_field_class_list),
        cmocka_unit_test(test_pipeline_list_matches_table),
        cmocka_unit_test(test_ranges_match_protocol_md),
        cmocka_unit_test(test_enum_exact_names),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
