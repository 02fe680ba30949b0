/* spc_internal.h — the client handle and the connection layer shared by the files of
 * libsplatclient (not installed; splat_client.h is the public header). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "frame_decode.h"
#include "params.h"
#include "proto.h"
#include "splat_client.h"

struct spc_tls_io;

struct spc_client {
    int fd;                       /* -1 once closed */
    struct ssl_st *ssl;           /* the TLS connection (spc_tls.c), NULL for plain TCP */
    struct ssl_ctx_st *tls_ctx;
    struct bio_method_st *tls_meth;
    struct spc_tls_io *tls_io;
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
    uint32_t open_pending;        /* an OPEN answered with a provisional INFO: its sequence,
                                   * until the full INFO (or an ERROR) of it arrives */
    int have_final;               /* that full INFO arrived while waiting for something else */
    spc_progress_fn open_progress; /* spc_open's progress callback: also called for the
                                   * PROGRESS of a provisional OPEN that later calls skip */
    void *open_user;
    proto_info final;
};

/* spc__note: m (a message no call is waiting for) may be the full INFO or an ERROR of a
 * provisionally answered OPEN: recorded. */
void spc__note(spc_client *c, const proto_msg *m);

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

/* spc__wait_fd: polls c->fd for ev (POLLIN/POLLOUT) until the deadline. 0 when ready, or
 * TIMEOUT/IO (failed on c). */
int spc__wait_fd(spc_client *c, short ev, uint64_t deadline);

/* spc__buffered: 1 when received bytes wait inside the library (its buffer or TLS's), so
 * the socket alone would not say that a message may be readable. */
int spc__buffered(const spc_client *c);

/* ---- TLS (spc_tls.c) ---- */

/* spc__tls_start: the TLS handshake on the connected c->fd, verifying the server's
 * certificate chain against ca_file (PEM; NULL: the system's trusted certificates) and that
 * it names `name` (an IP address or a DNS name; NULL: host). 0, or a code failed on c. */
int spc__tls_start(spc_client *c, const char *host, const char *name, const char *ca_file,
                   uint64_t deadline);
/* spc__tls_io: one SSL_write (writing) or SSL_read of up to len bytes. Returns 0 with *done
 * bytes moved, 1 when nothing can move now (*ev: the poll event to wait for), 2 when the
 * server closed the connection (reads), or a negative code failed on c. */
int spc__tls_io(spc_client *c, int writing, void *buf, size_t len, size_t *done, short *ev);
/* spc__tls_pending: 1 when TLS holds decrypted bytes not read yet. */
int spc__tls_pending(const spc_client *c);
/* spc__tls_end: frees the TLS state (graceful: sends close_notify first, best effort). */
void spc__tls_end(spc_client *c, int graceful);

/* spc__read_token: reads a token file by the daemon's rule (auth_token_load, auth.h): a
 * regular file that group and others cannot use, its trailing CR and LF characters not part of
 * the token, which must hold 1 to cap bytes; a file over cap + 2 bytes is refused. Returns the
 * token length (> 0) written to buf (cap bytes), or SPC_E_TOKEN with err filled. */
int spc__read_token(const char *path, uint8_t *buf, size_t cap, char *err, size_t errlen);
