/* splat_client.c — libsplatclient's requests: list, open, camera, parameters, frames,
 * streaming, ping (see splat_client.h; the connection layer is spc_conn.c). */
#include "spc_internal.h"
#include "attrs.h"
#include "framing.h"

/* The public header repeats the protocol's attribute bits (it is installed alone). */
#define SPC_ATTR_SAME_(id, bit, name) \
    _Static_assert((int)SPC_ATTR_##id == (int)SP_ATTR_##id, "SPC_ATTR_" #id " differs from protocol/attrs.h");
SP_ATTR_LIST(SPC_ATTR_SAME_)
#undef SPC_ATTR_SAME_

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* usable: fails with CLOSED when the connection is gone. */
static int usable(spc_client *c)
{
    if (!c) return SPC_E_INVALID_ARG;
    if (c->fd < 0) return spc__fail(c, SPC_E_CLOSED, "the connection is closed");
    return 0;
}

/* send_and_wait: flushes c->out (one request with sequence seq) and waits for its answer. */
static int send_and_wait(spc_client *c, uint32_t seq, unsigned type, proto_msg *m,
                         spc_progress_fn progress, void *user)
{
    int rc = spc__flush(c, spc__deadline(c));
    if (rc < 0) return rc;
    return spc__wait(c, seq, type, m, progress, user);
}

/* enc_failed: the failure of an encoder (only an over-long string or out of memory). */
static int enc_failed(spc_client *c, int rc, const char *what)
{
    c->out.len = 0;
    return spc__fail(c, rc == -PROTO_E_NOMEM ? SPC_E_NOMEM : SPC_E_INVALID_ARG,
                     "cannot encode %s: %s", what, proto_err_text(rc));
}

int spc_list(spc_client *c, spc_cloud **list)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    *list = NULL;
    uint32_t seq = spc__next_seq(c);
    if ((rc = proto_enc_empty(&c->out, PROTO_MSG_LIST, seq)) < 0) return enc_failed(c, rc, "LIST");
    proto_msg m;
    if ((rc = send_and_wait(c, seq, PROTO_MSG_CLOUDS, &m, NULL, NULL)) < 0) return rc;
    proto_clouds cl;
    proto_error e = {0};
    if (proto_parse_clouds(m.payload, m.len, &cl, &e) < 0)
        return spc__fail(c, -e.code, "bad CLOUDS from the server: %s", e.msg);
    spc_cloud *out = calloc(cl.count ? cl.count : 1, sizeof *out);
    if (!out) {
        proto_clouds_free(&cl);
        return spc__fail(c, SPC_E_NOMEM, "out of memory for %u cloud names", cl.count);
    }
    for (uint32_t i = 0; i < cl.count; i++) {
        snprintf(out[i].name, sizeof out[i].name, "%s", cl.items[i].name);
        out[i].bytes = cl.items[i].bytes;
        out[i].points = cl.items[i].points;
        out[i].flags = cl.items[i].flags;
    }
    int n = (int)cl.count;
    proto_clouds_free(&cl);
    *list = out;
    return n;
}

void spc_free_list(spc_cloud *list) { free(list); }

static void info_from(const proto_info *in, spc_info *info)
{
    if (!info) return;
    memset(info, 0, sizeof *info);
    snprintf(info->name, sizeof info->name, "%s", in->name);
    info->points = in->points;
    info->dropped = in->dropped;
    memcpy(info->bmin, in->bmin, sizeof in->bmin);
    memcpy(info->bmax, in->bmax, sizeof in->bmax);
    memcpy(info->offset, in->offset, sizeof in->offset);
    info->attrs = in->attrs;
    info->sigma = in->sigma;
    info->k = in->k;
    snprintf(info->format, sizeof info->format, "%s", in->format);
    memcpy(info->up, in->view.up, sizeof info->up);
    memcpy(info->view_dir, in->view.dir, sizeof info->view_dir);
    memcpy(info->view_bmin, in->view.bmin, sizeof info->view_bmin);
    memcpy(info->view_bmax, in->view.bmax, sizeof info->view_bmax);
    info->view_npts = in->view.npts;
    memcpy(info->view_pts, in->view.pts, sizeof info->view_pts);
}

