/* shaders.h — GLSL sources by name (embedded in the binary, or overridden from --shader-dir),
 * and compiling them into GL shaders and programs.
 *
 * Naming: shaders/NAME.STAGE.glsl with STAGE one of vert, frag, geom, comp (the Makefile embeds
 * every shaders/NAME.glsl by base name). Code refers to them as "NAME.STAGE" or "NAME.STAGE.glsl".
 * A name without a STAGE extension is accepted when it ends in _vert/_vs, _frag/_fs,
 * _geom/_gs or _comp/_cs, or when its text declares a compute work group (local_size_x).
 * Sources are complete GLSL files with their own #version line; `#include "lib_x.glsl"` lines
 * are expanded (rnd_shaders_source), and "lib_bindings.glsl" is generated from bindings.h. */
#pragma once
#include <stddef.h>

#include "gl_api.h"
#include "pipe.h"
#include "sd_err.h"

/* rnd_shaders_create: a source lookup; dir (NULL or "": none) is searched before the embedded
 * table, so one file can be replaced during development. Returns NULL with err filled. */
rnd_shaders *rnd_shaders_create(const char *dir, sd_err *err);
void rnd_shaders_destroy(rnd_shaders *sh);

/* rnd_shaders_source: the text of shader `name`, with its `#include "lib_x.glsl"` lines replaced
 * by those files (library code shared between shaders, which GLSL itself cannot include). Sets *text (valid until *owned is freed, or
 * for the life of the process when *owned is NULL) and writes where it came from ("embedded
 * points.vert.glsl" or the file path) to origin. Returns 0, SD_ENOTFOUND or SD_EIO. */
int rnd_shaders_source(const rnd_shaders *sh, const char *name, const char **text, char **owned,
                       char *origin, size_t origin_len, sd_err *err);

/* rnd_shader_stage: the GL stage (GL_VERTEX_SHADER, ...) of a shader from its name (and, for
 * the compute fallback, its text, which may be NULL). Returns 0 or SD_EINVAL. */
int rnd_shader_stage(const char *name, const char *text, GLenum *stage, sd_err *err);

/* gl_shader_compile: compiles one shader. Returns the shader object, or 0 with err holding
 * `origin` and the GL info log. */
GLuint gl_shader_compile(const gl_api *gl, GLenum stage, const char *text, const char *origin,
                         sd_err *err);

/* gl_program_from_list: gl_program_from with an array of n names. */
GLuint gl_program_from_list(const gl_api *gl, const rnd_shaders *sh, const char *const *names,
                            int n, sd_err *err);

/* gl_program_build: the program of the n shader files names, each compiled with `defines`
 * (lines such as "#define PASS 1\n", may be NULL) inserted after its #version line; one
 * source, several variants. Returns the program, or 0 with err naming the file, the variant
 * and the GL log. */
GLuint gl_program_build(const gl_api *gl, const rnd_shaders *sh, const char *const *names, int n,
                        const char *defines, sd_err *err);

/* gl_uniform: glGetUniformLocation; -1 when the uniform is absent or optimised out. */
GLint gl_uniform(const gl_api *gl, GLuint prog, const char *name);
