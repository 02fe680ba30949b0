/* soft_field.c — F per point for every `field` source (see soft_field.h and params.h for the
 * normalisations). */
#include "soft_field.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* read_words: words 4-byte values of GL buffer buf into a new array (NULL: no memory). */
static void *read_words(const gl_api *gl, GLuint buf, uint64_t words)
{
    void *p = malloc(words ? words * 4 : 4);
    if (!p) return NULL;
    gl->BindBuffer(GL_COPY_READ_BUFFER, buf);
    gl->GetBufferSubData(GL_COPY_READ_BUFFER, 0, (GLsizeiptr)(words * 4), p);
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    return p;
}

void soft_fields_free(const gl_api *gl, soft_fields *fs)
{
    for (uint32_t i = 0; i < fs->nsets; i++) {
        soft_fset *s = &fs->sets[i];
        free(s->pos), free(s->unc), free(s->inten), free(s->sca), free(s->cls), free(s->scan);
        free(s->f);
        if (s->f_buf) gl->DeleteBuffers(1, &s->f_buf);
    }
    free(fs->sets);
    memset(fs, 0, sizeof *fs);
}

int soft_fields_attach(const gl_api *gl, const rnd_gpu_cloud *c, soft_fields *fs, sd_err *err)
{
    memset(fs, 0, sizeof *fs);
    fs->sets = calloc(c->nsets ? c->nsets : 1, sizeof *fs->sets);
    if (!fs->sets) return sd_errf(err, SD_ENOMEM, "out of memory attaching a cloud's fields");
    fs->nsets = c->nsets;
    memcpy(fs->scalar_name, c->scalar_name, sizeof fs->scalar_name);
    fs->scalar_name[sizeof fs->scalar_name - 1] = 0;
    int has_cls = (c->attrs & PC_ATTR_CLASS) != 0, has_sca = (c->attrs & PC_ATTR_SCALAR) != 0;
    int has_scan = (c->attrs & PC_ATTR_SCAN) != 0;
    for (uint32_t si = 0; si < c->nsets; si++) {
        const rnd_bufset *b = &c->sets[si];
        soft_fset *s = &fs->sets[si];
        uint32_t n = b->n;
        s->n = n;
        s->pos = read_words(gl, b->buf[RND_ATTR_POS], (uint64_t)n * 3);
        s->unc = read_words(gl, b->buf[RND_ATTR_FIELD], n);
        s->inten = read_words(gl, b->buf[RND_ATTR_INTENSITY], n);
        s->sca = has_sca ? read_words(gl, b->buf[RND_ATTR_SCALAR], n) : calloc(n ? n : 1, 4);
        s->cls = has_cls ? read_words(gl, b->buf[RND_ATTR_CLASS], n) : NULL;
        s->scan = has_scan ? read_words(gl, b->buf[RND_ATTR_SCAN], n) : NULL;
        s->f = malloc((size_t)(n ? n : 1) * 4);
        if (!s->pos || !s->unc || !s->inten || !s->sca || (has_cls && !s->cls) ||
            (has_scan && !s->scan) || !s->f) {
            soft_fields_free(gl, fs);
            return sd_errf(err, SD_ENOMEM, "out of memory attaching a cloud's fields");
        }
    }
    return 0;
}

