/* shaders.c — shader sources by name and program building (see shaders.h and pipe.h). */
#include "shaders.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bindings.h"
#include "shaders_gen.h"

enum { SHADER_MAX_BYTES = 1 << 20, PROGRAM_MAX_STAGES = 8 };

#define BINDINGS_NAME "lib_bindings.glsl"

struct rnd_shaders {
    char *dir;          /* NULL: embedded only */
    char bindings[2048]; /* the generated lib_bindings.glsl */
};

int rnd_bindings_glsl(char *buf, size_t len)
{
    size_t n = 0;
    int w = snprintf(buf, len, "// lib_bindings.glsl: generated from server/bindings.h\n");
    if (w < 0 || (size_t)w >= len) return -1;
    n = (size_t)w;
#define BIND_LINE_(prefix, name, value)                                                       \
    w = snprintf(buf + n, len - n, "#define " prefix "%s %d\n", #name, (int)(value));         \
    if (w < 0 || (size_t)w >= len - n) return -1;                                            \
    n += (size_t)w;
#define BIND_B_(name) BIND_LINE_("B_", name, RND_B_##name)
#define BIND_T_(name) BIND_LINE_("T_", name, RND_T_##name)
    RND_STORAGE_BLOCKS(BIND_B_)
    RND_TEXTURE_UNITS(BIND_T_)
#undef BIND_B_
#undef BIND_T_
#undef BIND_LINE_
    return (int)n;
}

rnd_shaders *rnd_shaders_create(const char *dir, sd_err *err)
{
    rnd_shaders *sh = calloc(1, sizeof *sh);
    if (!sh) {
        sd_errf(err, SD_ENOMEM, "out of memory for the shader table");
        return NULL;
    }
    if (rnd_bindings_glsl(sh->bindings, sizeof sh->bindings) < 0) {
        free(sh);
        sd_errf(err, SD_ELIMIT, "the binding table outgrew its text buffer");
        return NULL;
    }
    if (dir && *dir) {
        sh->dir = strdup(dir);
        if (!sh->dir) {
            free(sh);
            sd_errf(err, SD_ENOMEM, "out of memory for the shader table");
            return NULL;
        }
    }
    return sh;
}

void rnd_shaders_destroy(rnd_shaders *sh)
{
    if (!sh) return;
    free(sh->dir);
    free(sh);
}

/* Reads path into a NUL-terminated malloc'd buffer. Returns 0, SD_ENOTFOUND (no such file),
 * SD_ELIMIT or SD_EIO. */
static int read_text(const char *path, char **out, sd_err *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        if (errno == ENOENT) return SD_ENOTFOUND;
        return sd_errf(err, SD_EIO, "%s: cannot open shader: %s", path, strerror(errno));
    }
    char *buf = malloc(SHADER_MAX_BYTES + 1);
    if (!buf) {
        fclose(f);
        return sd_errf(err, SD_ENOMEM, "%s: out of memory reading a shader", path);
    }
    size_t n = fread(buf, 1, SHADER_MAX_BYTES + 1, f);
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        free(buf);
        return sd_errf(err, SD_EIO, "%s: read error", path);
    }
    if (n > SHADER_MAX_BYTES) {
        free(buf);
        return sd_errf(err, SD_ELIMIT, "%s: shader larger than %d bytes", path, SHADER_MAX_BYTES);
    }
    buf[n] = 0;
    *out = buf;
    return 0;
}

static int ends_with(const char *s, const char *suffix)
{
    size_t a = strlen(s), b = strlen(suffix);
    return a >= b && !strcmp(s + a - b, suffix);
}

