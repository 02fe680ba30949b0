/* proto.c — the splatd wire format: little-endian helpers, header, incremental decoder,
 * one encoder and one parser per message type, cloud-name validation (see proto.h and
 * PROTOCOL.md). Everything that reads network bytes checks the length first. */
#include "proto.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

_Static_assert(sizeof(float) == 4, "f32 on the wire is an IEEE-754 binary32");
_Static_assert(sizeof(double) == 8, "f64 on the wire is an IEEE-754 binary64");
_Static_assert(PROTO_FRAME_FIXED == 4 + 1 + 1 + 2 + 4 + 4 + 4 * 8, "FRAME fixed part");
_Static_assert(PROTO_MAX_PREAUTH <= PROTO_MAX_REQUEST, "pre-auth limit is the tighter one");
_Static_assert(SP_PARAM_COUNT <= 64, "PARAMS changed mask is a u64");

/* ---- names, errors ---------------------------------------------------------------------- */

const char *proto_msg_name(unsigned type)
{
    switch (type) {
#define PROTO_N_(name, val, dir) case val: return #name;
        PROTO_MSG_LIST(PROTO_N_)
#undef PROTO_N_
    }
    return "?";
}

int proto_msg_dir(unsigned type)
{
    switch (type) {
#define PROTO_D_(name, val, dir) case val: return dir;
        PROTO_MSG_LIST(PROTO_D_)
#undef PROTO_D_
    }
    return 0;
}

const char *proto_err_name(int code)
{
    switch (code < 0 ? -code : code) {
#define PROTO_EN_(name, val, fatal, text) case val: return #name;
        PROTO_ERRORS(PROTO_EN_)
#undef PROTO_EN_
    }
    return "UNKNOWN";
}

const char *proto_err_text(int code)
{
    switch (code < 0 ? -code : code) {
#define PROTO_ET_(name, val, fatal, text) case val: return text;
        PROTO_ERRORS(PROTO_ET_)
#undef PROTO_ET_
    case 0: return "success";
    }
    return "unknown error";
}

int proto_err_fatal(int code)
{
    switch (code < 0 ? -code : code) {
#define PROTO_EF_(name, val, fatal, text) case val: return fatal;
        PROTO_ERRORS(PROTO_EF_)
#undef PROTO_EF_
    }
    return 1;
}

int proto_err_from_name(const char *name)
{
#define PROTO_EB_(name_, val, fatal, text) if (!strcmp(name, #name_)) return val;
    PROTO_ERRORS(PROTO_EB_)
#undef PROTO_EB_
    return 0;
}

int proto_errorf(proto_error *e, int code, const char *fmt, ...)
{
    if (e) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(e->msg, sizeof e->msg, fmt, ap);
        va_end(ap);
        e->code = code;
    }
    return -code;
}

/* ---- little-endian helpers ---------------------------------------------------------------- */

void proto_put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

void proto_put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

void proto_put_u64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

void proto_put_f32(uint8_t *p, float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    proto_put_u32(p, u);
}

void proto_put_f64(uint8_t *p, double v)
{
    uint64_t u;
    memcpy(&u, &v, 8);
    proto_put_u64(p, u);
}

uint16_t proto_get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }

uint32_t proto_get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

uint64_t proto_get_u64(const uint8_t *p)
{
    return (uint64_t)proto_get_u32(p) | (uint64_t)proto_get_u32(p + 4) << 32;
}

float proto_get_f32(const uint8_t *p)
{
    uint32_t u = proto_get_u32(p);
    float v;
    memcpy(&v, &u, 4);
    return v;
}

double proto_get_f64(const uint8_t *p)
{
    uint64_t u = proto_get_u64(p);
    double v;
    memcpy(&v, &u, 8);
    return v;
}

/* ---- header ------------------------------------------------------------------------------- */

void proto_put_header(uint8_t *p, const proto_header *h)
{
    proto_put_u32(p, h->magic);
    proto_put_u16(p + 4, h->version);
    proto_put_u16(p + 6, h->type);
    proto_put_u32(p + 8, h->seq);
    proto_put_u32(p + 12, h->len);
}

void proto_get_header(const uint8_t *p, proto_header *h)
{
    h->magic = proto_get_u32(p);
    h->version = proto_get_u16(p + 4);
    h->type = proto_get_u16(p + 6);
    h->seq = proto_get_u32(p + 8);
    h->len = proto_get_u32(p + 12);
}

/* ---- decoder ------------------------------------------------------------------------------ */

void proto_decoder_init(proto_decoder *d, uint8_t accept_dir)
{
    memset(d, 0, sizeof *d);
    d->max_payload = PROTO_MAX_REQUEST;
    d->accept_dir = accept_dir;
}

void proto_decoder_free(proto_decoder *d)
{
    free(d->payload);
    memset(d, 0, sizeof *d);
}

int proto_check_header(const proto_decoder *d, const proto_header *h, proto_error *e)
{
    unsigned long long at = (unsigned long long)d->offset;
    if (h->magic != PROTO_MAGIC)
        return proto_errorf(e, PROTO_E_BAD_MAGIC,
                            "bad magic 0x%08x in the message header at stream byte %llu "
                            "(expected 0x%08x, 'SPLT')", h->magic, at, PROTO_MAGIC);
    if (d->version ? h->version != d->version : h->version == 0)
        return proto_errorf(e, PROTO_E_BAD_VERSION,
                            "message header at stream byte %llu has protocol version %u; "
                            "this connection uses %s%u", at, h->version,
                            d->version ? "" : "a version >= ", d->version ? d->version : 1u);
    int dir = proto_msg_dir(h->type);
    if (!dir)
        return proto_errorf(e, PROTO_E_UNKNOWN_TYPE,
                            "unknown message type %u in the header at stream byte %llu",
                            h->type, at);
    if (d->accept_dir && dir != d->accept_dir)
        return proto_errorf(e, PROTO_E_UNKNOWN_TYPE,
                            "message type %u (%s) at stream byte %llu goes %s, not this way",
                            h->type, proto_msg_name(h->type), at,
                            dir == PROTO_C2S ? "client to server" : "server to client");
    if (d->preauth && h->type != PROTO_MSG_HELLO)
        return proto_errorf(e, PROTO_E_AUTH_REQUIRED,
                            "%s before authentication: only HELLO is accepted until the "
                            "server's WELCOME says authenticated", proto_msg_name(h->type));
    uint32_t limit = d->max_payload ? d->max_payload : PROTO_MAX_REQUEST;
    if (d->preauth && limit > PROTO_MAX_PREAUTH) limit = PROTO_MAX_PREAUTH;
    if (h->len > limit)
        return proto_errorf(e, PROTO_E_TOO_LARGE,
                            "%s payload of %u bytes (header at stream byte %llu) is over the "
                            "limit of %u bytes%s", proto_msg_name(h->type), h->len, at, limit,
                            d->preauth ? " before authentication" : "");
    return 0;
}