/* view_of: the default view of info; an info filled by hand with bounds only (no view) gets
 * the rule's view of its bounds (z up). */
_Static_assert(sizeof(((spc_info *)0)->view_pts) == sizeof(((sp_view *)0)->pts),
               "spc_info.view_pts holds SP_VIEW_PTS points");

static void view_of(const spc_info *info, sp_view *v)
{
    memset(v, 0, sizeof *v);
    double uu = 0, dd = 0;
    for (int i = 0; i < 3; i++) uu += info->up[i] * info->up[i], dd += info->view_dir[i] * info->view_dir[i];
    if (!(uu > 0 && dd > 0)) {
        sp_view_default(info->bmin, info->bmax, SP_UP_Z, NULL, v);
        return;
    }
    memcpy(v->up, info->up, sizeof v->up);
    memcpy(v->dir, info->view_dir, sizeof v->dir);
    int box = 0;
    for (int i = 0; i < 3; i++) box |= info->view_bmax[i] != 0 || info->view_bmin[i] != 0;
    memcpy(v->bmin, box ? info->view_bmin : info->bmin, sizeof v->bmin);
    memcpy(v->bmax, box ? info->view_bmax : info->bmax, sizeof v->bmax);
    if (box && info->view_npts <= SP_VIEW_PTS) {
        v->npts = info->view_npts;
        memcpy(v->pts, info->view_pts, sizeof v->pts);
    }
}

void spc__note(spc_client *c, const proto_msg *m)
{
    if (!c->open_pending || m->h.seq != c->open_pending) return;
    proto_error e = {0};
    proto_progress p;
    if (m->h.type == PROTO_MSG_PROGRESS && c->open_progress &&
        proto_parse_progress(m->payload, m->len, &p, &e) == 0) {
        c->open_progress(c->open_user, proto_phase_name(p.phase), p.fraction, p.text);
        return;
    }
    if (m->h.type == PROTO_MSG_INFO && proto_parse_info(m->payload, m->len, &c->final, &e) == 0 &&
        !(c->final.attrs & PROTO_INFO_PROVISIONAL)) {
        c->have_final = 1;
        c->open_pending = 0;
    }
}

int spc_open_provisional(const spc_client *c)
{
    return c && c->open_pending != 0;
}

int spc_wait_ready(spc_client *c, spc_info *info, spc_progress_fn progress, void *user)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (c->have_final) {
        c->have_final = 0;
        info_from(&c->final, info);
        return 1;
    }
    if (!c->open_pending) return 0;
    proto_msg m;
    uint32_t seq = c->open_pending;
    for (;;) {
        rc = spc__wait(c, seq, PROTO_MSG_INFO, &m, progress, user);
        if (rc < 0) {
            if (c->errseq == seq) c->open_pending = 0; /* the full prep failed */
            return rc;
        }
        proto_error e = {0};
        proto_info in;
        if (proto_parse_info(m.payload, m.len, &in, &e) < 0)
            return spc__fail(c, -e.code, "bad INFO from the server: %s", e.msg);
        if (in.attrs & PROTO_INFO_PROVISIONAL) continue;
        c->open_pending = 0;
        info_from(&in, info);
        return 1;
    }
}

int spc_open(spc_client *c, const char *name, spc_info *info, spc_progress_fn progress,
             void *user)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (!name) return spc__fail(c, SPC_E_INVALID_ARG, "no cloud name given");
    proto_error e = {0};
    if (proto_name_check(name, &e) < 0) return spc__fail(c, SPC_E_BAD_NAME, "%s", e.msg);
    uint32_t seq = spc__next_seq(c);
    if ((rc = proto_enc_open(&c->out, seq, name)) < 0) return enc_failed(c, rc, "OPEN");
    proto_msg m;
    if ((rc = send_and_wait(c, seq, PROTO_MSG_INFO, &m, progress, user)) < 0) return rc;
    proto_info in;
    if (proto_parse_info(m.payload, m.len, &in, &e) < 0)
        return spc__fail(c, -e.code, "bad INFO from the server: %s", e.msg);
    c->open_pending = in.attrs & PROTO_INFO_PROVISIONAL ? seq : 0;
    c->have_final = 0;
    c->open_progress = progress;
    c->open_user = user;
    info_from(&in, info);
    return 0;
}