/* axis_distance: distance of p from the line through a with unit direction u. */
static float axis_distance(const float *p, const float *a, const float *u)
{
    float d[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    float t = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
    float e[3] = {d[0] - t * u[0], d[1] - t * u[1], d[2] - t * u[2]};
    return sqrtf(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
}

static float clamp01(float x)
{
    return x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f; /* NaN -> 0 */
}

int soft_fields_update(const gl_api *gl, const rnd_gpu_cloud *c, soft_fields *fs,
                       const sp_params *p, sd_err *err)
{
    int field = p->field;
    int axis = field == SP_FIELD_AXIS;
    if (fs->have && fs->field == field && (field != SP_FIELD_CLASS || fs->classes == p->classes) &&
        (!axis || (!memcmp(fs->axis_a, p->axis_a, sizeof fs->axis_a) &&
                   !memcmp(fs->axis_b, p->axis_b, sizeof fs->axis_b))))
        return 0;
    if (field == SP_FIELD_QUALITY || field == SP_FIELD_CONFIDENCE) {
        const char *want = field == SP_FIELD_QUALITY ? "quality" : "confidence";
        if (strcmp(fs->scalar_name, want))
            return sd_errf(err, SD_EINVAL, "field=%s: the cloud has no property '%s' (its scalar "
                           "property: %s)", want, want,
                           fs->scalar_name[0] ? fs->scalar_name : "none");
    }
    if (field == SP_FIELD_SCALAR && !fs->scalar_name[0])
        return sd_errf(err, SD_EINVAL, "field=scalar: the cloud has no scalar property");
    if (field == SP_FIELD_CLASS && (c->attrs & PC_ATTR_CLASS) == 0)
        return sd_errf(err, SD_EINVAL, "field=class: the cloud has no classification");
    if (field == SP_FIELD_SCAN && (c->attrs & PC_ATTR_SCAN) == 0)
        return sd_errf(err, SD_EINVAL, "field=scan: the cloud has no scan indices (they come "
                       "from E57 files of more than one scan)");
    float u[3] = {p->axis_b[0] - p->axis_a[0], p->axis_b[1] - p->axis_a[1],
                  p->axis_b[2] - p->axis_a[2]};
    float ul = sqrtf(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    if (axis && !(ul > 0.0f))
        return sd_errf(err, SD_EINVAL, "field=axis-distance: axis_a and axis_b are the same "
                       "point (%g,%g,%g)", p->axis_a[0], p->axis_a[1], p->axis_a[2]);
    for (int i = 0; i < 3 && axis; i++) u[i] /= ul;
    float z0 = c->bmin[2], dz = c->bmax[2] - c->bmin[2];
    float zinv = dz > 0.0f ? 1.0f / dz : 0.0f;
    float dmax = 0.0f;
    for (uint32_t si = 0; si < fs->nsets; si++) {
        soft_fset *s = &fs->sets[si];
        for (uint32_t i = 0; i < s->n; i++) {
            float f;
            switch (field) {
            case SP_FIELD_HEIGHT: f = clamp01((s->pos[3 * (size_t)i + 2] - z0) * zinv); break;
            case SP_FIELD_INTENSITY: f = s->inten[i]; break;
            case SP_FIELD_SCALAR: f = s->sca[i]; break;
            case SP_FIELD_QUALITY:
            case SP_FIELD_CONFIDENCE: f = 1.0f - s->sca[i]; break;
            case SP_FIELD_CLASS:
                f = s->cls[i] < 32 && ((uint64_t)p->classes >> s->cls[i] & 1u) ? 1.0f : 0.0f;
                break;
            case SP_FIELD_SCAN: f = s->scan[i]; break;
            case SP_FIELD_AXIS:
                f = axis_distance(&s->pos[3 * (size_t)i], p->axis_a, u);
                dmax = fmaxf(dmax, f);
                break;
            default: f = s->unc[i]; break;
            }
            s->f[i] = f;
        }
    }
    for (uint32_t si = 0; si < fs->nsets; si++) {
        soft_fset *s = &fs->sets[si];
        if (axis)
            for (uint32_t i = 0; i < s->n; i++) s->f[i] = dmax > 0.0f ? s->f[i] / dmax : 0.0f;
        if (!s->f_buf) gl->GenBuffers(1, &s->f_buf);
        gl->BindBuffer(GL_TEXTURE_BUFFER, s->f_buf);
        gl->BufferData(GL_TEXTURE_BUFFER, (GLsizeiptr)((s->n ? s->n : 1) * 4ull), s->f,
                       GL_STATIC_DRAW);
    }
    gl->BindBuffer(GL_TEXTURE_BUFFER, 0);
    fs->have = 1, fs->field = field, fs->classes = p->classes;
    memcpy(fs->axis_a, p->axis_a, sizeof fs->axis_a);
    memcpy(fs->axis_b, p->axis_b, sizeof fs->axis_b);
    return 1;
}
