/* splat_client.h — libsplatclient: talk to a splatd daemon from C.
 *
 * The one public header of the library (installed with `make install`; pkg-config name
 * `splatclient`). It needs nothing but the C standard headers.
 *
 *     spc_options o = {.host = "127.0.0.1", .port = 7878};
 *     spc_client *c;
 *     char err[256];
 *     if (spc_connect(&o, &c, err, sizeof err) < 0) { fprintf(stderr, "%s\n", err); ... }
 *     spc_info info;
 *     if (spc_open(c, "bun000", &info, NULL, NULL) < 0) { puts(spc_errmsg(c)); ... }
 *     spc_camera cam;
 *     spc_camera_frame(&info, 1280, 720, &cam);
 *     spc_set_camera(c, &cam, NULL);
 *     spc_set_param(c, "quality=90");
 *     spc_frame f;
 *     if (spc_render(c, &f, 1) == 0) use(f.rgba, f.width, f.height);
 *     spc_close(c);
 *
 * Model: one handle = one TCP connection = one server session (one open cloud, one camera,
 * one parameter set). Calls block, each for at most the handle's timeout. The handle is not
 * thread-safe: use it from one thread at a time.
 *
 * Errors: every int-returning function returns 0 (or a documented non-negative value) on
 * success and a negative SPC_E_* code on failure; spc_errmsg(c) then holds a sentence saying
 * what went wrong. An ERROR sent by the server surfaces as the negative of its wire code
 * (e.g. SPC_E_NOT_FOUND) with the server's text. After a fatal error (spc_error_fatal) the
 * connection is closed and every later call fails with SPC_E_CLOSED; call spc_close. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SPC_DEFAULT_PORT 7878

/* Error codes: the negatives of the protocol's codes (protocol/PROTOCOL.md, section 6). */
enum spc_error {
    SPC_E_BAD_MAGIC = -1,        /* the peer does not speak this protocol */
    SPC_E_BAD_VERSION = -2,      /* no common protocol version */
    SPC_E_UNKNOWN_TYPE = -3,
    SPC_E_TOO_LARGE = -4,        /* a message over a limit (e.g. the frame maximum) */
    SPC_E_TRUNCATED = -5,
    SPC_E_MALFORMED = -6,
    SPC_E_BAD_PARAM_NAME = -7,   /* unknown parameter (checked locally first) */
    SPC_E_BAD_PARAM_VALUE = -8,  /* wrong type or out of range (checked locally first) */
    SPC_E_BAD_NAME = -9,         /* cloud name is path-like */
    SPC_E_NOT_FOUND = -10,       /* no such cloud */
    SPC_E_NOT_OPEN = -11,        /* no cloud open */
    SPC_E_AUTH_REQUIRED = -12,   /* the server needs a token and none was given */
    SPC_E_AUTH_FAILED = -13,     /* wrong token */
    SPC_E_BUSY = -14,
    SPC_E_INTERNAL = -15,
    SPC_E_RENDER_FAILED = -16,
    SPC_E_BAD_CAMERA = -17,      /* checked locally first */
    SPC_E_LOAD_FAILED = -18,
    SPC_E_SHUTTING_DOWN = -19,
    SPC_E_IO = -100,             /* connect/send/receive failed */
    SPC_E_TIMEOUT = -101,
    SPC_E_CLOSED = -102,         /* the connection is closed (by the peer, or after an error) */
    SPC_E_NOMEM = -103,
    SPC_E_INVALID_ARG = -104,
    SPC_E_DECODE = -105,         /* the frame could not be decoded to RGBA8 */
    SPC_E_TOKEN = -106,          /* token file missing, empty, or readable by group/others */
};

/* spc_strerror: the name of a code ("NOT_FOUND"); never NULL. */
const char *spc_strerror(int code);
/* spc_error_fatal: 1 when an error of this code closed the connection. */
int spc_error_fatal(int code);

typedef struct spc_client spc_client;