/* ---- camera ---------------------------------------------------------------------------- */

static void to_proto_cam(const spc_camera *s, proto_camera *p)
{
    memcpy(p->eye, s->eye, sizeof p->eye);
    memcpy(p->target, s->target, sizeof p->target);
    memcpy(p->up, s->up, sizeof p->up);
    p->fov_deg = s->fov_deg;
    p->znear = s->znear;
    p->zfar = s->zfar;
    p->width = s->width;
    p->height = s->height;
}

/* enc_camera: appends a CAMERA for cam to c->out after checking it exactly as the server will
 * (by parsing the encoded bytes), so a bad camera fails here with the server's message. */
static int enc_camera(spc_client *c, const spc_camera *cam, uint32_t *seq_out)
{
    proto_camera pc;
    to_proto_cam(cam, &pc);
    size_t start = c->out.len;
    uint32_t seq = spc__next_seq(c);
    int rc = proto_enc_camera(&c->out, seq, &pc);
    if (rc < 0) return enc_failed(c, rc, "CAMERA");
    proto_camera chk;
    proto_error e = {0};
    rc = proto_parse_camera(c->out.data + start + PROTO_HEADER_LEN,
                            (uint32_t)(c->out.len - start - PROTO_HEADER_LEN), &chk, &e);
    if (rc < 0) {
        c->out.len = start;
        return spc__fail(c, rc == -PROTO_E_BAD_CAMERA ? SPC_E_BAD_CAMERA : SPC_E_INVALID_ARG,
                         "%s", e.msg);
    }
    if ((c->server.max_width && cam->width > c->server.max_width) ||
        (c->server.max_height && cam->height > c->server.max_height)) {
        c->out.len = start;
        return spc__fail(c, SPC_E_BAD_CAMERA, "camera size %ux%u is over the server's maximum "
                         "of %ux%u", cam->width, cam->height, c->server.max_width,
                         c->server.max_height);
    }
    if (seq_out) *seq_out = seq;
    return 0;
}

int spc_set_camera(spc_client *c, const spc_camera *cam, uint32_t *seq)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (!cam) return spc__fail(c, SPC_E_INVALID_ARG, "no camera given");
    if ((rc = enc_camera(c, cam, seq)) < 0) return rc;
    return spc__flush(c, spc__deadline(c));
}

int spc_prefetch(spc_client *c, const spc_camera *cams, int n)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (!cams || n < 1) return spc__fail(c, SPC_E_INVALID_ARG, "no cameras to prefetch");
    if (n > (int)PROTO_MAX_PREFETCH) n = (int)PROTO_MAX_PREFETCH;
    proto_prefetch pf = {.count = (uint8_t)n};
    for (int k = 0; k < n; k++) {
        to_proto_cam(&cams[k], &pf.cams[k]);
        if ((c->server.max_width && cams[k].width > c->server.max_width) ||
            (c->server.max_height && cams[k].height > c->server.max_height))
            return spc__fail(c, SPC_E_BAD_CAMERA, "prefetch camera %d: size %ux%u is over the "
                             "server's maximum of %ux%u", k, cams[k].width, cams[k].height,
                             c->server.max_width, c->server.max_height);
    }
    size_t start = c->out.len;
    rc = proto_enc_prefetch(&c->out, spc__next_seq(c), &pf);
    if (rc < 0) return enc_failed(c, rc, "PREFETCH");
    proto_prefetch chk;
    proto_error e = {0};
    rc = proto_parse_prefetch(c->out.data + start + PROTO_HEADER_LEN,
                              (uint32_t)(c->out.len - start - PROTO_HEADER_LEN), &chk, &e);
    if (rc < 0) {
        c->out.len = start;
        return spc__fail(c, rc == -PROTO_E_BAD_CAMERA ? SPC_E_BAD_CAMERA : SPC_E_INVALID_ARG,
                         "%s", e.msg);
    }
    return spc__flush(c, spc__deadline(c));
}