int proto_decode(proto_decoder *d, const uint8_t *buf, size_t len, size_t *used, proto_msg *m,
                 proto_error *e)
{
    size_t u = 0;
    *used = 0;
    if (d->failed)
        return proto_errorf(e, d->failed, "the stream stopped at byte %llu after an earlier "
                            "%s error", (unsigned long long)d->offset, proto_err_name(d->failed));
    if (d->hdr_have < PROTO_HEADER_LEN) {
        size_t take = PROTO_HEADER_LEN - d->hdr_have;
        if (take > len) take = len;
        if (take) memcpy(d->hdr + d->hdr_have, buf, take);
        d->hdr_have += (uint32_t)take;
        u += take;
        if (d->hdr_have < PROTO_HEADER_LEN) {
            *used = u;
            return PROTO_NEED_MORE;
        }
        proto_get_header(d->hdr, &d->h);
        int rc = proto_check_header(d, &d->h, e);
        if (rc < 0) {
            d->failed = -rc;
            *used = u;
            return rc;
        }
        d->have = 0;
    }
    size_t take = d->h.len - d->have;
    if (take > len - u) take = len - u;
    if (take && d->have + take > d->cap) {
        /* The buffer grows with the bytes that arrive (doubling, at least PROTO_GROW_MIN, at
         * most the message), never to what a header merely claims before its payload comes. */
        uint64_t want = (uint64_t)d->cap * 2;
        if (want < PROTO_GROW_MIN) want = PROTO_GROW_MIN;
        if (want < (uint64_t)d->have + take) want = (uint64_t)d->have + take;
        if (want > d->h.len) want = d->h.len;
        uint8_t *np = realloc(d->payload, (size_t)want);
        if (!np) {
            d->failed = PROTO_E_NOMEM;
            *used = u;
            return proto_errorf(e, PROTO_E_NOMEM, "cannot allocate %llu bytes for a %s payload "
                                "of %u", (unsigned long long)want, proto_msg_name(d->h.type),
                                d->h.len);
        }
        d->payload = np;
        d->cap = (uint32_t)want;
    }
    if (take) memcpy(d->payload + d->have, buf + u, take);
    d->have += (uint32_t)take;
    u += take;
    *used = u;
    if (d->have < d->h.len) return PROTO_NEED_MORE; /* offset stays at the message start */
    m->h = d->h;
    m->payload = d->payload;
    m->len = d->h.len;
    d->offset += PROTO_HEADER_LEN + (uint64_t)d->h.len;
    d->hdr_have = 0;
    d->have = 0;
    return PROTO_ONE_MSG;
}

/* ---- encoder buffer ----------------------------------------------------------------------- */

void proto_buf_free(proto_buf *b)
{
    free(b->data);
    memset(b, 0, sizeof *b);
}

void proto_buf_consume(proto_buf *b, size_t n)
{
    if (n >= b->len) {
        b->len = 0;
        return;
    }
    memmove(b->data, b->data + n, b->len - n);
    b->len -= n;
}

/* A message being written: payload bytes go after the header reserved at start. */
typedef struct wr {
    proto_buf *b;
    size_t start;
    int rc;                     /* 0, or the first negative code */
} wr;

/* room: grows b so that n more bytes fit; returns the write pointer or NULL (rc set). */
static uint8_t *room(wr *w, size_t n)
{
    if (w->rc) return NULL;
    proto_buf *b = w->b;
    if (b->len + n > b->cap) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap < b->len + n) cap *= 2;
        uint8_t *np = realloc(b->data, cap);
        if (!np) {
            w->rc = -PROTO_E_NOMEM;
            return NULL;
        }
        b->data = np;
        b->cap = cap;
    }
    uint8_t *p = b->data + b->len;
    b->len += n;
    return p;
}

static void w_begin(wr *w, proto_buf *b)
{
    w->b = b;
    w->start = b->len;
    w->rc = 0;
    room(w, PROTO_HEADER_LEN);
}

static void w_u8(wr *w, uint8_t v) { uint8_t *p = room(w, 1); if (p) *p = v; }
static void w_u16(wr *w, uint16_t v) { uint8_t *p = room(w, 2); if (p) proto_put_u16(p, v); }
static void w_u32(wr *w, uint32_t v) { uint8_t *p = room(w, 4); if (p) proto_put_u32(p, v); }
static void w_u64(wr *w, uint64_t v) { uint8_t *p = room(w, 8); if (p) proto_put_u64(p, v); }
static void w_f32(wr *w, float v) { uint8_t *p = room(w, 4); if (p) proto_put_f32(p, v); }
static void w_f64(wr *w, double v) { uint8_t *p = room(w, 8); if (p) proto_put_f64(p, v); }

static void w_bytes(wr *w, const void *src, size_t n)
{
    uint8_t *p = room(w, n);
    if (p && n) memcpy(p, src, n);
}

/* w_str8: a u8-length string of at most max bytes (INVALID_ARG when longer). */
static void w_str8(wr *w, const char *s, size_t max)
{
    size_t n = s ? strlen(s) : 0;
    if (n > max || n > 255) {
        if (!w->rc) w->rc = -PROTO_E_INVALID_ARG;
        return;
    }
    w_u8(w, (uint8_t)n);
    w_bytes(w, s, n);
}

/* w_end: writes the header; on failure rolls b back to where the message began. */
static int w_end(wr *w, unsigned type, uint32_t seq)
{
    proto_buf *b = w->b;
    size_t plen = b->len - w->start - PROTO_HEADER_LEN;
    if (!w->rc && plen > UINT32_MAX) w->rc = -PROTO_E_INVALID_ARG;
    if (w->rc) {
        if (b->len > w->start) b->len = w->start;
        return w->rc;
    }
    proto_header h = {PROTO_MAGIC, b->version ? b->version : (uint16_t)PROTO_VERSION,
                      (uint16_t)type, seq, (uint32_t)plen};
    proto_put_header(b->data + w->start, &h);
    return 0;
}

/* ---- payload reader ----------------------------------------------------------------------- */

typedef struct rd {
    const uint8_t *p;
    uint32_t len, off;
    const char *msg;            /* message name for error sentences */
    proto_error *e;
    int rc;
} rd;

