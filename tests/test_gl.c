/* test_gl.c — both GL back ends open a core context, load the whole gl_api table, report a
 * renderer, and every embedded shader compiles on llvmpipe (whoever wrote it). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gl_api.h"
#include "gl_backend.h"
#include "gl_names.h"
#include "shaders.h"
#include "testutil.h"
#include "shaders_gen.h"

/* Opens a back end and loads the GL table; fails the test with the message otherwise. */
static gl_backend *open_backend(const gl_backend_ops *ops, gl_api *gl)
{
    sd_err err = {0};
    gl_backend *b = NULL;
    int rc = ops->create(&b, &err);
    if (rc < 0) fail_msg("%s: %s", ops->name, err.msg);
    rc = gl_api_load(gl, ops->getproc, b, &err);
    if (rc < 0) fail_msg("%s: %s", ops->name, err.msg);
    return b;
}

/* Context, renderer string, version >= 4.3, a compute work group, and the whole table. */
static void check_backend(const gl_backend_ops *ops)
{
    gl_api gl;
    gl_backend *b = open_backend(ops, &gl);
    const char *ren = (const char *)gl.GetString(GL_RENDERER);
    assert_non_null(ren);
    assert_true(strlen(ren) > 0);
    GLint major = 0, minor = 0;
    gl.GetIntegerv(GL_MAJOR_VERSION, &major);
    gl.GetIntegerv(GL_MINOR_VERSION, &minor);
    assert_true(major * 10 + minor >= 43);
    GLint mask = 0;
    gl.GetIntegerv(GL_CONTEXT_PROFILE_MASK, &mask);
    assert_true(mask & GL_CONTEXT_CORE_PROFILE_BIT);
    sd_err err = {0};
    assert_int_equal(gl_check(&gl, "context creation", &err), 0);
    /* An invalid enum is reported by name: the check itself must be able to fail. */
    gl.Enable(0xFFFF);
    assert_int_equal(gl_check(&gl, "a bad glEnable", &err), SD_EGL);
    assert_non_null(strstr(err.msg, "GL_INVALID_ENUM"));
    assert_int_equal(gl_check(&gl, "after the check", &err), 0);
    print_message("%s: %s | %s\n", ops->name, ops->describe(b), ren);
    ops->destroy(b);
}

static void test_egl(void **state)
{
    (void)state;
    check_backend(&gl_backend_egl);
}

static void test_osmesa(void **state)
{
    (void)state;
    check_backend(&gl_backend_osmesa);
}

/* EGL, then OSMesa, then EGL again in one process (the tests and auto fallback need this). */
static void test_backends_in_sequence(void **state)
{
    (void)state;
    check_backend(&gl_backend_egl);
    check_backend(&gl_backend_osmesa);
    check_backend(&gl_backend_egl);
}

static void test_error_names(void **state)
{
    (void)state;
    char buf[32];
    assert_string_equal(egl_error_name(0x3009, buf, sizeof buf), "EGL_BAD_MATCH");
    assert_string_equal(egl_error_name(0x3001, buf, sizeof buf), "EGL_NOT_INITIALIZED");
    assert_string_equal(gl_error_name(0x0502, buf, sizeof buf), "GL_INVALID_OPERATION");
    assert_string_equal(gl_error_name(0x8CD6, buf, sizeof buf),
                        "GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT");
    assert_string_equal(gl_error_name(0x1234, buf, sizeof buf), "GL error 0x1234");
}

static void test_shader_stage_names(void **state)
{
    (void)state;
    GLenum s = 0;
    assert_int_equal(rnd_shader_stage("points.vert.glsl", NULL, &s, NULL), 0);
    assert_int_equal(s, GL_VERTEX_SHADER);
    assert_int_equal(rnd_shader_stage("points.frag", NULL, &s, NULL), 0);
    assert_int_equal(s, GL_FRAGMENT_SHADER);
    assert_int_equal(rnd_shader_stage("x_resolve.comp.glsl", NULL, &s, NULL), 0);
    assert_int_equal(s, GL_COMPUTE_SHADER);
    assert_int_equal(rnd_shader_stage("splat_vis_vs.glsl", NULL, &s, NULL), 0);
    assert_int_equal(s, GL_VERTEX_SHADER);
    assert_int_equal(rnd_shader_stage("blur.glsl", "layout(local_size_x = 8) in;", &s, NULL), 0);
    assert_int_equal(s, GL_COMPUTE_SHADER);
    sd_err err = {0};
    assert_int_equal(rnd_shader_stage("mystery.glsl", "void main(){}", &s, &err), SD_EINVAL);
    assert_non_null(strstr(err.msg, "mystery.glsl"));
}

/* #include "NAME" lines are replaced by that shader's text (from --shader-dir first), nested;
 * a missing or malformed include is an error naming the including file and its line. */