void spc_camera_frame(const spc_info *info, uint32_t width, uint32_t height, spc_camera *cam)
{
    memset(cam, 0, sizeof *cam);
    cam->width = width;
    cam->height = height;
    cam->fov_deg = (float)SP_DEFAULT_FOV;
    sp_view v;
    view_of(info, &v);
    sp_frame_fit(&v, (int)width, (int)height, cam->fov_deg, cam->eye, cam->target, cam->up);
}

void spc_camera_orbit(const spc_info *info, const double up_in[3], int i, int n, float fov_deg,
                      uint32_t width, uint32_t height, spc_camera *cam)
{
    memset(cam, 0, sizeof *cam);
    cam->width = width;
    cam->height = height;
    cam->fov_deg = fov_deg > 0 && fov_deg < 180 ? fov_deg : (float)SP_DEFAULT_FOV;
    sp_view v;
    view_of(info, &v);
    sp_frame_orbit(&v, up_in, i, n, (int)width, (int)height, cam->fov_deg, cam->eye, cam->target,
                   cam->up);
}

/* ---- parameters ------------------------------------------------------------------------- */

/* send_params: sends the records of the parameters in mask (ids) from p; waits for OK; on
 * success c->params = *p. */
static int send_params(spc_client *c, const sp_params *p, uint64_t mask)
{
    proto_param_rec recs[SP_PARAM_COUNT];
    unsigned n = 0;
    for (int id = 0; id < SP_PARAM_COUNT; id++)
        if (mask & (1ull << id)) proto_param_rec_from(p, id, &recs[n++]);
    uint32_t seq = spc__next_seq(c);
    int rc = proto_enc_params(&c->out, seq, recs, n);
    if (rc < 0) return enc_failed(c, rc, "PARAMS");
    proto_msg m;
    if ((rc = send_and_wait(c, seq, PROTO_MSG_OK, &m, NULL, NULL)) < 0) return rc;
    c->params = *p;
    return 0;
}

/* set_text: validates name=value into *p with params.c; the id, or a code. */
static int set_text(spc_client *c, sp_params *p, const char *name, const char *value)
{
    char err[300];
    int id = sp_param_find(name);
    if (id < 0)
        return spc__fail(c, SPC_E_BAD_PARAM_NAME, "unknown parameter '%s'", name);
    if (sp_param_set_text(p, name, value, err, sizeof err) < 0)
        return spc__fail(c, SPC_E_BAD_PARAM_VALUE, "%s", err);
    return id;
}

/* split_kv: "name=value" into name (cap 64) and a pointer to value; 0 or a code. */
static int split_kv(spc_client *c, const char *kv, char name[64], const char **value)
{
    const char *eq = kv ? strchr(kv, '=') : NULL;
    if (!eq || eq == kv || (size_t)(eq - kv) >= 64)
        return spc__fail(c, SPC_E_INVALID_ARG, "'%s' is not key=value", kv ? kv : "(null)");
    memcpy(name, kv, (size_t)(eq - kv));
    name[eq - kv] = 0;
    *value = eq + 1;
    return 0;
}

int spc_set_params(spc_client *c, const char *const *kvs, int n)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (n < 0 || (n > 0 && !kvs)) return spc__fail(c, SPC_E_INVALID_ARG, "bad parameter list");
    sp_params p = c->params;
    uint64_t mask = 0;
    for (int i = 0; i < n; i++) {
        char name[64];
        const char *value = NULL;
        if ((rc = split_kv(c, kvs[i], name, &value)) < 0) return rc;
        int id = set_text(c, &p, name, value);
        if (id < 0) return id;
        mask |= 1ull << id;
    }
    /* a text form may set more than its own parameter (field=class:3,4,5 sets classes too) */
    for (int id = 0; id < SP_PARAM_COUNT; id++) {
        char a[160], b[160];
        sp_param_get_text(&p, id, a, sizeof a);
        sp_param_get_text(&c->params, id, b, sizeof b);
        if (strcmp(a, b)) mask |= 1ull << id;
    }
    if (!mask) return 0;
    return send_params(c, &p, mask);
}