static void r_init(rd *r, const uint8_t *p, uint32_t len, const char *msg, proto_error *e)
{
    r->p = p;
    r->len = len;
    r->off = 0;
    r->msg = msg;
    r->e = e;
    r->rc = 0;
}

/* need: 1 when n bytes are left for field; else records TRUNCATED (once) and returns 0. */
static int need(rd *r, uint32_t n, const char *field)
{
    if (r->rc) return 0;
    if (r->len - r->off < n) {
        r->rc = proto_errorf(r->e, PROTO_E_TRUNCATED,
                             "%s payload truncated: field '%s' needs %u bytes at offset %u, "
                             "%u left", r->msg, field, n, r->off, r->len - r->off);
        return 0;
    }
    return 1;
}

static uint8_t r_u8(rd *r, const char *f)
{
    if (!need(r, 1, f)) return 0;
    return r->p[r->off++];
}

static uint16_t r_u16(rd *r, const char *f)
{
    if (!need(r, 2, f)) return 0;
    r->off += 2;
    return proto_get_u16(r->p + r->off - 2);
}

static uint32_t r_u32(rd *r, const char *f)
{
    if (!need(r, 4, f)) return 0;
    r->off += 4;
    return proto_get_u32(r->p + r->off - 4);
}

static uint64_t r_u64(rd *r, const char *f)
{
    if (!need(r, 8, f)) return 0;
    r->off += 8;
    return proto_get_u64(r->p + r->off - 8);
}

static float r_f32(rd *r, const char *f)
{
    if (!need(r, 4, f)) return 0;
    r->off += 4;
    return proto_get_f32(r->p + r->off - 4);
}

static double r_f64(rd *r, const char *f)
{
    if (!need(r, 8, f)) return 0;
    r->off += 8;
    return proto_get_f64(r->p + r->off - 8);
}

static void r_bytes(rd *r, void *out, uint32_t n, const char *f)
{
    if (!need(r, n, f)) return;
    if (n) memcpy(out, r->p + r->off, n);
    r->off += n;
}

/* r_fail: records a non-truncation error (once). */
static void r_fail(rd *r, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void r_fail(rd *r, int code, const char *fmt, ...)
{
    if (r->rc) return;
    if (r->e) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(r->e->msg, sizeof r->e->msg, fmt, ap);
        va_end(ap);
        r->e->code = code;
    }
    r->rc = -code;
}

/* r_strn: a string of n bytes into out (cap >= n + 1), NUL-terminated; MALFORMED on a NUL. */
static void r_strn(rd *r, char *out, uint32_t n, const char *f)
{
    uint32_t at = r->off;
    out[0] = 0;
    if (!need(r, n, f)) return;
    if (n && memchr(r->p + r->off, 0, n)) {
        r_fail(r, PROTO_E_MALFORMED, "%s field '%s' at offset %u contains a NUL byte", r->msg,
               f, at);
        return;
    }
    if (n) memcpy(out, r->p + r->off, n);
    out[n] = 0;
    r->off += n;
}

/* r_str8: a u8-length string of at most max bytes. */
static void r_str8(rd *r, char *out, uint32_t max, const char *f)
{
    uint32_t at = r->off;
    uint8_t n = r_u8(r, f);
    out[0] = 0;
    if (r->rc) return;
    if (n > max) {
        r_fail(r, PROTO_E_MALFORMED, "%s field '%s' at offset %u is %u bytes long; the limit "
               "is %u", r->msg, f, at, n, max);
        return;
    }
    r_strn(r, out, n, f);
}

/* r_end: the parse result: the first error, or MALFORMED for trailing bytes, or 0. */
static int r_end(rd *r)
{
    if (r->rc) return r->rc;
    if (r->off != r->len)
        r_fail(r, PROTO_E_MALFORMED, "%s payload has %u unexpected bytes after its last field "
               "(offset %u of %u)", r->msg, r->len - r->off, r->off, r->len);
    return r->rc;
}

/* ---- simple messages ---------------------------------------------------------------------- */

int proto_enc_empty(proto_buf *b, unsigned type, uint32_t seq)
{
    if (type != PROTO_MSG_LIST && type != PROTO_MSG_RENDER && type != PROTO_MSG_BYE &&
        type != PROTO_MSG_OK)
        return -PROTO_E_INVALID_ARG;
    wr w;
    w_begin(&w, b);
    return w_end(&w, type, seq);
}

int proto_parse_empty(unsigned type, uint32_t len, proto_error *e)
{
    if (len)
        return proto_errorf(e, PROTO_E_MALFORMED, "%s has no payload, but the header says %u "
                            "bytes", proto_msg_name(type), len);
    return 0;
}

int proto_enc_hello(proto_buf *b, uint32_t seq, const proto_hello *m)
{
    if (m->proof_len != 0 && m->proof_len != PROTO_AUTH_LEN) return -PROTO_E_INVALID_ARG;
    wr w;
    w_begin(&w, b);
    w_u16(&w, m->min_version);
    w_u16(&w, m->max_version);
    w_str8(&w, m->client, PROTO_MAX_CLIENT);
    w_u8(&w, m->proof_len);
    w_bytes(&w, m->proof, m->proof_len);
    return w_end(&w, PROTO_MSG_HELLO, seq);
}

int proto_parse_hello(const uint8_t *pl, uint32_t len, proto_hello *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "HELLO", e);
    memset(m, 0, sizeof *m);
    m->min_version = r_u16(&r, "min_version");
    m->max_version = r_u16(&r, "max_version");
    r_str8(&r, m->client, PROTO_MAX_CLIENT, "client");
    m->proof_len = r_u8(&r, "proof_len");
    if (!r.rc && m->proof_len != 0 && m->proof_len != PROTO_AUTH_LEN)
        r_fail(&r, PROTO_E_MALFORMED, "HELLO proof_len is %u; it must be 0 or %u",
               m->proof_len, PROTO_AUTH_LEN);
    r_bytes(&r, m->proof, m->proof_len, "proof");
    if (!r.rc && (m->min_version == 0 || m->min_version > m->max_version))
        r_fail(&r, PROTO_E_MALFORMED, "HELLO version range [%u, %u] is empty or starts at 0",
               m->min_version, m->max_version);
    return r_end(&r);
}

int proto_pick_version(uint16_t min, uint16_t max, proto_error *e)
{
    uint16_t hi = max < PROTO_VERSION_MAX ? max : (uint16_t)PROTO_VERSION_MAX;
    uint16_t lo = min > PROTO_VERSION_MIN ? min : (uint16_t)PROTO_VERSION_MIN;
    if (min == 0 || min > max || lo > hi)
        return proto_errorf(e, PROTO_E_BAD_VERSION, "client speaks protocol versions [%u, %u], "
                            "this side speaks [%u, %u]", min, max, PROTO_VERSION_MIN,
                            PROTO_VERSION_MAX);
    return hi;
}

