/* mr_msg.h — the records rank 0 of splatd --mpi broadcasts to the other ranks (mpi_render.h):
 * their encoding and the decode with its checks on arrival.
 *
 * A command travels as MR_CMD_BYTES bytes, little-endian:
 *   0   u32 op (MR_LOAD, MR_RENDER, MR_QUIT)
 *   4   u32 key (the cloud: LOAD gives it, RENDER names it; never 0 for those)
 *   8   u32 want_float (RENDER: 1 for RGBA16F as well, else 0)
 *   12  u16 path length P, then P bytes (LOAD: the cloud's file; no NUL inside; else 0)
 *       u32 camera length C, then a CAMERA message's payload (RENDER; else 0)
 *       u32 parameters length Q, then a PARAMS message's payload (RENDER; else 0)
 *   the rest zeros.
 * The camera and the parameters are the protocol's own payloads (proto.h), so a rank checks
 * them by the rules the daemon applies to a client's messages: a record cut short, an unknown
 * command (the ranks out of step), a path without room for its terminator, a camera or
 * parameter the wire would refuse is an error with a message, never a renderer driven by
 * garbage. No MPI here, so that test_mpi and the mpimsg fuzz target (tests/fuzz) run the
 * decode without it. */
#pragma once
#include <limits.h>
#include <stddef.h>
#include <stdint.h>

#include "params.h"
#include "render.h"
#include "sd_err.h"

enum { MR_LOAD = 1, MR_RENDER, MR_QUIT };
enum { MR_CMD_BYTES = 8192 };

/* A command as the ranks use it. */
typedef struct mr_cmd {
    int32_t op;
    uint32_t key;
    int32_t want_float;
    rnd_camera cam;
    sp_params params;
    char path[PATH_MAX];
} mr_cmd;

/* What the first failing rank broadcasts when the ranks agree on a step's outcome (its
 * struct's bytes: code, then the message). */
typedef struct mr_fail {
    int32_t code;              /* SD_E* */
    char msg[sizeof(((sd_err *)0)->msg)]; /* "rank R of N: ...", NUL-terminated */
} mr_fail;

/* mr_cmd_encode: c as a record (the layout above) into out. Returns 0, or SD_ELIMIT when its
 * path does not fit (err says so). */
int mr_cmd_encode(const mr_cmd *c, uint8_t out[MR_CMD_BYTES], sd_err *err);

/* mr_cmd_decode: the record in buf (len bytes, as received) into *c, checked: len is
 * MR_CMD_BYTES; a known op; LOAD and RENDER a key other than 0; LOAD a non-empty path with no
 * NUL inside, shorter than PATH_MAX; RENDER want_float 0 or 1, a camera proto_parse_camera
 * accepts and parameters proto_parse_params accepts (applied to the defaults); the lengths
 * inside the record; nothing but zeros after the last field. Returns 0 or SD_EFORMAT with err
 * saying which field is wrong (c is then unspecified). */
int mr_cmd_decode(const uint8_t *buf, size_t len, mr_cmd *c, sd_err *err);

/* mr_fail_decode: the failure record in buf (len bytes) into err: its code when that is an
 * SD_E* code, else SD_EIO; its message up to the terminator or the end of the field, or a
 * sentence saying that the rank sent none. Returns err's code (always negative). */
int mr_fail_decode(const void *buf, size_t len, sd_err *err);