/* The text of one shader file, before #include expansion (see rnd_shaders_source). */
static int lookup(const rnd_shaders *sh, const char *name, const char **text, char **owned,
                  char *origin, size_t origin_len, sd_err *err)
{
    *text = NULL;
    *owned = NULL;
    if (!name || !*name || strchr(name, '/'))
        return sd_errf(err, SD_EINVAL, "bad shader name '%s'", name ? name : "(null)");
    if (sh && !strcmp(name, BINDINGS_NAME)) {
        *text = sh->bindings;
        snprintf(origin, origin_len, "%s (generated from server/bindings.h)", BINDINGS_NAME);
        return 0;
    }
    const char *sfx[2] = {"", ends_with(name, ".glsl") ? NULL : ".glsl"};
    if (sh && sh->dir) {
        for (int i = 0; i < 2 && sfx[i]; i++) {
            char path[4096];
            snprintf(path, sizeof path, "%s/%s%s", sh->dir, name, sfx[i]);
            char *buf = NULL;
            int rc = read_text(path, &buf, err);
            if (rc == SD_ENOTFOUND) continue;
            if (rc < 0) return rc;
            *text = *owned = buf;
            snprintf(origin, origin_len, "%s", path);
            return 0;
        }
    }
    for (int i = 0; i < 2 && sfx[i]; i++) {
        char full[256];
        snprintf(full, sizeof full, "%s%s", name, sfx[i]);
        for (const shader_src *s = shaders_embedded; s->name; s++) {
            if (strcmp(s->name, full)) continue;
            *text = s->text;
            snprintf(origin, origin_len, "shaders/%s (embedded)", s->name);
            return 0;
        }
    }
    return sd_errf(err, SD_ENOTFOUND, "shader '%s' not found (looked for %s.glsl%s%s)", name,
                   name, sh && sh->dir ? " in --shader-dir " : " in the embedded table",
                   sh && sh->dir ? sh->dir : "");
}

/* Appends len bytes of s to the growing buffer *b (used *n, capacity *cap). */
static int append(char **b, size_t *n, size_t *cap, const char *s, size_t len)
{
    if (*n + len + 1 > *cap) {
        size_t c = (*n + len + 1) * 2;
        char *q = realloc(*b, c);
        if (!q) return -1;
        *b = q;
        *cap = c;
    }
    memcpy(*b + *n, s, len);
    *n += len;
    (*b)[*n] = 0;
    return 0;
}

/* Expands the lines `#include "NAME"` of text into *out (malloc'd), recursively up to depth 4.
 * GLSL has no include; this is how shaders share library code (shaders/lib_*.glsl). The
 * #line directives keep the compiler's line numbers pointing into the including file. */
static int expand(const rnd_shaders *sh, const char *text, const char *origin, int depth,
                  char **out, size_t *n, size_t *cap, sd_err *err)
{
    if (depth > 4) return sd_errf(err, SD_ELIMIT, "%s: #include nested too deeply", origin);
    int line = 1;
    for (const char *p = text; *p;) {
        const char *e = strchr(p, '\n');
        size_t len = e ? (size_t)(e - p) + 1 : strlen(p);
        const char *q = p;
        while (*q == ' ' || *q == '\t') q++;
        if (!strncmp(q, "#include", 8)) {
            const char *a = strchr(q, '"');
            const char *b = a ? strchr(a + 1, '"') : NULL;
            if (!a || !b || b > p + len || b - a - 1 <= 0 || b - a - 1 >= 128)
                return sd_errf(err, SD_EINVAL, "%s:%d: malformed #include (want #include \"NAME\")",
                               origin, line);
            char name[128], inc_origin[512];
            memcpy(name, a + 1, (size_t)(b - a - 1));
            name[b - a - 1] = 0;
            const char *itext;
            char *iowned;
            if (lookup(sh, name, &itext, &iowned, inc_origin, sizeof inc_origin, err) < 0) {
                char why[sizeof err->msg];
                snprintf(why, sizeof why, "%s", err->msg);
                return sd_errf(err, err->code, "%s:%d: %s", origin, line, why);
            }
            char ln[32];
            int rc = expand(sh, itext, inc_origin, depth + 1, out, n, cap, err);
            free(iowned);
            if (rc < 0) return rc;
            snprintf(ln, sizeof ln, "\n#line %d\n", line + 1);
            if (append(out, n, cap, ln, strlen(ln)) < 0) goto oom;
        } else if (append(out, n, cap, p, len) < 0) {
            goto oom;
        }
        p += len;
        line++;
    }
    return 0;
oom:
    return sd_errf(err, SD_ENOMEM, "%s: out of memory expanding #include", origin);
}