int proto_enc_open(proto_buf *b, uint32_t seq, const char *name)
{
    wr w;
    w_begin(&w, b);
    w_str8(&w, name, PROTO_MAX_NAME);
    return w_end(&w, PROTO_MSG_OPEN, seq);
}

int proto_name_check(const char *name, proto_error *e)
{
    size_t n = strlen(name);
    if (n == 0 || n > PROTO_MAX_NAME)
        return proto_errorf(e, PROTO_E_BAD_NAME, "cloud name of %zu bytes: a name has 1 to %u "
                            "bytes", n, PROTO_MAX_NAME);
    if (name[0] == '.' || name[0] == ' ')
        return proto_errorf(e, PROTO_E_BAD_NAME, "cloud name '%s' starts with '%c'; names are "
                            "plain file names in the data directory", name, name[0]);
    if (name[n - 1] == ' ')
        return proto_errorf(e, PROTO_E_BAD_NAME, "cloud name '%s' ends with a space", name);
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)name[i];
        if (c == '/' || c == '\\' || c == ':')
            return proto_errorf(e, PROTO_E_BAD_NAME, "cloud name '%s' contains '%c' at byte "
                                "%zu; names are file names in the data directory, never paths",
                                name, c, i);
        if (c < 0x20 || c == 0x7f)
            return proto_errorf(e, PROTO_E_BAD_NAME, "cloud name contains control byte 0x%02x "
                                "at byte %zu", c, i);
    }
    return 0;
}

int proto_parse_open(const uint8_t *pl, uint32_t len, char name[PROTO_MAX_NAME + 1],
                     proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "OPEN", e);
    r_str8(&r, name, PROTO_MAX_NAME, "name");
    int rc = r_end(&r);
    if (rc) return rc;
    return proto_name_check(name, e);
}

/* ---- CAMERA ------------------------------------------------------------------------------- */

static void w_camera(wr *w, const proto_camera *m)
{
    for (int i = 0; i < 3; i++) w_f64(w, m->eye[i]);
    for (int i = 0; i < 3; i++) w_f64(w, m->target[i]);
    for (int i = 0; i < 3; i++) w_f64(w, m->up[i]);
    w_f32(w, m->fov_deg);
    w_f32(w, m->znear);
    w_f32(w, m->zfar);
    w_u32(w, m->width);
    w_u32(w, m->height);
}

int proto_enc_camera(proto_buf *b, uint32_t seq, const proto_camera *m)
{
    wr w;
    w_begin(&w, b);
    w_camera(&w, m);
    return w_end(&w, PROTO_MSG_CAMERA, seq);
}

int proto_enc_prefetch(proto_buf *b, uint32_t seq, const proto_prefetch *m)
{
    if (m->count < 1 || m->count > PROTO_MAX_PREFETCH) return -PROTO_E_INVALID_ARG;
    wr w;
    w_begin(&w, b);
    w_u8(&w, m->count);
    for (unsigned k = 0; k < m->count; k++) w_camera(&w, &m->cams[k]);
    return w_end(&w, PROTO_MSG_PREFETCH, seq);
}

/* camera_check: the geometric checks of a CAMERA; 0 or -BAD_CAMERA with e filled. */
static int camera_check(const proto_camera *m, proto_error *e)
{
    const double *v[3] = {m->eye, m->target, m->up};
    static const char *nm[3] = {"eye", "target", "up"};
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < 3; i++)
            if (!isfinite(v[k][i]))
                return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA %s[%d] is not finite",
                                    nm[k], i);
            else if (fabs(v[k][i]) > PROTO_MAX_COORD)
                /* Checked before any arithmetic: 1e308 - 0 squared is infinite, which would
                 * otherwise be reported as "eye and target are the same point". */
                return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA %s[%d] = %g is out of range: "
                                    "coordinates are at most %g in magnitude", nm[k], i,
                                    v[k][i], PROTO_MAX_COORD);
    if (!isfinite(m->fov_deg) || !(m->fov_deg > 0.0f && m->fov_deg < 180.0f))
        return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA fov %g is out of range (0, 180) "
                            "degrees", (double)m->fov_deg);
    if (!isfinite(m->znear) || !isfinite(m->zfar) || m->znear < 0 || m->zfar < 0 ||
        (m->znear > 0 && m->zfar > 0 && !(m->znear < m->zfar)))
        return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA near %g / far %g: each is 0 "
                            "(derive) or positive, and near < far", (double)m->znear,
                            (double)m->zfar);
    if (m->width < 1 || m->width > PROTO_MAX_DIM || m->height < 1 || m->height > PROTO_MAX_DIM)
        return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA size %ux%u is out of range: width "
                            "and height are 1 to %u", m->width, m->height, PROTO_MAX_DIM);
    double d[3], c[3];
    for (int i = 0; i < 3; i++) d[i] = m->target[i] - m->eye[i];
    c[0] = d[1] * m->up[2] - d[2] * m->up[1];
    c[1] = d[2] * m->up[0] - d[0] * m->up[2];
    c[2] = d[0] * m->up[1] - d[1] * m->up[0];
    double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double ul = sqrt(m->up[0] * m->up[0] + m->up[1] * m->up[1] + m->up[2] * m->up[2]);
    double cl = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(dl > 0) || !isfinite(dl))
        return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA eye and target are the same point");
    /* sin(angle between view direction and up) below 1e-6: no usable right vector */
    if (!(ul > 0) || !(cl > 1e-6 * dl * ul))
        return proto_errorf(e, PROTO_E_BAD_CAMERA, "CAMERA up (%g, %g, %g) is zero or parallel "
                            "to the view direction", m->up[0], m->up[1], m->up[2]);
    return 0;
}

static void r_camera(rd *r, proto_camera *m)
{
    memset(m, 0, sizeof *m);
    static const char *fe[3] = {"eye.x", "eye.y", "eye.z"};
    static const char *ft[3] = {"target.x", "target.y", "target.z"};
    static const char *fu[3] = {"up.x", "up.y", "up.z"};
    for (int i = 0; i < 3; i++) m->eye[i] = r_f64(r, fe[i]);
    for (int i = 0; i < 3; i++) m->target[i] = r_f64(r, ft[i]);
    for (int i = 0; i < 3; i++) m->up[i] = r_f64(r, fu[i]);
    m->fov_deg = r_f32(r, "fov");
    m->znear = r_f32(r, "near");
    m->zfar = r_f32(r, "far");
    m->width = r_u32(r, "width");
    m->height = r_u32(r, "height");
}

