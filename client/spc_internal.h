/* spc_internal.h — the client handle and the connection layer shared by the files of
 * libsplatclient (not installed; splat_client.h is the public header). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "frame_decode.h"
#include "params.h"
#include "proto.h"
#include "splat_client.h"

struct spc_client {
    int fd;                       /* -1 once closed */
    int timeout_ms;               /* < 0: none */
    uint32_t seq;                 /* last request sequence number used */
    proto_decoder dec;            /* server -> client */
    proto_buf out;                /* requests waiting to be sent */
    uint8_t rbuf[64 * 1024];      /* bytes received but not yet fed to dec */
    size_t rpos, rlen;
    sp_params params;             /* what this client has set (validated locally) */
    spc_server_info server;
    uint8_t challenge[PROTO_AUTH_LEN];
    fd_ctx *fdec;                 /* frame decoder, created on first use */
    uint32_t errseq;
    char errmsg[1400];
};

/* spc__fail: records a failure on c (message from fmt), closes the connection when the code
 * is fatal, and returns code (negative SPC_E_*). */
int spc__fail(spc_client *c, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* spc__now_us: monotonic clock, microseconds. */
uint64_t spc__now_us(void);

/* spc__deadline: now + the handle's timeout in microseconds, or UINT64_MAX without one. */
uint64_t spc__deadline(const spc_client *c);

/* spc__next_seq: the next request sequence number (1, 2, ...; skips 0 on wrap). */
uint32_t spc__next_seq(spc_client *c);

/* spc__flush: sends every byte of c->out before the deadline; clears it. 0 or a code. */
int spc__flush(spc_client *c, uint64_t deadline);

/* spc__recv: the next server message in *m (payload valid until the next spc__recv).
 * Returns 0 or a code (IO, TIMEOUT, CLOSED, or a decoder error, all fatal). */
int spc__recv(spc_client *c, proto_msg *m, uint64_t deadline);

/* spc__server_error: turns an ERROR message into the failure it reports; returns its code. */
int spc__server_error(spc_client *c, const proto_msg *m);

/* spc__wait: receives until the message of type `type` answering request seq arrives (ERROR
 * for any request fails the wait; streamed frames are dropped; PROGRESS for seq goes to
 * progress, which may be NULL, and restarts the timeout). Returns 0 with *m set, or a code. */
int spc__wait(spc_client *c, uint32_t seq, unsigned type, proto_msg *m, spc_progress_fn progress,
              void *user);

/* spc__read_token: reads a token file (refusing group/other permissions). Returns the token
 * length (> 0) written to buf (cap bytes), or SPC_E_TOKEN with err filled. */
int spc__read_token(const char *path, uint8_t *buf, size_t cap, char *err, size_t errlen);
