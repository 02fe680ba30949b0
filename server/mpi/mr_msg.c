/* mr_msg.c — the records one rank of splatd --mpi sends another (mr_msg.h). */
#include "mr_msg.h"

#include <stdio.h>
#include <string.h>

#include "proto.h"

static void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint32_t get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* put_payload: b's payload (the message less its header) at out + *at as u32 length + bytes;
 * 0, or -1 when the message was not encoded or does not fit before MR_CMD_BYTES. */
static int put_payload(uint8_t *out, size_t *at, int enc_rc, const proto_buf *b)
{
    if (enc_rc != 0 || b->len < PROTO_HEADER_LEN) return -1;
    size_t n = b->len - PROTO_HEADER_LEN;
    if (n > MR_CMD_BYTES - 4 - *at) return -1;
    put32(out + *at, (uint32_t)n);
    memcpy(out + *at + 4, b->data + PROTO_HEADER_LEN, n);
    *at += 4 + n;
    return 0;
}

int mr_cmd_encode(const mr_cmd *c, uint8_t out[MR_CMD_BYTES], sd_err *err)
{
    memset(out, 0, MR_CMD_BYTES);
    put32(out, (uint32_t)c->op);
    put32(out + 4, c->key);
    put32(out + 8, (uint32_t)c->want_float);
    size_t pl = c->op == MR_LOAD ? strnlen(c->path, sizeof c->path) : 0;
    if (pl >= sizeof c->path)
        return sd_errf(err, SD_ELIMIT, "MPI LOAD: the path is not shorter than %zu bytes",
                       sizeof c->path);
    out[12] = (uint8_t)pl;
    out[13] = (uint8_t)(pl >> 8);
    memcpy(out + 14, c->path, pl);
    size_t at = 14 + pl;
    if (c->op != MR_RENDER) return 0; /* the camera's and parameters' lengths stay 0 */
    proto_camera pc = {.fov_deg = c->cam.fov_deg, .znear = c->cam.znear, .zfar = c->cam.zfar,
                       .width = (uint32_t)c->cam.width, .height = (uint32_t)c->cam.height};
    memcpy(pc.eye, c->cam.eye, sizeof pc.eye);
    memcpy(pc.target, c->cam.target, sizeof pc.target);
    memcpy(pc.up, c->cam.up, sizeof pc.up);
    proto_param_rec recs[SP_PARAM_COUNT];
    for (int id = 0; id < SP_PARAM_COUNT; id++) proto_param_rec_from(&c->params, id, &recs[id]);
    proto_buf bc = {0}, bp = {0};
    int rc = put_payload(out, &at, proto_enc_camera(&bc, 0, &pc), &bc);
    if (rc == 0) rc = put_payload(out, &at, proto_enc_params(&bp, 0, recs, SP_PARAM_COUNT), &bp);
    proto_buf_free(&bc);
    proto_buf_free(&bp);
    return rc == 0 ? 0 : sd_errf(err, SD_ELIMIT, "MPI RENDER: the camera and parameters do not "
                                 "encode into %d bytes", MR_CMD_BYTES);
}

/* The reading of one record: where the next field starts, what failed first. */
typedef struct rdr {
    const uint8_t *b;
    size_t at;
    const char *what;          /* "LOAD", "RENDER" or "QUIT" */
    sd_err *err;
    int rc;
} rdr;

/* take: the next field of n bytes (its start), or NULL with r->rc set when it passes the end. */
static const uint8_t *take(rdr *r, size_t n, const char *field)
{
    if (r->rc) return NULL;
    if (n > MR_CMD_BYTES - r->at) {
        r->rc = sd_errf(r->err, SD_EFORMAT, "MPI %s: %s (%zu bytes at offset %zu) runs past "
                        "the %d-byte record", r->what, field, n, r->at, MR_CMD_BYTES);
        return NULL;
    }
    const uint8_t *p = r->b + r->at;
    r->at += n;
    return p;
}

