/* params.c — parameter table, defaults, text parsing and validation (see params.h). */
#include "params.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const sp_param_info sp_param_table[SP_PARAM_COUNT] = {
#define SP_INFO_(id, name, type, field, lo, hi, def, vals) {name, type, lo, hi, def, vals},
    SP_PARAM_LIST(SP_INFO_)
#undef SP_INFO_
};

int sp_param_find(const char *name)
{
    for (int i = 0; i < SP_PARAM_COUNT; i++)
        if (!strcmp(sp_param_table[i].name, name)) return i;
    return -1;
}

/* Index of value v in the '|'-separated list, or -1. */
static int enum_index(const char *list, const char *v)
{
    size_t vl = strlen(v);
    int idx = 0;
    for (const char *s = list; *s; idx++) {
        const char *e = strchr(s, '|');
        size_t l = e ? (size_t)(e - s) : strlen(s);
        if (l == vl && !strncmp(s, v, l)) return idx;
        if (!e) break;
        s = e + 1;
    }
    return -1;
}

const char *sp_enum_name(int id, int v, char *buf, size_t len)
{
    if (id < 0 || id >= SP_PARAM_COUNT || !sp_param_table[id].values || v < 0) return NULL;
    const char *s = sp_param_table[id].values;
    for (int i = 0; i < v; i++) {
        s = strchr(s, '|');
        if (!s) return NULL;
        s++;
    }
    const char *e = strchr(s, '|');
    size_t l = e ? (size_t)(e - s) : strlen(s);
    if (l + 1 > len) l = len - 1;
    memcpy(buf, s, l);
    buf[l] = 0;
    return buf;
}

static void *field_ptr(sp_params *p, int id)
{
    switch (id) {
#define SP_PTR_(id_, name, type, field, lo, hi, def, vals) case SP_##id_: return &p->field;
        SP_PARAM_LIST(SP_PTR_)
#undef SP_PTR_
    }
    return NULL;
}

static int parse_double(const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || errno || !isfinite(v)) return -1;
    *out = v;
    return 0;
}

/* set_class_list: the text form "class:3,4,5" of field: field=class and classes = the bits of
 * the listed classes (each 0-31). Returns 0, or -1 with err. */
static int set_class_list(sp_params *p, const char *list, char *err, size_t errlen)
{
    int64_t mask = 0;
    const char *s = list;
    do {
        char *end;
        errno = 0;
        long c = strtol(s, &end, 10);
        if (end == s || errno || c < 0 || c > 31 || (*end && *end != ',')) {
            snprintf(err, errlen, "parameter 'field': 'class:%s' is not a list of LAS classes "
                     "0-31 like class:3,4,5", list);
            return -1;
        }
        mask |= (int64_t)1 << c;
        s = *end ? end + 1 : end;
    } while (*s);
    p->field = SP_FIELD_CLASS;
    p->classes = mask;
    return 0;
}

int sp_param_set_text(sp_params *p, const char *name, const char *value, char *err, size_t errlen)
{
    int id = sp_param_find(name);
    if (id < 0) {
        snprintf(err, errlen, "unknown parameter '%s'", name);
        return -1;
    }
    if (id == SP_FIELD && !strncmp(value, "class:", 6)) return set_class_list(p, value + 6, err, errlen);
    const sp_param_info *in = &sp_param_table[id];
    void *f = field_ptr(p, id);
    switch (in->type) {
    case SP_T_ENUM: {
        int v = enum_index(in->values, value);
        if (v < 0) {
            snprintf(err, errlen, "parameter '%s': '%s' is not one of %s", name, value, in->values);
            return -1;
        }
        *(int32_t *)f = v;
        return 0;
    }
    case SP_T_FLOAT:
    case SP_T_INT: {
        double v;
        if (parse_double(value, &v) < 0 || (in->type == SP_T_INT && v != floor(v))) {
            snprintf(err, errlen, "parameter '%s': '%s' is not %s", name, value,
                     in->type == SP_T_INT ? "an integer" : "a number");
            return -1;
        }
        /* floats are compared as stored, so the printed value of a stored float reads back */
        int out = in->type == SP_T_FLOAT
                      ? ((float)v < (float)in->min || (float)v > (float)in->max)
                      : (v < in->min || v > in->max);
        if (out) {
            snprintf(err, errlen, "parameter '%s': %s is out of range [%g, %g]", name, value,
                     in->min, in->max);
            return -1;
        }
        if (in->type == SP_T_FLOAT) *(float *)f = (float)v;
        else *(int64_t *)f = (int64_t)v;
        return 0;
    }
    case SP_T_VEC3: {
        double v[3];
        char tmp[128];
        if (strlen(value) >= sizeof tmp) { /* longer than tmp: would be cut, not refused */
            snprintf(err, errlen, "parameter '%s': value of %zu bytes is too long", name,
                     strlen(value));
            return -1;
        }
        snprintf(tmp, sizeof tmp, "%s", value);
        char *save = NULL, *tok = strtok_r(tmp, ",", &save);
        int k = 0;
        for (; tok && k < 3; k++, tok = strtok_r(NULL, ",", &save))
            if (parse_double(tok, &v[k]) < 0) break;
        if (k != 3 || tok) {
            snprintf(err, errlen, "parameter '%s': '%s' is not three numbers x,y,z", name, value);
            return -1;
        }
        for (k = 0; k < 3; k++) {
            if (v[k] < in->min || v[k] > in->max) {
                snprintf(err, errlen, "parameter '%s': component %g is out of range [%g, %g]",
                         name, v[k], in->min, in->max);
                return -1;
            }
        }
        for (k = 0; k < 3; k++) ((float *)f)[k] = (float)v[k];
        return 0;
    }
    }
    snprintf(err, errlen, "parameter '%s': bad type", name);
    return -1;
}

int sp_param_set_kv(sp_params *p, const char *kv, char *err, size_t errlen)
{
    const char *eq = strchr(kv, '=');
    if (!eq || eq == kv) {
        snprintf(err, errlen, "'%s' is not key=value", kv);
        return -1;
    }
    char name[64];
    size_t l = (size_t)(eq - kv);
    if (l >= sizeof name) {
        snprintf(err, errlen, "parameter name in '%s' is too long", kv);
        return -1;
    }
    memcpy(name, kv, l);
    name[l] = 0;
    return sp_param_set_text(p, name, eq + 1, err, errlen);
}

void sp_param_get_text(const sp_params *p, int id, char *buf, size_t len)
{
    const void *f = field_ptr((sp_params *)p, id);
    if (!f) {
        snprintf(buf, len, "?");
        return;
    }
    switch (sp_param_table[id].type) {
    case SP_T_ENUM:
        if (!sp_enum_name(id, *(const int32_t *)f, buf, len)) snprintf(buf, len, "?");
        break;
    case SP_T_FLOAT: snprintf(buf, len, "%g", *(const float *)f); break;
    case SP_T_INT: snprintf(buf, len, "%lld", (long long)*(const int64_t *)f); break;
    case SP_T_VEC3: {
        const float *v = f;
        snprintf(buf, len, "%g,%g,%g", v[0], v[1], v[2]);
        break;
    }
    }
}

void sp_params_defaults(sp_params *p)
{
    char err[160];
    memset(p, 0, sizeof *p);
    for (int i = 0; i < SP_PARAM_COUNT; i++) {
        int rc = sp_param_set_text(p, sp_param_table[i].name, sp_param_table[i].def, err, sizeof err);
        (void)rc; /* the table's defaults are valid; tests/test_params.c checks each */
    }
}