int proto_parse_camera(const uint8_t *pl, uint32_t len, proto_camera *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "CAMERA", e);
    r_camera(&r, m);
    int rc = r_end(&r);
    if (rc) return rc;
    return camera_check(m, e);
}

int proto_parse_prefetch(const uint8_t *pl, uint32_t len, proto_prefetch *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "PREFETCH", e);
    m->count = r_u8(&r, "count");
    if (!r.rc && (m->count < 1 || m->count > PROTO_MAX_PREFETCH))
        return proto_errorf(e, PROTO_E_MALFORMED, "PREFETCH count %u is outside 1..%u",
                            m->count, PROTO_MAX_PREFETCH);
    for (unsigned k = 0; k < m->count && !r.rc; k++) r_camera(&r, &m->cams[k]);
    int rc = r_end(&r);
    if (rc) return rc;
    for (unsigned k = 0; k < m->count; k++) {
        proto_error ce = {0};
        if ((rc = camera_check(&m->cams[k], &ce)) < 0)
            return proto_errorf(e, -rc, "PREFETCH camera %u: %s", k, ce.msg);
    }
    return 0;
}

/* ---- PARAMS ------------------------------------------------------------------------------- */

/* param_ptr: the field of parameter id in p (from the same X-macro list as params.c). */
static void *param_ptr(sp_params *p, int id)
{
    switch (id) {
#define PROTO_PP_(id_, name, type, field, lo, hi, def, vals) case SP_##id_: return &p->field;
        SP_PARAM_LIST(PROTO_PP_)
#undef PROTO_PP_
    }
    return NULL;
}

static unsigned value_size(unsigned type)
{
    switch (type) {
    case SP_T_ENUM: return 4;
    case SP_T_FLOAT: return 4;
    case SP_T_INT: return 8;
    case SP_T_VEC3: return 12;
    }
    return 0;
}

static const char *type_name(unsigned type)
{
    switch (type) {
    case SP_T_ENUM: return "enum";
    case SP_T_FLOAT: return "float";
    case SP_T_INT: return "int";
    case SP_T_VEC3: return "vec3";
    }
    return "?";
}

static int enum_count(const char *values)
{
    int n = 1;
    for (const char *s = values; *s; s++) n += *s == '|';
    return n;
}

void proto_param_rec_from(const sp_params *p, int id, proto_param_rec *r)
{
    memset(r, 0, sizeof *r);
    if (id < 0 || id >= SP_PARAM_COUNT) return;
    const sp_param_info *in = &sp_param_table[id];
    const void *f = param_ptr((sp_params *)p, id);
    snprintf(r->name, sizeof r->name, "%s", in->name);
    r->type = (uint8_t)in->type;
    switch (in->type) {
    case SP_T_ENUM: memcpy(&r->u.e, f, 4); break;
    case SP_T_FLOAT: memcpy(&r->u.f, f, 4); break;
    case SP_T_INT: memcpy(&r->u.i, f, 8); break;
    case SP_T_VEC3: memcpy(r->u.v, f, 12); break;
    }
}

int proto_enc_params(proto_buf *b, uint32_t seq, const proto_param_rec *recs, unsigned n)
{
    if (n > PROTO_MAX_PARAMS) return -PROTO_E_INVALID_ARG;
    wr w;
    w_begin(&w, b);
    w_u16(&w, (uint16_t)n);
    for (unsigned i = 0; i < n; i++) {
        const proto_param_rec *r = &recs[i];
        w_str8(&w, r->name, sizeof r->name - 1);
        w_u8(&w, r->type);
        switch (r->type) {
        case SP_T_ENUM: w_u32(&w, (uint32_t)r->u.e); break;
        case SP_T_FLOAT: w_f32(&w, r->u.f); break;
        case SP_T_INT: w_u64(&w, (uint64_t)r->u.i); break;
        case SP_T_VEC3: for (int k = 0; k < 3; k++) w_f32(&w, r->u.v[k]); break;
        default: if (!w.rc) w.rc = -PROTO_E_INVALID_ARG;
        }
    }
    return w_end(&w, PROTO_MSG_PARAMS, seq);
}

/* param_apply: validates record r against the table and stores it in p. 0 or -code. */
static int param_apply(const proto_param_rec *r, unsigned idx, sp_params *p, uint64_t *changed,
                       proto_error *e)
{
    int id = sp_param_find(r->name);
    if (id < 0)
        return proto_errorf(e, PROTO_E_BAD_PARAM_NAME, "PARAMS record %u: unknown parameter "
                            "'%s'", idx, r->name);
    const sp_param_info *in = &sp_param_table[id];
    char range[200];
    if (in->type == SP_T_ENUM) snprintf(range, sizeof range, "one of %s", in->values);
    else snprintf(range, sizeof range, "range [%g, %g]", in->min, in->max);
    if (r->type != in->type)
        return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "parameter '%s' is a %s (%s); PARAMS "
                            "record %u sends a %s", in->name, type_name(in->type), range, idx,
                            type_name(r->type));
    void *f = param_ptr(p, id);
    switch (in->type) {
    case SP_T_ENUM:
        if (r->u.e < 0 || r->u.e >= enum_count(in->values))
            return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "parameter '%s': value index %d is "
                                "not one of %s (0 to %d)", in->name, (int)r->u.e, in->values,
                                enum_count(in->values) - 1);
        memcpy(f, &r->u.e, 4);
        break;
    case SP_T_FLOAT:
        /* compared as floats: the table's 0.01 is below the float 0.01f a client stores */
        if (!isfinite(r->u.f) || r->u.f < (float)in->min || r->u.f > (float)in->max)
            return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "parameter '%s': %g is out of %s",
                                in->name, (double)r->u.f, range);
        memcpy(f, &r->u.f, 4);
        break;
    case SP_T_INT:
        if ((double)r->u.i < in->min || (double)r->u.i > in->max)
            return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "parameter '%s': %lld is out of %s",
                                in->name, (long long)r->u.i, range);
        memcpy(f, &r->u.i, 8);
        break;
    case SP_T_VEC3:
        for (int k = 0; k < 3; k++)
            if (!isfinite(r->u.v[k]) || r->u.v[k] < (float)in->min || r->u.v[k] > (float)in->max)
                return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "parameter '%s': component %d "
                                    "(%g) is out of %s", in->name, k, (double)r->u.v[k], range);
        memcpy(f, r->u.v, 12);
        break;
    }
    if (changed) *changed |= 1ull << id;
    return 0;
}

