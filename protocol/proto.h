/* proto.h — the splatd wire protocol: the only code that knows the byte layout of a message.
 * Server and client both link it; protocol/PROTOCOL.md is the normative text this implements.
 *
 * Every message = 16-byte header + payload, all integers and floats little-endian:
 *
 *   offset size  field
 *   0      4     magic      'S','P','L','T' (0x544C5053 read as u32 LE)
 *   4      2     version    negotiated protocol version (PROTO_VERSION); any >= 1 on HELLO
 *   6      2     type       PROTO_MSG_* below
 *   8      4     sequence   client: its request counter (1, 2, ...); server: the sequence of
 *                           the request the message answers, 0 when unsolicited
 *   12     4     length     payload bytes that follow, checked against a limit before reading
 *
 * No packed structs: every field is read and written with the explicit put/get helpers below.
 * Decoding is incremental (proto_decoder): feed bytes as they arrive; it answers NEED_MORE,
 * one message, or a specific error. Payloads are then parsed by one proto_parse_* per type,
 * which check every length and range and never allocate what a count merely claims.
 *
 * Conventions: functions return 0 (or a positive status documented per function) on success
 * and a negative -PROTO_E_* code on failure, and fill a proto_error with a sentence naming
 * the message, the field and the byte offset. Nothing here logs or keeps global state. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "framing.h"
#include "params.h"

/* ---- constants ------------------------------------------------------------------------- */

#define PROTO_MAGIC          0x544C5053u /* bytes 'S' 'P' 'L' 'T' on the wire */
#define PROTO_VERSION        1u          /* the version this code speaks */
#define PROTO_VERSION_MIN    1u          /* oldest version this code accepts */
#define PROTO_VERSION_MAX    1u          /* newest version this code accepts */
#define PROTO_HEADER_LEN     16u
#define PROTO_DEFAULT_PORT   7878

/* Payload limits (bytes), enforced on the header before any payload byte is read. */
#define PROTO_MAX_PREAUTH    1024u               /* client -> server before authentication */
#define PROTO_MAX_REQUEST    (64u * 1024u)       /* client -> server after authentication */
#define PROTO_MAX_FRAME      (256u * 1024u * 1024u) /* server -> client, default maximum */

#define PROTO_MAX_NAME       255u  /* cloud names, strings with a u8 length */
#define PROTO_MAX_CLIENT     64u   /* HELLO client name */
#define PROTO_MAX_ERRTEXT    1024u /* ERROR message text */
#define PROTO_MAX_PARAMS     64u   /* records in one PARAMS message */
#define PROTO_MAX_DIM        16384u /* largest width or height a CAMERA may ask for */
#define PROTO_MAX_PREFETCH   16u   /* cameras in one PREFETCH message */
#define PROTO_MAX_COORD      1e12   /* largest |coordinate| of a CAMERA's eye, target and up:
                                     * far beyond any georeferenced scan (ECEF is ~6.4e6 m),
                                     * and small enough that differences, squares and lengths
                                     * stay finite in double */
#define PROTO_AUTH_LEN       32u   /* challenge and HMAC-SHA256 proof */

/* ---- message types ----------------------------------------------------------------------
 * X(name, value, direction): C2S = client -> server, S2C = server -> client. */
enum { PROTO_C2S = 1, PROTO_S2C = 2 };

#define PROTO_MSG_LIST(X)            \
    X(HELLO,    1,   PROTO_C2S)      \
    X(LIST,     2,   PROTO_C2S)      \
    X(OPEN,     3,   PROTO_C2S)      \
    X(CAMERA,   4,   PROTO_C2S)      \
    X(PARAMS,   5,   PROTO_C2S)      \
    X(RENDER,   6,   PROTO_C2S)      \
    X(STREAM,   7,   PROTO_C2S)      \
    X(PING,     8,   PROTO_C2S)      \
    X(BYE,      9,   PROTO_C2S)      \
    X(PREFETCH, 10,  PROTO_C2S)      \
    X(WELCOME,  129, PROTO_S2C)      \
    X(CLOUDS,   130, PROTO_S2C)      \
    X(INFO,     131, PROTO_S2C)      \
    X(PROGRESS, 132, PROTO_S2C)      \
    X(FRAME,    133, PROTO_S2C)      \
    X(PONG,     134, PROTO_S2C)      \
    X(ERROR,    135, PROTO_S2C)      \
    X(OK,       136, PROTO_S2C)