int rnd_shaders_source(const rnd_shaders *sh, const char *name, const char **text, char **owned,
                       char *origin, size_t origin_len, sd_err *err)
{
    int rc = lookup(sh, name, text, owned, origin, origin_len, err);
    if (rc < 0 || !strstr(*text, "#include")) return rc;
    char *buf = NULL;
    size_t n = 0, cap = 0;
    rc = expand(sh, *text, origin, 0, &buf, &n, &cap, err);
    free(*owned);
    *owned = NULL;
    *text = NULL;
    if (rc < 0) {
        free(buf);
        return rc;
    }
    *text = *owned = buf;
    return 0;
}

int rnd_shader_stage(const char *name, const char *text, GLenum *stage, sd_err *err)
{
    static const struct {
        const char *ext;
        GLenum stage;
    } tab[] = {
        {".vert", GL_VERTEX_SHADER},   {".frag", GL_FRAGMENT_SHADER},
        {".geom", GL_GEOMETRY_SHADER}, {".comp", GL_COMPUTE_SHADER},
        {"_vert", GL_VERTEX_SHADER},   {"_frag", GL_FRAGMENT_SHADER},
        {"_geom", GL_GEOMETRY_SHADER}, {"_comp", GL_COMPUTE_SHADER},
        {"_vs", GL_VERTEX_SHADER},     {"_fs", GL_FRAGMENT_SHADER},
        {"_gs", GL_GEOMETRY_SHADER},   {"_cs", GL_COMPUTE_SHADER},
    };
    char base[256];
    snprintf(base, sizeof base, "%s", name);
    size_t l = strlen(base);
    if (l >= 5 && !strcmp(base + l - 5, ".glsl")) base[l - 5] = 0;
    for (size_t i = 0; i < sizeof tab / sizeof tab[0]; i++) {
        if (ends_with(base, tab[i].ext)) {
            *stage = tab[i].stage;
            return 0;
        }
    }
    if (text && strstr(text, "local_size_x")) {
        *stage = GL_COMPUTE_SHADER;
        return 0;
    }
    return sd_errf(err, SD_EINVAL,
                   "cannot tell the stage of shader '%s': name it NAME.vert.glsl, NAME.frag.glsl, "
                   "NAME.geom.glsl or NAME.comp.glsl", name);
}

GLuint gl_shader_compile(const gl_api *gl, GLenum stage, const char *text, const char *origin,
                         sd_err *err)
{
    GLuint s = gl->CreateShader(stage);
    if (!s) {
        sd_errf(err, SD_EGL, "%s: glCreateShader failed", origin);
        return 0;
    }
    gl->ShaderSource(s, 1, &text, NULL);
    gl->CompileShader(s);
    GLint ok = 0;
    gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[400] = "";
        gl->GetShaderInfoLog(s, sizeof log, NULL, log);
        size_t l = strlen(log);
        while (l && (log[l - 1] == '\n' || log[l - 1] == ' ')) log[--l] = 0;
        sd_errf(err, SD_EGL, "%s: shader compilation failed: %s", origin, log);
        gl->DeleteShader(s);
        return 0;
    }
    return s;
}

/* with_defines: text with `defines` inserted after its #version line (malloc'd), or NULL. */
static char *with_defines(const char *text, const char *defines)
{
    const char *nl = strchr(text, '\n');
    size_t head = nl ? (size_t)(nl - text) + 1 : strlen(text);
    size_t dl = strlen(defines), tl = strlen(text);
    char *full = malloc(tl + dl + 2);
    if (!full) return NULL;
    memcpy(full, text, head);
    size_t o = head;
    if (!nl) full[o++] = '\n';
    memcpy(full + o, defines, dl);
    o += dl;
    memcpy(full + o, text + head, tl - head + 1);
    return full;
}

