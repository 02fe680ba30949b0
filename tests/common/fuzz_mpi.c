/* fuzz_mpi.c — the body of the mpimsg fuzz target (fuzz_targets.h): the checks one rank of
 * splatd --mpi applies to what another sends it (server/mpi/mr_msg.h), without MPI. */
#include "fuzz_targets.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mr_msg.h"
#include "proto.h"

/* check_cmd: a command mr_cmd_decode accepted holds what its op needs, within the wire's
 * rules, and survives mr_cmd_encode + mr_cmd_decode unchanged. */
static void check_cmd(const mr_cmd *c)
{
    if (c->op != MR_LOAD && c->op != MR_RENDER && c->op != MR_QUIT)
        fuzz_fail("mpimsg", "op %d accepted", (int)c->op);
    if (c->op != MR_QUIT && c->key == 0) fuzz_fail("mpimsg", "key 0 accepted");
    if (c->op == MR_LOAD) {
        size_t l = strnlen(c->path, sizeof c->path);
        if (l == 0 || l == sizeof c->path)
            fuzz_fail("mpimsg", "LOAD accepted with a path of %zu bytes%s", l,
                      l ? " and no terminator" : "");
    }
    if (c->want_float != 0 && (c->op != MR_RENDER || c->want_float != 1))
        fuzz_fail("mpimsg", "want_float %d accepted", (int)c->want_float);
    if (c->op == MR_RENDER) {
        const rnd_camera *k = &c->cam;
        for (int i = 0; i < 3; i++)
            if (!isfinite(k->eye[i]) || !isfinite(k->target[i]) || !isfinite(k->up[i]))
                fuzz_fail("mpimsg", "a camera with non-finite coordinates accepted");
        if (!(k->fov_deg > 0 && k->fov_deg < 180) || k->width < 1 || k->height < 1 ||
            (unsigned)k->width > PROTO_MAX_DIM || (unsigned)k->height > PROTO_MAX_DIM)
            fuzz_fail("mpimsg", "camera fov %g, %dx%d accepted", (double)k->fov_deg, k->width,
                      k->height);
        for (int id = 0; id < SP_PARAM_COUNT; id++) {
            proto_param_rec r;
            proto_param_rec_from(&c->params, id, &r);
            sp_params p;
            sp_params_defaults(&p);
            proto_error pe = {0};
            if (proto_param_apply(&r, &p, NULL, &pe) != 0)
                fuzz_fail("mpimsg", "parameter %s accepted but the wire refuses it: %s",
                          sp_param_table[id].name, pe.msg);
        }
    }
    uint8_t *rec = malloc(MR_CMD_BYTES);
    if (!rec) abort();
    sd_err err = {0};
    if (mr_cmd_encode(c, rec, &err) != 0)
        fuzz_fail("mpimsg", "a decoded command does not encode: %s", err.msg);
    mr_cmd d;
    if (mr_cmd_decode(rec, MR_CMD_BYTES, &d, &err) != 0)
        fuzz_fail("mpimsg", "a re-encoded command does not decode: %s", err.msg);
    if (d.op != c->op || d.key != c->key || d.want_float != c->want_float ||
        strcmp(d.path, c->path) != 0 || memcmp(&d.cam, &c->cam, sizeof d.cam) != 0 ||
        !fuzz_params_equal(&d.params, &c->params))
        fuzz_fail("mpimsg", "op %d key %u decodes differently after encode + decode",
                  (int)c->op, c->key);
    free(rec);
}

int fuzz_one_mpimsg(const uint8_t *data, size_t len)
{
    if (len < 1) return SD_EINVAL;
    const uint8_t *body = data + 1;
    size_t n = len - 1;
    sd_err err = {0};
    if (data[0] & 1) {
        /* a failure record, as received (any length) */
        int rc = mr_fail_decode(body, n, &err);
        if (rc > SD_EIO || rc < SD_ENOTFOUND || err.code != rc || !err.msg[0] ||
            !memchr(err.msg, 0, sizeof err.msg))
            fuzz_fail("mpimsg", "mr_fail_decode gave %d, error %d '%.80s'", rc, err.code,
                      err.msg);
        mr_fail f;
        if (n >= sizeof f) {
            memcpy(&f, body, sizeof f);
            size_t l = strnlen(f.msg, sizeof f.msg);
            if (l && strncmp(err.msg, f.msg, l < sizeof err.msg - 1 ? l : sizeof err.msg - 1))
                fuzz_fail("mpimsg", "the message '%.80s' became '%.80s'", f.msg, err.msg);
            if (f.code >= SD_ENOTFOUND && f.code <= SD_EIO && rc != f.code)
                fuzz_fail("mpimsg", "code %d became %d", (int)f.code, rc);
        }
        return 0;
    }
    /* a command record as received (only MR_CMD_BYTES is a record), then padded with zeros
     * or cut to that size, so that the fields' checks are reached */
    mr_cmd c;
    int rc = mr_cmd_decode(body, n, &c, &err);
    if (n != MR_CMD_BYTES ? rc != SD_EFORMAT : rc != 0 && rc != SD_EFORMAT)
        fuzz_fail("mpimsg", "a %zu-byte record gave %d", n, rc);
    uint8_t *rec = calloc(1, MR_CMD_BYTES);
    if (!rec) abort();
    memcpy(rec, body, n < MR_CMD_BYTES ? n : MR_CMD_BYTES);
    memset(&err, 0, sizeof err);
    rc = mr_cmd_decode(rec, MR_CMD_BYTES, &c, &err);
    fuzz_check_sd_err(rc, &err, "MPI", "mpimsg");
    if (rc == 0) check_cmd(&c);
    free(rec);
    return rc;
}