int mr_cmd_decode(const uint8_t *buf, size_t len, mr_cmd *c, sd_err *err)
{
    if (len != MR_CMD_BYTES)
        return sd_errf(err, SD_EFORMAT, "MPI command of %zu bytes; the record has %d", len,
                       MR_CMD_BYTES);
    memset(c, 0, sizeof *c);
    sp_params_defaults(&c->params);
    c->op = (int32_t)get32(buf);
    c->key = get32(buf + 4);
    c->want_float = (int32_t)get32(buf + 8);
    if (c->op != MR_LOAD && c->op != MR_RENDER && c->op != MR_QUIT)
        return sd_errf(err, SD_EFORMAT, "unknown MPI command %d (the ranks are out of step)",
                       (int)c->op);
    rdr r = {.b = buf, .at = 12, .err = err,
             .what = c->op == MR_LOAD ? "LOAD" : c->op == MR_RENDER ? "RENDER" : "QUIT"};
    const uint8_t *p = take(&r, 2, "the path length");
    size_t pl = p ? (size_t)p[0] | (size_t)p[1] << 8 : 0;
    const uint8_t *path = take(&r, pl, "the path");
    p = take(&r, 4, "the camera length");
    size_t cl = p ? get32(p) : 0;
    const uint8_t *cam = take(&r, cl, "the camera");
    p = take(&r, 4, "the parameters length");
    size_t ql = p ? get32(p) : 0;
    const uint8_t *par = take(&r, ql, "the parameters");
    if (r.rc) return r.rc;
    for (size_t i = r.at; i < MR_CMD_BYTES; i++)
        if (buf[i])
            return sd_errf(err, SD_EFORMAT, "MPI %s: byte %zu after the last field is not zero",
                           r.what, i);
    if (c->op != MR_QUIT && c->key == 0)
        return sd_errf(err, SD_EFORMAT, "MPI %s of cloud key 0", r.what);
    if ((c->op == MR_LOAD) != (pl > 0) || (c->op == MR_RENDER) != (cl > 0 || ql > 0))
        return sd_errf(err, SD_EFORMAT, "MPI %s with a path of %zu bytes, a camera of %zu and "
                       "parameters of %zu", r.what, pl, cl, ql);
    if ((c->op != MR_RENDER && c->want_float != 0) || (c->want_float != 0 && c->want_float != 1))
        return sd_errf(err, SD_EFORMAT, "MPI %s: want_float %d", r.what, (int)c->want_float);
    if (c->op == MR_LOAD) {
        if (pl >= sizeof c->path || memchr(path, 0, pl))
            return sd_errf(err, SD_EFORMAT, "MPI LOAD: a path of %zu bytes%s", pl,
                           pl >= sizeof c->path ? ", not shorter than PATH_MAX" : " with a NUL");
        memcpy(c->path, path, pl);
        return 0;
    }
    if (c->op == MR_QUIT) return 0;
    proto_camera pc;
    proto_error pe = {0};
    int rc = proto_parse_camera(cam, (uint32_t)cl, &pc, &pe);
    if (rc == 0) {
        memcpy(c->cam.eye, pc.eye, sizeof pc.eye);
        memcpy(c->cam.target, pc.target, sizeof pc.target);
        memcpy(c->cam.up, pc.up, sizeof pc.up);
        c->cam.fov_deg = pc.fov_deg;
        c->cam.znear = pc.znear;
        c->cam.zfar = pc.zfar;
        c->cam.width = (int)pc.width;
        c->cam.height = (int)pc.height;
        rc = proto_parse_params(par, (uint32_t)ql, &c->params, NULL, &pe);
        if (rc < 0) return sd_errf(err, SD_EFORMAT, "MPI RENDER: %s", pe.msg);
        return 0;
    }
    return sd_errf(err, SD_EFORMAT, "MPI RENDER: %s", pe.msg);
}

int mr_fail_decode(const void *buf, size_t len, sd_err *err)
{
    mr_fail f;
    memset(&f, 0, sizeof f);
    memcpy(&f, buf, len < sizeof f ? len : sizeof f);
    int code = f.code <= SD_EIO && f.code >= SD_ENOTFOUND ? (int)f.code : SD_EIO;
    size_t n = strnlen(f.msg, sizeof f.msg);
    if (len < sizeof f || n == 0)
        return sd_errf(err, code, "a rank failed (code %d) without a message%s", (int)f.code,
                       len < sizeof f ? " (its record was cut short)" : "");
    return sd_errf(err, code, "%.*s", (int)n, f.msg);
}