int spc_set_param(spc_client *c, const char *kv) { return spc_set_params(c, &kv, 1); }

/* set_rec: validates record r locally with the server's own check, then sends it. */
static int set_rec(spc_client *c, proto_param_rec *r)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    sp_params p = c->params;
    uint64_t mask = 0;
    proto_error e = {0};
    if (proto_param_apply(r, &p, &mask, &e) < 0)
        return spc__fail(c, -e.code, "%s", e.msg);
    return send_params(c, &p, mask);
}

/* rec_init: a record for name of type t (the name is checked by proto_param_apply). */
static int rec_init(spc_client *c, proto_param_rec *r, const char *name, sp_type t)
{
    memset(r, 0, sizeof *r);
    if (!name || strlen(name) >= sizeof r->name)
        return spc__fail(c, SPC_E_BAD_PARAM_NAME, "unknown parameter '%.64s'", name ? name : "");
    memcpy(r->name, name, strlen(name) + 1);
    r->type = (uint8_t)t;
    return 0;
}

int spc_set_param_float(spc_client *c, const char *name, float v)
{
    proto_param_rec r;
    int rc = rec_init(c, &r, name, SP_T_FLOAT);
    if (rc < 0) return rc;
    r.u.f = v;
    return set_rec(c, &r);
}

int spc_set_param_int(spc_client *c, const char *name, int64_t v)
{
    proto_param_rec r;
    int rc = rec_init(c, &r, name, SP_T_INT);
    if (rc < 0) return rc;
    r.u.i = v;
    return set_rec(c, &r);
}

int spc_set_param_enum(spc_client *c, const char *name, const char *value)
{
    proto_param_rec r;
    int rc = rec_init(c, &r, name, SP_T_ENUM);
    if (rc < 0) return rc;
    /* the text form checks the value against the list and names the choices */
    sp_params tmp = c->params;
    int id = set_text(c, &tmp, name, value ? value : "");
    if (id < 0) return id;
    if (sp_param_table[id].type != SP_T_ENUM)
        return spc__fail(c, SPC_E_BAD_PARAM_VALUE, "parameter '%s' is not an enum", name);
    proto_param_rec_from(&tmp, id, &r);
    return set_rec(c, &r);
}

int spc_set_param_vec3(spc_client *c, const char *name, const float v[3])
{
    proto_param_rec r;
    int rc = rec_init(c, &r, name, SP_T_VEC3);
    if (rc < 0) return rc;
    memcpy(r.u.v, v, sizeof r.u.v);
    return set_rec(c, &r);
}

int spc_get_param(const spc_client *c, const char *name, char *buf, size_t len)
{
    int id = c && name ? sp_param_find(name) : -1;
    if (id < 0 || !buf || !len) return SPC_E_INVALID_ARG;
    sp_param_get_text(&c->params, id, buf, len);
    return 0;
}

/* ---- frames ----------------------------------------------------------------------------- */

/* fill_frame: parses FRAME m into f and decodes it when asked. */
static int fill_frame(spc_client *c, const proto_msg *m, spc_frame *f, int decode)
{
    proto_frame pf;
    proto_error e = {0};
    memset(f, 0, sizeof *f);
    if (proto_parse_frame(m->payload, m->len, &pf, &e) < 0)
        return spc__fail(c, -e.code, "bad FRAME from the server: %s", e.msg);
    f->seq = m->h.seq;
    f->camera_seq = pf.camera_seq;
    if (!sp_enum_name(SP_PIPELINE, pf.pipeline, f->pipeline, sizeof f->pipeline))
        snprintf(f->pipeline, sizeof f->pipeline, "#%u", pf.pipeline);
    if (!sp_enum_name(SP_FORMAT, pf.format, f->format, sizeof f->format))
        snprintf(f->format, sizeof f->format, "#%u", pf.format);
    f->width = pf.width;
    f->height = pf.height;
    f->render_us = pf.render_us;
    f->readback_us = pf.readback_us;
    f->encode_us = pf.encode_us;
    f->points_drawn = pf.points_drawn;
    f->complete = (pf.flags & PROTO_FRAME_COMPLETE) != 0;
    f->provisional = (pf.flags & PROTO_FRAME_PROVISIONAL) != 0;
    f->data = pf.data;
    f->data_len = pf.data_len;
    if (!decode) return 0;
    char err[400];
    if (!c->fdec && !(c->fdec = fd_create(err, sizeof err)))
        return spc__fail(c, SPC_E_DECODE, "cannot start the frame decoder: %s", err);
    uint64_t t0 = spc__now_us();
    const uint8_t *rgba = NULL;
    int rc = fd_decode(c->fdec, pf.format, pf.data, pf.data_len, (int)pf.width, (int)pf.height,
                       &rgba, NULL, NULL, err, sizeof err);
    if (rc < 0)
        return spc__fail(c, SPC_E_DECODE, "cannot decode the %s frame of request %u: %s",
                         f->format, f->seq, err);
    f->rgba = rgba;
    f->decode_us = spc__now_us() - t0;
    return 0;
}