/* Connection options. Zero-initialise, set what you need; zero fields take the defaults. */
typedef struct spc_options {
    const char *host;            /* default "127.0.0.1"; a name or an IPv4/IPv6 address */
    int port;                    /* default 7878 */
    const char *token_file;      /* default NULL: no token. The file must not be readable by
                                  * group or others (mode 0600); its content, trailing newline
                                  * removed, is the shared secret */
    int timeout_ms;              /* default 30000: limit of every blocking call; < 0: none */
    const char *client_name;     /* default "libsplatclient": shown in the server's log */
    uint32_t max_frame_bytes;    /* default 256 MiB: larger FRAME messages are refused */
    int tls;                     /* 1: TLS, verifying the server's certificate against the
                                  * system's trusted certificates and its name against host */
    const char *tls_ca;          /* PEM file of the CA(s) to trust instead (implies tls) */
    const char *tls_name;        /* the name the certificate must carry when it differs from
                                  * host (implies tls); an IP address or a DNS name */
} spc_options;

/* What the server said about itself in its WELCOME. */
typedef struct spc_server_info {
    unsigned version;            /* negotiated protocol version */
    int auth_required;
    char server[256];            /* "splatd 0.1" */
    char backend[256];           /* "egl", "osmesa", "null" */
    char renderer[256];          /* GL renderer string */
    uint32_t max_width, max_height;
} spc_server_info;

/* spc_connect: connects (TCP_NODELAY), negotiates the version and, when the server asks for
 * it, authenticates with HMAC-SHA256(token, challenge). On success returns 0 and sets *out;
 * on failure returns a negative code, sets *out to NULL and writes a sentence to err. */
int spc_connect(const spc_options *opt, spc_client **out, char *err, size_t errlen);

/* spc_close: sends BYE (best effort), closes the socket and frees c. NULL is allowed. */
void spc_close(spc_client *c);

/* spc_errmsg: the sentence describing the last failure on c ("" when none). */
const char *spc_errmsg(const spc_client *c);
/* spc_errseq: the request sequence number the last server ERROR named (0: none/unattributed). */
uint32_t spc_errseq(const spc_client *c);
/* spc_server: the server's WELCOME information; valid until spc_close. */
const spc_server_info *spc_server(const spc_client *c);
/* spc_set_timeout: changes the per-call timeout (ms; < 0: none). */
void spc_set_timeout(spc_client *c, int timeout_ms);

/* ---- clouds ------------------------------------------------------------------------------ */

typedef struct spc_cloud {
    char name[256];              /* file name in the server's data directory */
    uint64_t bytes;              /* file size */
    uint64_t points;             /* 0 when not known before loading */
    uint32_t flags;              /* 1: preprocessed cache exists, 2: loaded now */
} spc_cloud;

/* spc_list: the clouds the server offers. Returns the count (>= 0) and sets *list to a
 * malloc'd array (free with spc_free_list), or a negative code. */
int spc_list(spc_client *c, spc_cloud **list);
void spc_free_list(spc_cloud *list);

enum { SPC_ATTR_RGB = 1, SPC_ATTR_NORMAL = 2, SPC_ATTR_INTENSITY = 4, SPC_ATTR_CLASS = 8,
       SPC_ATTR_RADIUS = 16, SPC_ATTR_SCALAR = 32, SPC_ATTR_F = 64, SPC_ATTR_SCAN = 128 };
/* spc_info.attrs bit 31: the cloud is provisional (see spc_open). */
#define SPC_INFO_PROVISIONAL 0x80000000u

typedef struct spc_info {
    char name[256];              /* resolved file name */
    uint64_t points, dropped;
    double bmin[3], bmax[3];     /* bounding box, file coordinates */
    double offset[3];            /* re-centring offset */
    uint32_t attrs;              /* SPC_ATTR_* */
    float sigma;                 /* median nearest-neighbour distance */
    uint32_t k;                  /* neighbours used by preprocessing */
    char format[256];            /* "PLY binary_little_endian 1.0" */
    /* The default view, the same in every client (the server's rule, protocol/framing.h):
     * world up (z for LAS/LAZ/COPC/E57 and georeferenced clouds, a PCD's sensor orientation,
     * else the flat axis or +y), the direction the first view looks along, and the box it
     * frames (the bounds without their farthest outliers). Orbits and drags turn about up. */
    double up[3], view_dir[3];
    double view_bmin[3], view_bmax[3];
    uint32_t view_npts;          /* 0-26: the cloud's extreme points, which the default camera */
    double view_pts[26][3];      /*   fits instead of the box's corners (PROTOCOL.md, INFO) */
} spc_info;