enum proto_msg_type {
#define PROTO_T_(name, val, dir) PROTO_MSG_##name = val,
    PROTO_MSG_LIST(PROTO_T_)
#undef PROTO_T_
};

/* proto_msg_name: "CAMERA" for PROTO_MSG_CAMERA; "?" for an unknown type. */
const char *proto_msg_name(unsigned type);

/* proto_msg_dir: PROTO_C2S or PROTO_S2C for a known type, 0 for an unknown one. */
int proto_msg_dir(unsigned type);

/* ---- error codes ------------------------------------------------------------------------
 * X(name, value, fatal, text). Values 1-99 travel in ERROR messages; 100+ are local to a
 * client (never on the wire). fatal = 1: the server sends ERROR and closes the connection
 * (framing lost, or the peer cannot be trusted); 0: the request failed, the session goes on. */
#define PROTO_ERRORS(X)                                                                  \
    X(BAD_MAGIC,       1,  1, "bad magic (not the splatd protocol)")                      \
    X(BAD_VERSION,     2,  1, "unsupported protocol version")                             \
    X(UNKNOWN_TYPE,    3,  1, "unknown or unexpected message type")                      \
    X(TOO_LARGE,       4,  1, "payload over the limit")                                   \
    X(TRUNCATED,       5,  1, "payload shorter than its fields")                          \
    X(MALFORMED,       6,  1, "malformed payload")                                        \
    X(BAD_PARAM_NAME,  7,  0, "unknown parameter")                                        \
    X(BAD_PARAM_VALUE, 8,  0, "parameter value of the wrong type or out of range")        \
    X(BAD_NAME,        9,  0, "invalid cloud name")                                       \
    X(NOT_FOUND,       10, 0, "no such cloud")                                            \
    X(NOT_OPEN,        11, 0, "no cloud is open")                                         \
    X(AUTH_REQUIRED,   12, 1, "authentication required")                                  \
    X(AUTH_FAILED,     13, 1, "authentication failed")                                    \
    X(BUSY,            14, 0, "server busy")                                              \
    X(INTERNAL,        15, 0, "internal server error")                                    \
    X(RENDER_FAILED,   16, 0, "rendering failed")                                         \
    X(BAD_CAMERA,      17, 0, "invalid camera")                                           \
    X(LOAD_FAILED,     18, 0, "the cloud could not be loaded")                            \
    X(SHUTTING_DOWN,   19, 1, "server shutting down")                                     \
    X(IO,              100, 1, "connection error")                                        \
    X(TIMEOUT,         101, 1, "timed out")                                               \
    X(CLOSED,          102, 1, "connection closed by the peer")                           \
    X(NOMEM,           103, 1, "out of memory")                                           \
    X(INVALID_ARG,     104, 0, "invalid argument")                                        \
    X(DECODE,          105, 0, "frame could not be decoded")                              \
    X(TOKEN,           106, 1, "token file unusable")

enum proto_err_code {
#define PROTO_E_(name, val, fatal, text) PROTO_E_##name = val,
    PROTO_ERRORS(PROTO_E_)
#undef PROTO_E_
};

/* proto_err_name: "BAD_MAGIC" for PROTO_E_BAD_MAGIC (sign ignored); "UNKNOWN" otherwise. */
const char *proto_err_name(int code);
/* proto_err_text: the fixed sentence of a code ("bad magic (not the splatd protocol)"). */
const char *proto_err_text(int code);
/* proto_err_fatal: 1 when an error of this code ends the connection (see the list). */
int proto_err_fatal(int code);
/* proto_err_from_name: the code for "BAD_MAGIC", or 0. */
int proto_err_from_name(const char *name);