GLuint gl_program_from_list(const gl_api *gl, const rnd_shaders *sh, const char *const *names,
                            int n, sd_err *err)
{
    return gl_program_build(gl, sh, names, n, NULL, err);
}

GLuint gl_program_build(const gl_api *gl, const rnd_shaders *sh, const char *const *names, int n,
                        const char *defines, sd_err *err)
{
    GLuint shaders[PROGRAM_MAX_STAGES] = {0};
    char origins[256] = "";
    GLuint prog = 0;
    int ns = 0;
    if (n <= 0 || n > PROGRAM_MAX_STAGES) {
        sd_errf(err, SD_EINVAL, "a program needs 1 to %d shaders, not %d", PROGRAM_MAX_STAGES, n);
        return 0;
    }
    for (; ns < n; ns++) {
        const char *text;
        char *owned;
        char origin[512];
        GLenum stage;
        if (rnd_shaders_source(sh, names[ns], &text, &owned, origin, sizeof origin, err) < 0)
            goto fail;
        if (rnd_shader_stage(names[ns], text, &stage, err) < 0) {
            free(owned);
            goto fail;
        }
        char *full = NULL;
        if (defines && *defines) {
            full = with_defines(text, defines);
            if (!full) {
                free(owned);
                sd_errf(err, SD_ENOMEM, "out of memory building shader %s", names[ns]);
                goto fail;
            }
            /* the error names the variant: "splat_raster.comp [#define PASS 1 ...]" */
            size_t ol = strlen(origin);
            snprintf(origin + ol, sizeof origin - ol, " [%s]", defines);
            for (char *q = origin + ol; *q; q++)
                if (*q == '\n') *q = ' ';
        }
        shaders[ns] = gl_shader_compile(gl, stage, full ? full : text, origin, err);
        free(full);
        free(owned);
        if (!shaders[ns]) goto fail;
        size_t ol = strlen(origins);
        snprintf(origins + ol, sizeof origins - ol, "%s%s", ol ? " + " : "", names[ns]);
    }
    prog = gl->CreateProgram();
    for (int i = 0; i < ns; i++) gl->AttachShader(prog, shaders[i]);
    gl->LinkProgram(prog);
    GLint ok = 0;
    gl->GetProgramiv(prog, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[400] = "";
        gl->GetProgramInfoLog(prog, sizeof log, NULL, log);
        sd_errf(err, SD_EGL, "program %s: link failed: %s", origins, log);
        gl->DeleteProgram(prog);
        prog = 0;
        goto fail;
    }
    for (int i = 0; i < ns; i++) {
        gl->DetachShader(prog, shaders[i]);
        gl->DeleteShader(shaders[i]);
    }
    if (gl_check(gl, "building a shader program", err) < 0) {
        gl->DeleteProgram(prog);
        return 0;
    }
    return prog;
fail:
    for (int i = 0; i < ns; i++)
        if (shaders[i]) gl->DeleteShader(shaders[i]);
    return 0;
}

GLuint gl_program_from(const gl_api *gl, const rnd_shaders *sh, sd_err *err, ...)
{
    const char *names[PROGRAM_MAX_STAGES + 1];
    int n = 0;
    va_list ap;
    va_start(ap, err);
    const char *s;
    while ((s = va_arg(ap, const char *)) != NULL) {
        if (n > PROGRAM_MAX_STAGES) break;
        names[n++] = s;
    }
    va_end(ap);
    return gl_program_from_list(gl, sh, names, n, err);
}

GLint gl_uniform(const gl_api *gl, GLuint prog, const char *name)
{
    return gl->GetUniformLocation(prog, name);
}