/* Progress of a first OPEN (loading, kNN, ...): phase name, fraction [0,1] of that phase. */
typedef void (*spc_progress_fn)(void *user, const char *phase, float fraction, const char *text);

/* spc_open: opens cloud name (a file name in the server's data directory; an extension may be
 * left out). Blocks until the server has loaded it (preprocessing a new cloud can take a
 * while: the timeout applies to the gap between messages, and PROGRESS resets it), calling
 * progress (may be NULL) for each PROGRESS. Fills info (may be NULL). Returns 0 or a code:
 * SPC_E_BAD_NAME (checked locally first), SPC_E_NOT_FOUND, SPC_E_LOAD_FAILED, ... */
int spc_open(spc_client *c, const char *name, spc_info *info, spc_progress_fn progress,
             void *user);
/* Provisional clouds: after spc_set_param(c, "provisional=1"), an OPEN of a cloud the server
 * is still preparing may return early with a provisional cloud (info->attrs has
 * SPC_INFO_PROVISIONAL; today: a COPC file's top octree levels): frames render at once, drawn
 * with `points` (spc_frame.provisional = 1) whatever `pipeline` says, while the server goes on
 * preparing; then the server swaps in the full cloud and sends its INFO.
 * Until the full INFO, progress and user of spc_open stay in use: every call on c that skips a
 * PROGRESS of the OPEN passes it to progress.
 * spc_open_provisional: 1 while the open cloud is provisional (its full INFO not yet seen by
 * any call on c). spc_wait_ready: waits for that full INFO (calling progress for each PROGRESS,
 * skipping frames) and fills info; returns 1 then, 0 at once when nothing was pending, or a
 * code (SPC_E_LOAD_FAILED when the full preparation failed: the cloud is then closed). */
int spc_open_provisional(const spc_client *c);
int spc_wait_ready(spc_client *c, spc_info *info, spc_progress_fn progress, void *user);

/* ---- camera ------------------------------------------------------------------------------ */

typedef struct spc_camera {
    double eye[3], target[3], up[3]; /* the cloud's file coordinates */
    float fov_deg;                   /* vertical field of view, (0, 180) */
    float znear, zfar;               /* 0: derived by the server from the bounds */
    uint32_t width, height;          /* pixels, 1..16384 (the server may allow less) */
} spc_camera;

/* spc_camera_frame: the cloud's default camera at width x height (fov 45), the same as the
 * server's frame without a camera: looking along info's view direction with its up, from
 * where the view's box fills the frame (its projection centred, 4 % of the frame left free). */
void spc_camera_frame(const spc_info *info, uint32_t width, uint32_t height, spc_camera *cam);

/* spc_camera_orbit: camera i of n on a circle around the view box's centre, about the axis up
 * (NULL: info's world up), 30 degrees above the horizon, starting at the default view's
 * azimuth and turning counter-clockwise seen from above, every camera at the distance where
 * the box fits from all n of them (fov_deg <= 0: 45). */
void spc_camera_orbit(const spc_info *info, const double up[3], int i, int n, float fov_deg,
                      uint32_t width, uint32_t height, spc_camera *cam);

/* spc_set_camera: sends a CAMERA (checked locally first, also against the server's maximum
 * size from WELCOME: SPC_E_BAD_CAMERA). Does not wait for
 * an answer; the server reports a rejected camera as an ERROR that the next waiting call
 * returns. *seq (may be NULL) gets the camera's sequence number (FRAME camera_seq echoes it). */
int spc_set_camera(spc_client *c, const spc_camera *cam, uint32_t *seq);

/* spc_prefetch: tells the server the next cameras of a path (at most 16 are sent; nearest
 * first): for a level-of-detail cloud it reads and uploads the nodes they need ahead, between
 * frames, so those frames find them resident (a later PREFETCH replaces the earlier one). A
 * flat cloud ignores it. Checked locally like spc_set_camera; no answer unless wrong. */
int spc_prefetch(spc_client *c, const spc_camera *cams, int n);