typedef struct proto_error {
    int code;        /* PROTO_E_* (positive), 0 when none */
    char msg[320];   /* full sentence: message, field, byte offset, value, limit */
} proto_error;

/* proto_errorf: fills e (if not NULL) and returns -code, for `return proto_errorf(e, ...)`. */
int proto_errorf(proto_error *e, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* ---- little-endian helpers ---------------------------------------------------------------
 * The only way a multi-byte value is read from or written to the wire. p must have room. */
void proto_put_u16(uint8_t *p, uint16_t v);
void proto_put_u32(uint8_t *p, uint32_t v);
void proto_put_u64(uint8_t *p, uint64_t v);
void proto_put_f32(uint8_t *p, float v);
void proto_put_f64(uint8_t *p, double v);
uint16_t proto_get_u16(const uint8_t *p);
uint32_t proto_get_u32(const uint8_t *p);
uint64_t proto_get_u64(const uint8_t *p);
float proto_get_f32(const uint8_t *p);
double proto_get_f64(const uint8_t *p);

/* ---- header ---------------------------------------------------------------------------- */

typedef struct proto_header {
    uint32_t magic;
    uint16_t version;
    uint16_t type;
    uint32_t seq;
    uint32_t len;     /* payload bytes */
} proto_header;

/* proto_put_header / proto_get_header: the 16 header bytes at p. */
void proto_put_header(uint8_t *p, const proto_header *h);
void proto_get_header(const uint8_t *p, proto_header *h);

/* ---- incremental decoder ----------------------------------------------------------------
 * One per connection and direction. Set the configuration fields after proto_decoder_init
 * (they may change between calls, e.g. max_payload after authentication). The payload buffer
 * grows with the payload bytes that have arrived (doubling from PROTO_GROW_MIN, up to the
 * length of a header that passed every check): a header alone allocates nothing. */
enum { PROTO_NEED_MORE = 0, PROTO_ONE_MSG = 1 };
enum { PROTO_GROW_MIN = 64 * 1024 };

typedef struct proto_decoder {
    /* configuration */
    uint32_t max_payload;  /* default PROTO_MAX_REQUEST; a client sets its frame maximum */
    uint16_t version;      /* 0 (default): any version >= 1 accepted (before negotiation);
                            * else the header version must equal it */
    uint8_t accept_dir;    /* PROTO_C2S (a server), PROTO_S2C (a client); 0: either */
    uint8_t preauth;       /* 1: only HELLO is accepted (else AUTH_REQUIRED) and the limit is
                            * min(max_payload, PROTO_MAX_PREAUTH) */
    /* state (private) */
    uint8_t hdr[PROTO_HEADER_LEN];
    uint32_t hdr_have;     /* header bytes collected so far */
    proto_header h;        /* the header, once complete */
    uint8_t *payload;      /* malloc'd, cap bytes */
    uint32_t cap;
    uint32_t have;         /* payload bytes collected so far */
    int failed;            /* sticky: the error code after a failure (framing is lost) */
    uint64_t offset;       /* stream bytes consumed in total, for error messages */
} proto_decoder;

/* A decoded message; payload points into the decoder and stays valid until the next
 * proto_decode or proto_decoder_free call on it. */
typedef struct proto_msg {
    proto_header h;
    const uint8_t *payload;
    uint32_t len;
} proto_msg;

/* proto_decoder_init: zeroes d and sets the defaults (max_payload = PROTO_MAX_REQUEST). */
void proto_decoder_init(proto_decoder *d, uint8_t accept_dir);
/* proto_decoder_free: releases the payload buffer and zeroes d; safe to call twice. */
void proto_decoder_free(proto_decoder *d);

/* proto_decode: consumes bytes from buf[0..len) until one message is complete or the bytes
 * run out. Sets *used to the bytes consumed (always; on NEED_MORE it is len). Returns
 * PROTO_ONE_MSG with *m filled (call again with the rest of buf for the next message),
 * PROTO_NEED_MORE, or -PROTO_E_{BAD_MAGIC,BAD_VERSION,UNKNOWN_TYPE,TOO_LARGE,AUTH_REQUIRED,
 * NOMEM} with e filled. An error is sticky: every later call returns it again. */
int proto_decode(proto_decoder *d, const uint8_t *buf, size_t len, size_t *used, proto_msg *m,
                 proto_error *e);

/* proto_check_header: the checks proto_decode applies to a complete header, usable alone
 * (e.g. by a fuzzer). Returns 0 or the negative code with e filled. */
int proto_check_header(const proto_decoder *d, const proto_header *h, proto_error *e);

/* ---- encoder buffer ----------------------------------------------------------------------
 * A growable byte buffer; every proto_enc_* appends exactly one whole message to it. */
typedef struct proto_buf {
    uint8_t *data;
    size_t len, cap;
    uint16_t version;      /* header version written; 0 = PROTO_VERSION */
} proto_buf;

void proto_buf_free(proto_buf *b);                /* frees data and zeroes b; safe twice */
void proto_buf_consume(proto_buf *b, size_t n);   /* drops the first n bytes */

/* ---- messages ------------------------------------------------------------------------------
 * Strings travel as u8 length + bytes (u16 for ERROR text), no terminator, no NUL inside;
 * the structs below hold them NUL-terminated. */

typedef struct proto_hello {          /* HELLO, client -> server */
    uint16_t min_version, max_version;  /* versions the client speaks, 1 <= min <= max */
    char client[PROTO_MAX_CLIENT + 1];  /* free text, e.g. "splat 0.1" */
    uint8_t proof_len;                  /* 0 or PROTO_AUTH_LEN */
    uint8_t proof[PROTO_AUTH_LEN];      /* HMAC-SHA256(token, challenge) */
} proto_hello;

typedef struct proto_welcome {        /* WELCOME, server -> client */
    uint16_t version;                   /* the version chosen for this connection */
    uint8_t auth_required;              /* 1: the server needs a proof */
    uint8_t authenticated;              /* 1: requests other than HELLO are now accepted */
    uint8_t challenge[PROTO_AUTH_LEN];  /* random, fixed for the connection */
    uint32_t max_request;               /* the server's client->server payload limit */
    uint32_t max_width, max_height;     /* largest frame the server renders */
    char server[PROTO_MAX_NAME + 1];    /* "splatd 0.1" */
    char backend[PROTO_MAX_NAME + 1];   /* "egl", "osmesa", "null" */
    char renderer[PROTO_MAX_NAME + 1];  /* GL renderer string */
} proto_welcome;

/* INFO attrs bit 31: the cloud is provisional (an OPEN with parameter provisional = 1 of a
 * cloud still being prepared): it draws with `points` only, and a second INFO of the same
 * OPEN's sequence follows when the full cloud replaces it (PROTOCOL.md, OPEN). */
#define PROTO_INFO_PROVISIONAL (1u << 31)

enum { PROTO_CLOUD_PREPARED = 1u << 0, /* a valid cache entry exists: OPEN is fast */
       PROTO_CLOUD_LOADED = 1u << 1 }; /* in the renderer now */

typedef struct proto_cloud_entry {
    char name[PROTO_MAX_NAME + 1];      /* file name in the data directory, e.g. "bun000.ply" */
    uint64_t bytes;                     /* file size */
    uint64_t points;                    /* 0 when not known before loading */
    uint32_t flags;                     /* PROTO_CLOUD_* */
} proto_cloud_entry;

typedef struct proto_clouds {         /* CLOUDS, server -> client */
    uint32_t count;
    proto_cloud_entry *items;           /* malloc'd by proto_parse_clouds; proto_clouds_free */
} proto_clouds;

typedef struct proto_info {           /* INFO, server -> client */
    char name[PROTO_MAX_NAME + 1];      /* resolved file name */
    uint64_t points, dropped;           /* points kept; points dropped (non-finite) */
    double bmin[3], bmax[3];            /* bounding box, file coordinates */
    double offset[3];                   /* re-centring offset: file = local + offset */
    uint32_t attrs;                     /* PC_ATTR_* bit mask (server/cloud.h) */
    float sigma;                        /* median nearest-neighbour distance, file units */
    uint32_t k;                         /* neighbours used by preprocessing */
    char format[PROTO_MAX_NAME + 1];    /* "PLY binary_little_endian 1.0" */
    sp_view view;                       /* the default view (framing.h): world up, the look
                                           direction and the box it frames */
} proto_info;

/* The phases of a first OPEN, in wire order (append only): id, name. The daemon's preprocessing
 * reports them by these ids, never by text. */
#define PROTO_PHASE_LIST(X) \
    X(LOAD, "load") X(KNN, "knn") X(NORMALS, "normals") X(RADIUS, "radius") X(FIELD, "field") \
    X(REORDER, "reorder") X(CACHE, "cache") X(UPLOAD, "upload")

enum {
#define PROTO_PHASE_ENUM_(id, name) PROTO_PHASE_##id,
    PROTO_PHASE_LIST(PROTO_PHASE_ENUM_)
#undef PROTO_PHASE_ENUM_
    PROTO_PHASE_COUNT
};

/* proto_phase_name: "knn" for PROTO_PHASE_KNN, ...; "?" for an unknown phase. */
const char *proto_phase_name(int phase);

typedef struct proto_progress {       /* PROGRESS, server -> client */
    uint8_t phase;                      /* PROTO_PHASE_* (< PROTO_PHASE_COUNT) */
    float fraction;                     /* [0, 1] of that phase */
    char text[PROTO_MAX_NAME + 1];      /* optional, e.g. "kNN 41%" */
} proto_progress;

typedef struct proto_camera {         /* CAMERA, client -> server */
    double eye[3], target[3], up[3];    /* file coordinates; eye != target; up not parallel */
    float fov_deg;                      /* vertical field of view, (0, 180) degrees */
    float znear, zfar;                  /* 0 = derive from bounds; else 0 < near < far */
    uint32_t width, height;             /* pixels, 1 .. PROTO_MAX_DIM */
} proto_camera;

typedef struct proto_prefetch {       /* PREFETCH, client -> server */
    uint8_t count;                      /* 1 .. PROTO_MAX_PREFETCH */
    proto_camera cams[PROTO_MAX_PREFETCH]; /* the next cameras of a path, nearest first */
} proto_prefetch;

typedef struct proto_param_rec {      /* one PARAMS record */
    char name[64];                      /* parameter name (params.h) */
    uint8_t type;                       /* sp_type */
    union {
        int32_t e;                      /* SP_T_ENUM: index into the values list */
        float f;                        /* SP_T_FLOAT */
        int64_t i;                      /* SP_T_INT */
        float v[3];                     /* SP_T_VEC3 */
    } u;
} proto_param_rec;

typedef struct proto_stream {         /* STREAM, client -> server */
    uint8_t on;                         /* 1: render on every camera/params change */
    float max_fps;                      /* 0 = no cap; else (0, 1000] */
} proto_stream;

typedef struct proto_ping {           /* PING, client -> server */
    uint64_t token;                     /* opaque, echoed in PONG (e.g. a client clock) */
} proto_ping;

typedef struct proto_pong {           /* PONG, server -> client */
    uint64_t token;                     /* the PING's token */
    uint64_t server_us;                 /* server monotonic clock, microseconds */
} proto_pong;

enum { PROTO_FRAME_FIXED = 48 };      /* FRAME payload bytes before the image data */
enum { PROTO_FRAME_HEAD_LEN = PROTO_HEADER_LEN + PROTO_FRAME_FIXED };

/* proto_frame_fits: 1 when a FRAME carrying data_len bytes of image data fits the server ->
 * client payload limit PROTO_MAX_FRAME (PROTOCOL.md section 3): PROTO_FRAME_FIXED + data_len
 * <= PROTO_MAX_FRAME. A server sends no larger FRAME. */
int proto_frame_fits(uint64_t data_len);

/* FRAME flags: COMPLETE = every node the view wants was drawn (always for a flat cloud); a
 * frame without it is a step of progressive refinement of a LOD cloud, and a refined frame of
 * the same camera follows while streaming. */
/* SOFT_TRUNCATED = soft with model=base or concentric dropped samples past its memory cap
 * (soft_frag_mib) or past 32 overlapping spheres in a pixel: the soft layer is incomplete there. */
enum { PROTO_FRAME_COMPLETE = 1, PROTO_FRAME_SOFT_TRUNCATED = 2 };
/* FRAME flags bit 2: drawn from a provisional cloud (INFO attrs PROTO_INFO_PROVISIONAL), with
 * the `points` pipeline whatever `pipeline` says. */
enum { PROTO_FRAME_PROVISIONAL = 4 };

typedef struct proto_frame {          /* FRAME, server -> client */
    uint32_t camera_seq;                /* sequence of the CAMERA it renders, 0 = default camera */
    uint8_t pipeline;                   /* params.h pipeline index */
    uint8_t format;                     /* params.h format index: SP_FMT_* */
    uint16_t flags;                     /* PROTO_FRAME_COMPLETE | PROTO_FRAME_SOFT_TRUNCATED */
    uint32_t width, height;             /* pixels */
    uint64_t render_us, readback_us, encode_us; /* microseconds */
    uint64_t points_drawn;
    const uint8_t *data;                /* encoded image (points into the payload when parsed) */
    uint32_t data_len;
} proto_frame;

typedef struct proto_errmsg {         /* ERROR, server -> client */
    uint32_t code;                      /* PROTO_E_* 1..99 */
    char text[PROTO_MAX_ERRTEXT + 1];
} proto_errmsg;

/* ---- encoders: each appends one message (header + payload). Return 0, or
 * -PROTO_E_INVALID_ARG (a string over its limit, a field out of range) or -PROTO_E_NOMEM,
 * leaving b unchanged. ---- */
int proto_enc_empty(proto_buf *b, unsigned type, uint32_t seq);  /* LIST, RENDER, BYE, OK */
int proto_enc_hello(proto_buf *b, uint32_t seq, const proto_hello *m);
int proto_enc_open(proto_buf *b, uint32_t seq, const char *name);
int proto_enc_camera(proto_buf *b, uint32_t seq, const proto_camera *m);
int proto_enc_params(proto_buf *b, uint32_t seq, const proto_param_rec *recs, unsigned n);
int proto_enc_stream(proto_buf *b, uint32_t seq, const proto_stream *m);
int proto_enc_prefetch(proto_buf *b, uint32_t seq, const proto_prefetch *m);
int proto_enc_ping(proto_buf *b, uint32_t seq, const proto_ping *m);
int proto_enc_welcome(proto_buf *b, uint32_t seq, const proto_welcome *m);
int proto_enc_clouds(proto_buf *b, uint32_t seq, const proto_cloud_entry *items, uint32_t n);
int proto_enc_info(proto_buf *b, uint32_t seq, const proto_info *m);
int proto_enc_progress(proto_buf *b, uint32_t seq, const proto_progress *m);
int proto_enc_frame(proto_buf *b, uint32_t seq, const proto_frame *m); /* copies m->data */
int proto_enc_pong(proto_buf *b, uint32_t seq, const proto_pong *m);
int proto_enc_error(proto_buf *b, uint32_t seq, uint32_t code, const char *text);

/* proto_frame_head: writes the header and the fixed FRAME fields (PROTO_FRAME_HEAD_LEN bytes)
 * for m->data_len bytes of image data that the caller sends right after (no copy). */
void proto_frame_head(uint8_t out[PROTO_FRAME_HEAD_LEN], uint16_t version, uint32_t seq,
                      const proto_frame *m);

/* proto_param_rec_from: the record of parameter id (params.h) holding its value in p. */
void proto_param_rec_from(const sp_params *p, int id, proto_param_rec *r);

/* proto_param_apply: validates one record against the params.h table (the check that
 * proto_parse_params applies to each record: name known, type equal to the table's, value
 * finite and in range, compared as float for float parameters) and stores it in *p.
 * *changed (may be NULL) gets bit id. Returns 0, or -PROTO_E_BAD_PARAM_NAME /
 * -PROTO_E_BAD_PARAM_VALUE with e naming the parameter and its range or values. */
int proto_param_apply(const proto_param_rec *r, sp_params *p, uint64_t *changed,
                      proto_error *e);

/* ---- parsers: payload (len bytes) -> struct. Return 0, or -PROTO_E_TRUNCATED (a field
 * cut short), -PROTO_E_MALFORMED (trailing bytes, NUL in a string, bad count/range), or the
 * code named per function, with e naming the message, field and offset. ---- */
int proto_parse_hello(const uint8_t *pl, uint32_t len, proto_hello *m, proto_error *e);
/* proto_parse_open: also -PROTO_E_BAD_NAME when the name fails proto_name_check. */
int proto_parse_open(const uint8_t *pl, uint32_t len, char name[PROTO_MAX_NAME + 1],
                     proto_error *e);
/* proto_parse_camera: also -PROTO_E_BAD_CAMERA (non-finite, fov, near/far, size, eye ==
 * target, up parallel to the view direction). */
int proto_parse_camera(const uint8_t *pl, uint32_t len, proto_camera *m, proto_error *e);
/* proto_parse_params: validates every record against the params.h table and applies them
 * all to *p, or none: -PROTO_E_BAD_PARAM_NAME (unknown name) or -PROTO_E_BAD_PARAM_VALUE
 * (wrong type, non-finite, out of range; the message names the parameter and its range or
 * values). *changed (may be NULL) gets bit id set for each parameter present. */
int proto_parse_params(const uint8_t *pl, uint32_t len, sp_params *p, uint64_t *changed,
                       proto_error *e);
int proto_parse_stream(const uint8_t *pl, uint32_t len, proto_stream *m, proto_error *e);
/* proto_parse_prefetch: count in 1..PROTO_MAX_PREFETCH, then count cameras as CAMERA's payload,
 * each checked as CAMERA is (the error names the camera's index). */
int proto_parse_prefetch(const uint8_t *pl, uint32_t len, proto_prefetch *m, proto_error *e);
int proto_parse_ping(const uint8_t *pl, uint32_t len, proto_ping *m, proto_error *e);
/* proto_parse_empty: LIST, RENDER, BYE, OK: MALFORMED unless len == 0. */
int proto_parse_empty(unsigned type, uint32_t len, proto_error *e);
int proto_parse_welcome(const uint8_t *pl, uint32_t len, proto_welcome *m, proto_error *e);
/* proto_parse_clouds: allocates m->items only after checking count against len. */
int proto_parse_clouds(const uint8_t *pl, uint32_t len, proto_clouds *m, proto_error *e);
void proto_clouds_free(proto_clouds *m);
int proto_parse_info(const uint8_t *pl, uint32_t len, proto_info *m, proto_error *e);
int proto_parse_progress(const uint8_t *pl, uint32_t len, proto_progress *m, proto_error *e);
/* proto_parse_frame: m->data points into pl. Checks format/pipeline indices and sizes. */
int proto_parse_frame(const uint8_t *pl, uint32_t len, proto_frame *m, proto_error *e);
int proto_parse_pong(const uint8_t *pl, uint32_t len, proto_pong *m, proto_error *e);
int proto_parse_error(const uint8_t *pl, uint32_t len, proto_errmsg *m, proto_error *e);

/* ---- names and negotiation ------------------------------------------------------------ */

/* proto_name_check: 0 when name can name a cloud in the data directory: 1..255 bytes, no
 * '/', '\\' or ':', no control bytes, not starting with '.' or ' ', not ending with ' '.
 * So "..", "/etc/passwd", "a/../b" are refused. Else -PROTO_E_BAD_NAME with e saying why. */
int proto_name_check(const char *name, proto_error *e);

/* proto_pick_version: the highest version in [min, max] that this code speaks, or
 * -PROTO_E_BAD_VERSION with e naming both ranges. */
int proto_pick_version(uint16_t min, uint16_t max, proto_error *e);