int proto_param_apply(const proto_param_rec *r, sp_params *p, uint64_t *changed,
                      proto_error *e)
{
    return param_apply(r, 0, p, changed, e);
}

int proto_parse_params(const uint8_t *pl, uint32_t len, sp_params *p, uint64_t *changed,
                       proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "PARAMS", e);
    uint16_t n = r_u16(&r, "count");
    if (!r.rc && n > PROTO_MAX_PARAMS)
        r_fail(&r, PROTO_E_MALFORMED, "PARAMS count %u is over the limit of %u records", n,
               PROTO_MAX_PARAMS);
    sp_params tmp = *p;
    uint64_t ch = 0;
    for (unsigned i = 0; i < n && !r.rc; i++) {
        proto_param_rec rec;
        memset(&rec, 0, sizeof rec);
        char name[256];
        r_str8(&r, name, 255, "name");
        rec.type = r_u8(&r, "type");
        if (r.rc) break;
        unsigned vs = value_size(rec.type);
        if (!vs) {
            r_fail(&r, PROTO_E_MALFORMED, "PARAMS record %u ('%s'): unknown value type %u at "
                   "offset %u", i, name, rec.type, r.off - 1);
            break;
        }
        switch (rec.type) {
        case SP_T_ENUM: rec.u.e = (int32_t)r_u32(&r, "value"); break;
        case SP_T_FLOAT: rec.u.f = r_f32(&r, "value"); break;
        case SP_T_INT: rec.u.i = (int64_t)r_u64(&r, "value"); break;
        case SP_T_VEC3: for (int k = 0; k < 3; k++) rec.u.v[k] = r_f32(&r, "value"); break;
        }
        if (r.rc) break;
        if (strlen(name) >= sizeof rec.name) {
            r.rc = proto_errorf(e, PROTO_E_BAD_PARAM_NAME, "PARAMS record %u: unknown "
                                "parameter '%.60s...' (%zu bytes)", i, name, strlen(name));
            break;
        }
        memcpy(rec.name, name, strlen(name) + 1);
        int rc = param_apply(&rec, i, &tmp, &ch, e);
        if (rc) r.rc = rc;
    }
    int rc = r_end(&r);
    if (rc) return rc;
    *p = tmp;
    if (changed) *changed = ch;
    return 0;
}

/* ---- STREAM, PING, PONG ------------------------------------------------------------------- */

int proto_enc_stream(proto_buf *b, uint32_t seq, const proto_stream *m)
{
    wr w;
    w_begin(&w, b);
    w_u8(&w, m->on);
    w_f32(&w, m->max_fps);
    return w_end(&w, PROTO_MSG_STREAM, seq);
}

int proto_parse_stream(const uint8_t *pl, uint32_t len, proto_stream *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "STREAM", e);
    m->on = r_u8(&r, "on");
    m->max_fps = r_f32(&r, "max_fps");
    int rc = r_end(&r);
    if (rc) return rc;
    if (m->on > 1)
        return proto_errorf(e, PROTO_E_MALFORMED, "STREAM on is %u; it must be 0 or 1", m->on);
    if (!isfinite(m->max_fps) || m->max_fps < 0 || m->max_fps > 1000)
        return proto_errorf(e, PROTO_E_BAD_PARAM_VALUE, "STREAM max_fps %g is out of range "
                            "[0, 1000] (0 = no cap)", (double)m->max_fps);
    return 0;
}

int proto_enc_ping(proto_buf *b, uint32_t seq, const proto_ping *m)
{
    wr w;
    w_begin(&w, b);
    w_u64(&w, m->token);
    return w_end(&w, PROTO_MSG_PING, seq);
}

int proto_parse_ping(const uint8_t *pl, uint32_t len, proto_ping *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "PING", e);
    m->token = r_u64(&r, "token");
    return r_end(&r);
}

int proto_enc_pong(proto_buf *b, uint32_t seq, const proto_pong *m)
{
    wr w;
    w_begin(&w, b);
    w_u64(&w, m->token);
    w_u64(&w, m->server_us);
    return w_end(&w, PROTO_MSG_PONG, seq);
}

int proto_parse_pong(const uint8_t *pl, uint32_t len, proto_pong *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "PONG", e);
    m->token = r_u64(&r, "token");
    m->server_us = r_u64(&r, "server_us");
    return r_end(&r);
}

/* ---- WELCOME, CLOUDS, INFO, PROGRESS ------------------------------------------------------ */

int proto_enc_welcome(proto_buf *b, uint32_t seq, const proto_welcome *m)
{
    wr w;
    w_begin(&w, b);
    w_u16(&w, m->version);
    w_u8(&w, m->auth_required);
    w_u8(&w, m->authenticated);
    w_bytes(&w, m->challenge, PROTO_AUTH_LEN);
    w_u32(&w, m->max_request);
    w_u32(&w, m->max_width);
    w_u32(&w, m->max_height);
    w_str8(&w, m->server, PROTO_MAX_NAME);
    w_str8(&w, m->backend, PROTO_MAX_NAME);
    w_str8(&w, m->renderer, PROTO_MAX_NAME);
    return w_end(&w, PROTO_MSG_WELCOME, seq);
}

int proto_parse_welcome(const uint8_t *pl, uint32_t len, proto_welcome *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "WELCOME", e);
    memset(m, 0, sizeof *m);
    m->version = r_u16(&r, "version");
    m->auth_required = r_u8(&r, "auth_required");
    m->authenticated = r_u8(&r, "authenticated");
    r_bytes(&r, m->challenge, PROTO_AUTH_LEN, "challenge");
    m->max_request = r_u32(&r, "max_request");
    m->max_width = r_u32(&r, "max_width");
    m->max_height = r_u32(&r, "max_height");
    r_str8(&r, m->server, PROTO_MAX_NAME, "server");
    r_str8(&r, m->backend, PROTO_MAX_NAME, "backend");
    r_str8(&r, m->renderer, PROTO_MAX_NAME, "renderer");
    int rc = r_end(&r);
    if (rc) return rc;
    if (m->auth_required > 1 || m->authenticated > 1 || m->version == 0)
        return proto_errorf(e, PROTO_E_MALFORMED, "WELCOME flags auth_required=%u "
                            "authenticated=%u version=%u are not valid", m->auth_required,
                            m->authenticated, m->version);
    return 0;
}

enum { CLOUD_ENTRY_MIN = 1 + 8 + 8 + 4 };