/* ---- parameters (the table in protocol/params.h; `splat --help` lists them) ------------- */

/* spc_set_param: sets one parameter from "key=value" text ("splat_scale=1.5", "light=0,1,1",
 * "pipeline=points"). Validated locally (SPC_E_BAD_PARAM_NAME/VALUE naming the parameter and
 * its range), then sent; waits for the server's OK. */
int spc_set_param(spc_client *c, const char *key_value);
/* spc_set_params: several "key=value" at once; all are applied or none. */
int spc_set_params(spc_client *c, const char *const *key_values, int n);
/* Typed forms: name must be a parameter of that type. */
int spc_set_param_float(spc_client *c, const char *name, float v);
int spc_set_param_int(spc_client *c, const char *name, int64_t v);
int spc_set_param_enum(spc_client *c, const char *name, const char *value);
int spc_set_param_vec3(spc_client *c, const char *name, const float v[3]);
/* spc_get_param: the value this client last set (or the default), as text. 0 or INVALID_ARG. */
int spc_get_param(const spc_client *c, const char *name, char *buf, size_t len);

/* ---- frames ------------------------------------------------------------------------------- */

typedef struct spc_frame {
    uint32_t seq;                /* the RENDER request it answers; 0 for a streamed frame */
    uint32_t camera_seq;         /* the CAMERA it renders (0: the server's default camera) */
    char pipeline[32];           /* "splat", "points", ... */
    char format[16];             /* "jpeg", "png", "lz4", "raw", "exr" */
    uint32_t width, height;
    uint64_t render_us, readback_us, encode_us; /* server-side times, microseconds */
    uint64_t points_drawn;
    uint64_t decode_us;          /* client-side decoding time (0 when not decoded) */
    const uint8_t *data;         /* the encoded bytes as sent (JPEG/PNG/EXR file, SPL4, raw) */
    size_t data_len;
    const uint8_t *rgba;         /* decoded RGBA8, top-down rows, when asked for; else NULL */
    int complete;                /* 1: the view's every wanted node was drawn (always for a flat
                                    cloud); 0: a step of a LOD cloud's progressive refinement */
    int provisional;             /* 1: drawn from a provisional cloud (spc_open), with `points` */
} spc_frame;
/* data and rgba belong to the handle and stay valid until the next call on it.
 *
 * Calls that wait for an answer (spc_open, spc_set_param*, spc_render, spc_stream, spc_ping,
 * spc_list) skip any FRAME that arrives meanwhile: receive the frames of spc_send_render with
 * spc_recv_frame before making such a call, and expect streamed frames to be dropped while
 * one waits (streaming is latest-wins anyway). */

/* spc_render: renders one frame with the current camera and parameters and waits for it.
 * decode = 1 also decodes it to RGBA8 (jpeg, lz4, raw; png/exr give SPC_E_DECODE: ask for
 * those only to save the bytes). Returns 0 or a negative code. */
int spc_render(spc_client *c, spc_frame *f, int decode);

/* spc_send_render: sends CAMERA (when cam is not NULL) and RENDER without waiting, so that
 * several frames can be in flight; *render_seq (may be NULL) gets the RENDER's sequence
 * number, which the answering frame's seq carries. Receive with spc_recv_frame. */
int spc_send_render(spc_client *c, const spc_camera *cam, uint32_t *render_seq);

/* spc_recv_frame: waits for the next FRAME (answered or streamed). A server ERROR returns its
 * code (spc_errseq says which request failed). */
int spc_recv_frame(spc_client *c, spc_frame *f, int decode);

/* spc_stream: on = 1: the server renders and sends a frame whenever the camera or parameters
 * change (latest wins), at most max_fps per second (0: no cap); receive them with
 * spc_recv_frame. on = 0 stops. Waits for the server's OK. */
int spc_stream(spc_client *c, int on, float max_fps);

/* spc_ping: a round trip; *rtt_us (may be NULL) gets its duration in microseconds. */
int spc_ping(spc_client *c, uint64_t *rtt_us);

/* spc_fd: the socket, for callers that poll it alongside other input (e.g. a viewer). */
int spc_fd(const spc_client *c);

#ifdef __cplusplus
}
#endif