int spc_send_render(spc_client *c, const spc_camera *cam, uint32_t *render_seq)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (cam && (rc = enc_camera(c, cam, NULL)) < 0) return rc;
    uint32_t seq = spc__next_seq(c);
    if ((rc = proto_enc_empty(&c->out, PROTO_MSG_RENDER, seq)) < 0)
        return enc_failed(c, rc, "RENDER");
    if ((rc = spc__flush(c, spc__deadline(c))) < 0) return rc;
    if (render_seq) *render_seq = seq;
    return 0;
}

int spc_recv_frame(spc_client *c, spc_frame *f, int decode)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    uint64_t deadline = spc__deadline(c);
    for (;;) {
        proto_msg m;
        if ((rc = spc__recv(c, &m, deadline)) < 0) return rc;
        if (m.h.type == PROTO_MSG_ERROR) return spc__server_error(c, &m);
        if (m.h.type == PROTO_MSG_FRAME) return fill_frame(c, &m, f, decode);
        spc__note(c, &m); /* the full INFO of a provisional OPEN */
        /* OK/PONG/... of requests nobody waits for: skip */
    }
}

int spc_render(spc_client *c, spc_frame *f, int decode)
{
    uint32_t seq;
    int rc = spc_send_render(c, NULL, &seq);
    if (rc < 0) return rc;
    proto_msg m;
    if ((rc = spc__wait(c, seq, PROTO_MSG_FRAME, &m, NULL, NULL)) < 0) return rc;
    return fill_frame(c, &m, f, decode);
}

int spc_stream(spc_client *c, int on, float max_fps)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    if (!(max_fps >= 0 && max_fps <= 1000))
        return spc__fail(c, SPC_E_BAD_PARAM_VALUE, "max_fps %g is out of range [0, 1000]",
                         (double)max_fps);
    proto_stream s = {(uint8_t)(on != 0), max_fps};
    uint32_t seq = spc__next_seq(c);
    if ((rc = proto_enc_stream(&c->out, seq, &s)) < 0) return enc_failed(c, rc, "STREAM");
    proto_msg m;
    return send_and_wait(c, seq, PROTO_MSG_OK, &m, NULL, NULL);
}

int spc_ping(spc_client *c, uint64_t *rtt_us)
{
    int rc = usable(c);
    if (rc < 0) return rc;
    uint64_t t0 = spc__now_us();
    proto_ping p = {t0};
    uint32_t seq = spc__next_seq(c);
    if ((rc = proto_enc_ping(&c->out, seq, &p)) < 0) return enc_failed(c, rc, "PING");
    proto_msg m;
    if ((rc = send_and_wait(c, seq, PROTO_MSG_PONG, &m, NULL, NULL)) < 0) return rc;
    proto_pong po;
    proto_error e = {0};
    if (proto_parse_pong(m.payload, m.len, &po, &e) < 0)
        return spc__fail(c, -e.code, "bad PONG from the server: %s", e.msg);
    if (po.token != t0)
        return spc__fail(c, SPC_E_MALFORMED, "PONG token %llu does not echo the PING's %llu",
                         (unsigned long long)po.token, (unsigned long long)t0);
    if (rtt_us) *rtt_us = spc__now_us() - t0;
    return 0;
}