int proto_enc_clouds(proto_buf *b, uint32_t seq, const proto_cloud_entry *items, uint32_t n)
{
    wr w;
    w_begin(&w, b);
    w_u32(&w, n);
    for (uint32_t i = 0; i < n; i++) {
        w_str8(&w, items[i].name, PROTO_MAX_NAME);
        w_u64(&w, items[i].bytes);
        w_u64(&w, items[i].points);
        w_u32(&w, items[i].flags);
    }
    return w_end(&w, PROTO_MSG_CLOUDS, seq);
}

int proto_parse_clouds(const uint8_t *pl, uint32_t len, proto_clouds *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "CLOUDS", e);
    memset(m, 0, sizeof *m);
    uint32_t n = r_u32(&r, "count");
    if (r.rc) return r.rc;
    /* every entry takes at least CLOUD_ENTRY_MIN bytes: bound the count before allocating */
    if (n > (len - r.off) / CLOUD_ENTRY_MIN)
        return proto_errorf(e, PROTO_E_TRUNCATED, "CLOUDS count %u needs at least %llu bytes "
                            "of entries, the payload has %u", n,
                            (unsigned long long)n * CLOUD_ENTRY_MIN, len - r.off);
    if (n) {
        m->items = calloc(n, sizeof *m->items);
        if (!m->items) return proto_errorf(e, PROTO_E_NOMEM, "CLOUDS: out of memory");
    }
    m->count = n;
    for (uint32_t i = 0; i < n && !r.rc; i++) {
        proto_cloud_entry *c = &m->items[i];
        r_str8(&r, c->name, PROTO_MAX_NAME, "name");
        c->bytes = r_u64(&r, "bytes");
        c->points = r_u64(&r, "points");
        c->flags = r_u32(&r, "flags");
    }
    int rc = r_end(&r);
    if (rc) proto_clouds_free(m);
    return rc;
}

void proto_clouds_free(proto_clouds *m)
{
    free(m->items);
    m->items = NULL;
    m->count = 0;
}

int proto_enc_info(proto_buf *b, uint32_t seq, const proto_info *m)
{
    wr w;
    w_begin(&w, b);
    w_str8(&w, m->name, PROTO_MAX_NAME);
    w_u64(&w, m->points);
    w_u64(&w, m->dropped);
    for (int i = 0; i < 3; i++) w_f64(&w, m->bmin[i]);
    for (int i = 0; i < 3; i++) w_f64(&w, m->bmax[i]);
    for (int i = 0; i < 3; i++) w_f64(&w, m->offset[i]);
    w_u32(&w, m->attrs);
    w_f32(&w, m->sigma);
    w_u32(&w, m->k);
    w_str8(&w, m->format, PROTO_MAX_NAME);
    for (int i = 0; i < 3; i++) w_f64(&w, m->view.up[i]);
    for (int i = 0; i < 3; i++) w_f64(&w, m->view.dir[i]);
    for (int i = 0; i < 3; i++) w_f64(&w, m->view.bmin[i]);
    for (int i = 0; i < 3; i++) w_f64(&w, m->view.bmax[i]);
    uint32_t np = m->view.npts <= SP_VIEW_PTS ? m->view.npts : SP_VIEW_PTS;
    w_u8(&w, (uint8_t)np);
    for (uint32_t k = 0; k < np; k++)
        for (int i = 0; i < 3; i++) w_f64(&w, m->view.pts[k][i]);
    return w_end(&w, PROTO_MSG_INFO, seq);
}

/* view_ok: 1 when v can frame a camera (proto_parse_info's check of INFO's view). */
static int view_ok(const sp_view *v)
{
    double uu = 0, dd = 0, ud = 0;
    for (int i = 0; i < 3; i++) {
        if (!isfinite(v->up[i]) || !isfinite(v->dir[i]) || !isfinite(v->bmin[i]) ||
            !isfinite(v->bmax[i]) || !(v->bmin[i] <= v->bmax[i]) ||
            fabs(v->bmin[i]) > PROTO_MAX_COORD || fabs(v->bmax[i]) > PROTO_MAX_COORD)
            return 0;
        uu += v->up[i] * v->up[i], dd += v->dir[i] * v->dir[i], ud += v->up[i] * v->dir[i];
    }
    for (uint32_t k = 0; k < v->npts; k++)
        for (int i = 0; i < 3; i++)
            if (!isfinite(v->pts[k][i]) || fabs(v->pts[k][i]) > PROTO_MAX_COORD) return 0;
    return uu > 1e-12 && dd > 1e-12 && uu * dd - ud * ud > 1e-12 * uu * dd;
}

int proto_parse_info(const uint8_t *pl, uint32_t len, proto_info *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "INFO", e);
    memset(m, 0, sizeof *m);
    r_str8(&r, m->name, PROTO_MAX_NAME, "name");
    m->points = r_u64(&r, "points");
    m->dropped = r_u64(&r, "dropped");
    for (int i = 0; i < 3; i++) m->bmin[i] = r_f64(&r, "bmin");
    for (int i = 0; i < 3; i++) m->bmax[i] = r_f64(&r, "bmax");
    for (int i = 0; i < 3; i++) m->offset[i] = r_f64(&r, "offset");
    m->attrs = r_u32(&r, "attrs");
    m->sigma = r_f32(&r, "sigma");
    m->k = r_u32(&r, "k");
    r_str8(&r, m->format, PROTO_MAX_NAME, "format");
    uint32_t at = r.off;
    for (int i = 0; i < 3; i++) m->view.up[i] = r_f64(&r, "view_up");
    for (int i = 0; i < 3; i++) m->view.dir[i] = r_f64(&r, "view_dir");
    for (int i = 0; i < 3; i++) m->view.bmin[i] = r_f64(&r, "view_bmin");
    for (int i = 0; i < 3; i++) m->view.bmax[i] = r_f64(&r, "view_bmax");
    uint32_t at_n = r.off;
    m->view.npts = r_u8(&r, "view_npts");
    if (!r.rc && m->view.npts > SP_VIEW_PTS)
        r_fail(&r, PROTO_E_MALFORMED, "INFO view_npts at offset %u is %u; the limit is %u", at_n,
               m->view.npts, (unsigned)SP_VIEW_PTS);
    for (uint32_t k = 0; k < m->view.npts && !r.rc; k++)
        for (int i = 0; i < 3; i++) m->view.pts[k][i] = r_f64(&r, "view_pts");
    if (!r.rc && !view_ok(&m->view))
        r_fail(&r, PROTO_E_MALFORMED, "INFO view at offset %u is not a view: up and dir must be "
               "finite, non-zero and not parallel, the box and points finite with bmin <= bmax",
               at);
    return r_end(&r);
}