static void test_shader_include(void **state)
{
    (void)state;
    char dir[512], path[600];
    assert_non_null(tu_tmpdir(dir, sizeof dir));
    snprintf(path, sizeof path, "%s/lib_a.glsl", dir);
    assert_int_equal(tu_write_file(path, "int a;\n#include \"lib_b.glsl\"\n", 30), 0);
    snprintf(path, sizeof path, "%s/lib_b.glsl", dir);
    assert_int_equal(tu_write_file(path, "int b;\n", 7), 0);
    snprintf(path, sizeof path, "%s/x.frag.glsl", dir);
    const char *x = "#version 430\n#include \"lib_a.glsl\"\nint c;\n";
    assert_int_equal(tu_write_file(path, x, strlen(x)), 0);
    snprintf(path, sizeof path, "%s/bad.frag.glsl", dir);
    const char *bad = "#version 430\n\n#include \"lib_nope.glsl\"\n";
    assert_int_equal(tu_write_file(path, bad, strlen(bad)), 0);
    snprintf(path, sizeof path, "%s/worse.frag.glsl", dir);
    assert_int_equal(tu_write_file(path, "#include lib_a\n", 15), 0);

    sd_err err = {0};
    rnd_shaders *sh = rnd_shaders_create(dir, &err);
    assert_non_null(sh);
    const char *text;
    char *owned, origin[512];
    assert_int_equal(rnd_shaders_source(sh, "x.frag.glsl", &text, &owned, origin, sizeof origin, &err), 0);
    const char *want = "#version 430\nint a;\nint b;\n\n#line 3\n\n#line 3\nint c;\n";
    assert_string_equal(text, want);
    free(owned);
    assert_int_equal(rnd_shaders_source(sh, "bad.frag.glsl", &text, &owned, origin, sizeof origin, &err),
                     SD_ENOTFOUND);
    assert_non_null(strstr(err.msg, "bad.frag.glsl:3"));
    assert_non_null(strstr(err.msg, "lib_nope"));
    assert_int_equal(rnd_shaders_source(sh, "worse.frag.glsl", &text, &owned, origin, sizeof origin, &err),
                     SD_EINVAL);
    assert_non_null(strstr(err.msg, "worse.frag.glsl:1: malformed #include"));
    /* the embedded colour map is included by the embedded shaders */
    assert_int_equal(rnd_shaders_source(sh, "points.vert.glsl", &text, &owned, origin, sizeof origin, &err), 0);
    assert_non_null(strstr(text, "vec3 colormap(float t)"));
    assert_null(strstr(text, "#include \""));
    free(owned);
    rnd_shaders_destroy(sh);
    tu_rm_rf(dir);
}

/* Every shader compiled into the binary compiles on llvmpipe; a broken one is named. */
static void test_embedded_shaders_compile(void **state)
{
    (void)state;
    gl_api gl;
    gl_backend *b = open_backend(&gl_backend_egl, &gl);
    sd_err err = {0};
    int failures = 0;
    rnd_shaders *lib = rnd_shaders_create(NULL, &err);
    assert_non_null(lib);
    for (const shader_src *s = shaders_embedded; s->name; s++) {
        GLenum stage;
        if (!strncmp(s->name, "lib_", 4)) continue; /* included by the others, not compiled alone */
        const char *text;
        char *owned, origin[512];
        if (rnd_shaders_source(lib, s->name, &text, &owned, origin, sizeof origin, &err) < 0 ||
            rnd_shader_stage(s->name, text, &stage, &err) < 0) {
            print_error("%s\n", err.msg);
            failures++;
            continue;
        }
        GLuint sh = gl_shader_compile(&gl, stage, text, s->name, &err);
        free(owned);
        if (!sh) {
            print_error("%s\n", err.msg);
            failures++;
            continue;
        }
        gl.DeleteShader(sh);
    }
    assert_int_equal(failures, 0);
    /* The compiler check can fail: a broken source is reported with its name and the log. */
    const char *broken = "#version 430\nvoid main() { x; }\n";
    assert_int_equal(gl_shader_compile(&gl, GL_FRAGMENT_SHADER, broken, "broken.frag", &err), 0);
    assert_non_null(strstr(err.msg, "broken.frag"));
    assert_int_equal(gl_check(&gl, "shader compilation", &err), 0);
    print_message("%d embedded shaders compiled\n", shaders_embedded_count);
    rnd_shaders_destroy(lib);
    gl_backend_egl.destroy(b);
}

/* A --shader-dir file replaces the embedded one, and a missing name is an error naming it. */
static void test_shader_dir_override(void **state)
{
    (void)state;
    char dir[] = "/tmp/splatd_shdir_XXXXXX";
    assert_non_null(mkdtemp(dir));
    char path[256];
    snprintf(path, sizeof path, "%s/only_here.comp.glsl", dir);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fputs("#version 430\nlayout(local_size_x = 1) in;\nvoid main() {}\n", f);
    fclose(f);
    sd_err err = {0};
    rnd_shaders *sh = rnd_shaders_create(dir, &err);
    assert_non_null(sh);
    const char *text;
    char *owned;
    char origin[512];
    assert_int_equal(rnd_shaders_source(sh, "only_here.comp", &text, &owned, origin,
                                        sizeof origin, &err), 0);
    assert_non_null(strstr(text, "local_size_x"));
    assert_string_equal(origin, path);
    free(owned);
    assert_int_equal(rnd_shaders_source(sh, "nope.vert", &text, &owned, origin, sizeof origin,
                                        &err), SD_ENOTFOUND);
    assert_non_null(strstr(err.msg, "nope.vert"));

    gl_api gl;
    gl_backend *b = open_backend(&gl_backend_osmesa, &gl);
    GLuint prog = gl_program_from(&gl, sh, &err, "only_here.comp", NULL);
    assert_true(prog != 0);
    gl.DeleteProgram(prog);
    gl_backend_osmesa.destroy(b);
    rnd_shaders_destroy(sh);
    remove(path);
    rmdir(dir);
}

int main(int argc, char **argv)
{
    tu_args(argc, argv);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_error_names),
        cmocka_unit_test(test_shader_stage_names),
        cmocka_unit_test(test_egl),
        cmocka_unit_test(test_osmesa),
        cmocka_unit_test(test_backends_in_sequence),
        cmocka_unit_test(test_shader_include),
        cmocka_unit_test(test_embedded_shaders_compile),
        cmocka_unit_test(test_shader_dir_override),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