int proto_enc_progress(proto_buf *b, uint32_t seq, const proto_progress *m)
{
    wr w;
    w_begin(&w, b);
    w_u8(&w, m->phase);
    w_f32(&w, m->fraction);
    w_str8(&w, m->text, PROTO_MAX_NAME);
    return w_end(&w, PROTO_MSG_PROGRESS, seq);
}

int proto_parse_progress(const uint8_t *pl, uint32_t len, proto_progress *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "PROGRESS", e);
    memset(m, 0, sizeof *m);
    m->phase = r_u8(&r, "phase");
    m->fraction = r_f32(&r, "fraction");
    r_str8(&r, m->text, PROTO_MAX_NAME, "text");
    int rc = r_end(&r);
    if (rc) return rc;
    if (m->phase >= PROTO_PHASE_COUNT || !(m->fraction >= 0 && m->fraction <= 1))
        return proto_errorf(e, PROTO_E_MALFORMED, "PROGRESS phase %u / fraction %g out of "
                            "range (phase < %d, fraction in [0, 1])", m->phase,
                            (double)m->fraction, PROTO_PHASE_COUNT);
    return 0;
}

/* ---- FRAME, ERROR ------------------------------------------------------------------------- */

static void frame_fixed(uint8_t *p, const proto_frame *m)
{
    proto_put_u32(p, m->camera_seq);
    p[4] = m->pipeline;
    p[5] = m->format;
    proto_put_u16(p + 6, m->flags);
    proto_put_u32(p + 8, m->width);
    proto_put_u32(p + 12, m->height);
    proto_put_u64(p + 16, m->render_us);
    proto_put_u64(p + 24, m->readback_us);
    proto_put_u64(p + 32, m->encode_us);
    proto_put_u64(p + 40, m->points_drawn);
}

int proto_frame_fits(uint64_t data_len)
{
    return data_len <= (uint64_t)PROTO_MAX_FRAME - PROTO_FRAME_FIXED;
}

void proto_frame_head(uint8_t out[PROTO_FRAME_HEAD_LEN], uint16_t version, uint32_t seq,
                      const proto_frame *m)
{
    proto_header h = {PROTO_MAGIC, version ? version : (uint16_t)PROTO_VERSION,
                      PROTO_MSG_FRAME, seq, PROTO_FRAME_FIXED + m->data_len};
    proto_put_header(out, &h);
    frame_fixed(out + PROTO_HEADER_LEN, m);
}

int proto_enc_frame(proto_buf *b, uint32_t seq, const proto_frame *m)
{
    if (m->data_len > UINT32_MAX - PROTO_FRAME_FIXED) return -PROTO_E_INVALID_ARG;
    wr w;
    w_begin(&w, b);
    uint8_t *p = room(&w, PROTO_FRAME_FIXED);
    if (p) frame_fixed(p, m);
    w_bytes(&w, m->data, m->data_len);
    return w_end(&w, PROTO_MSG_FRAME, seq);
}

int proto_parse_frame(const uint8_t *pl, uint32_t len, proto_frame *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "FRAME", e);
    memset(m, 0, sizeof *m);
    m->camera_seq = r_u32(&r, "camera_seq");
    m->pipeline = r_u8(&r, "pipeline");
    m->format = r_u8(&r, "format");
    m->flags = r_u16(&r, "flags");
    m->width = r_u32(&r, "width");
    m->height = r_u32(&r, "height");
    m->render_us = r_u64(&r, "render_us");
    m->readback_us = r_u64(&r, "readback_us");
    m->encode_us = r_u64(&r, "encode_us");
    m->points_drawn = r_u64(&r, "points_drawn");
    if (r.rc) return r.rc;
    m->data = pl + r.off;
    m->data_len = len - r.off;
    if (m->format >= enum_count(sp_param_table[SP_FORMAT].values) ||
        m->pipeline >= enum_count(sp_param_table[SP_PIPELINE].values))
        return proto_errorf(e, PROTO_E_MALFORMED, "FRAME format %u / pipeline %u is not a "
                            "known index (%s; %s)", m->format, m->pipeline,
                            sp_param_table[SP_FORMAT].values, sp_param_table[SP_PIPELINE].values);
    if (m->width < 1 || m->width > PROTO_MAX_DIM || m->height < 1 || m->height > PROTO_MAX_DIM)
        return proto_errorf(e, PROTO_E_MALFORMED, "FRAME size %ux%u is out of range (1 to %u)",
                            m->width, m->height, PROTO_MAX_DIM);
    if (m->format == SP_FMT_RAW && (uint64_t)m->data_len != (uint64_t)m->width * m->height * 4)
        return proto_errorf(e, PROTO_E_MALFORMED, "FRAME raw %ux%u carries %u bytes of pixels; "
                            "RGBA8 needs %llu", m->width, m->height, m->data_len,
                            (unsigned long long)m->width * m->height * 4);
    return 0;
}

int proto_enc_error(proto_buf *b, uint32_t seq, uint32_t code, const char *text)
{
    size_t n = text ? strlen(text) : 0;
    if (n > PROTO_MAX_ERRTEXT) n = PROTO_MAX_ERRTEXT; /* an error is never refused: cut it */
    wr w;
    w_begin(&w, b);
    w_u32(&w, code);
    w_u16(&w, (uint16_t)n);
    w_bytes(&w, text, n);
    return w_end(&w, PROTO_MSG_ERROR, seq);
}

int proto_parse_error(const uint8_t *pl, uint32_t len, proto_errmsg *m, proto_error *e)
{
    rd r;
    r_init(&r, pl, len, "ERROR", e);
    memset(m, 0, sizeof *m);
    m->code = r_u32(&r, "code");
    uint16_t n = r_u16(&r, "text_len");
    if (!r.rc && n > PROTO_MAX_ERRTEXT)
        r_fail(&r, PROTO_E_MALFORMED, "ERROR text_len %u is over the limit of %u", n,
               PROTO_MAX_ERRTEXT);
    if (!r.rc) r_strn(&r, m->text, n, "text");
    int rc = r_end(&r);
    if (rc) return rc;
    if (m->code == 0)
        return proto_errorf(e, PROTO_E_MALFORMED, "ERROR code 0 is not an error");
    return 0;
}

const char *proto_phase_name(int phase)
{
    static const char *const names[PROTO_PHASE_COUNT] = {
#define PROTO_PHASE_NAME_(id, name) [PROTO_PHASE_##id] = name,
        PROTO_PHASE_LIST(PROTO_PHASE_NAME_)
#undef PROTO_PHASE_NAME_
    };
    return phase >= 0 && phase < PROTO_PHASE_COUNT ? names[phase] : "?";
}
