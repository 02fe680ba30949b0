/* fuzz_targets.c — the fuzz target bodies and their oracles (see fuzz_targets.h).
 *
 * Plain C11 + Linux (memfd_create), compiled by gcc into every test and by clang with
 * -fsanitize=fuzzer into the fuzzers: nothing compiler-specific here. */
#include "fuzz_targets.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "cloud.h"
#include "e57_bitpack.h"
#include "e57_scan.h"
#include "e57_xml.h"
#include "e57test.h"
#include "frame_decode.h"
#include "lod.h"
#include "lzf.h"
#include "params.h"
#include "prep.h"
#include "proto.h"
#include "sd_err.h"
#include "http.h"
#include "ws.h"

/* ---- failing an oracle ------------------------------------------------------------------- */

static void fz_fail(const char *where, const char *fmt, ...) __attribute__((format(printf, 2, 3),
                                                                            noreturn));
static void fz_fail(const char *where, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "fuzz oracle failed (%s): ", where);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    abort();
}

void fuzz_fail(const char *where, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    fz_fail(where, "%s", msg);
}

/* FNV-1a, to compare two runs of the decoder without storing their messages. */
static uint64_t fnv(uint64_t h, const void *p, size_t n)
{
    const uint8_t *b = p;
    for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* ---- protocol ---------------------------------------------------------------------------- */

/* check_proto_err: a parser's or the decoder's failure must be a known negative code with a
 * sentence in e. */
static void check_proto_err(int rc, const proto_error *e, const char *what)
{
    if (rc >= 0) return;
    if (e->code != -rc || !e->msg[0] || !strcmp(proto_err_name(rc), "UNKNOWN"))
        fz_fail("proto", "%s returned %d but the error says code %d, message '%s'", what, rc,
                e->code, e->msg);
}

/* check_reenc: the message that parsed must re-encode (enc_rc from its proto_enc_*) to exactly
 * the header and payload that were decoded. Frees b. */
static void check_reenc(const proto_msg *m, proto_buf *b, int enc_rc)
{
    const char *name = proto_msg_name(m->h.type);
    if (enc_rc != 0)
        fz_fail("proto", "%s parsed but its encoder refused the parsed struct (%d)", name, enc_rc);
    proto_header h;
    if (b->len < PROTO_HEADER_LEN)
        fz_fail("proto", "%s re-encoded to %zu bytes, less than a header", name, b->len);
    proto_get_header(b->data, &h);
    if (b->len != PROTO_HEADER_LEN + (size_t)m->len || h.magic != m->h.magic ||
        h.version != m->h.version || h.type != m->h.type || h.seq != m->h.seq ||
        h.len != m->h.len)
        fz_fail("proto", "%s re-encoded to a different header or length (%zu bytes, len %u; "
                "decoded len %u)", name, b->len, h.len, m->len);
    if (m->len && memcmp(b->data + PROTO_HEADER_LEN, m->payload, m->len) != 0)
        fz_fail("proto", "%s re-encoded to different payload bytes (%u bytes)", name, m->len);
    proto_buf_free(b);
}

/* params_equal: 1 when a and b hold the same value of every parameter (bitwise). */
static int params_equal(const sp_params *a, const sp_params *b)
{
    for (int id = 0; id < SP_PARAM_COUNT; id++) {
        proto_param_rec ra, rb;
        proto_param_rec_from(a, id, &ra);
        proto_param_rec_from(b, id, &rb);
        if (memcmp(&ra, &rb, sizeof ra) != 0) return 0;
    }
    return 1;
}

int fuzz_params_equal(const sp_params *a, const sp_params *b)
{
    return params_equal(a, b);
}

/* check_params_msg: PARAMS applies all records or none; what it applied travels through the
 * encoder and parser unchanged. Returns the parse code. */
static int check_params_msg(const proto_msg *m, proto_error *e)
{
    sp_params p, before;
    sp_params_defaults(&p);
    before = p;
    uint64_t changed = 0;
    int rc = proto_parse_params(m->payload, m->len, &p, &changed, e);
    check_proto_err(rc, e, "proto_parse_params");
    if (rc < 0) {
        if (!params_equal(&p, &before))
            fz_fail("proto", "PARAMS failed (%s) but changed the parameters", e->msg);
        return rc;
    }
    if (changed >> SP_PARAM_COUNT)
        fz_fail("proto", "PARAMS changed mask 0x%llx has bits past the %d parameters",
                (unsigned long long)changed, SP_PARAM_COUNT);
    proto_param_rec recs[SP_PARAM_COUNT];
    for (int id = 0; id < SP_PARAM_COUNT; id++) proto_param_rec_from(&p, id, &recs[id]);
    proto_buf b = {0};
    int erc = proto_enc_params(&b, 1, recs, SP_PARAM_COUNT);
    if (erc != 0) fz_fail("proto", "PARAMS values that parsed do not encode (%d)", erc);
    sp_params q;
    sp_params_defaults(&q);
    proto_error e2 = {0};
    int prc = proto_parse_params(b.data + PROTO_HEADER_LEN, (uint32_t)(b.len - PROTO_HEADER_LEN),
                                 &q, NULL, &e2);
    proto_buf_free(&b);
    if (prc != 0 || !params_equal(&p, &q))
        fz_fail("proto", "PARAMS values that parsed do not survive encode + parse (%d: %s)", prc,
                e2.msg);
    return 0;
}

/* fuzz_parse_msg (fuzz_targets.h): runs the message's parser and, when it accepts, the re-encoding check. Returns
 * the parser's code. */
int fuzz_parse_msg(const proto_msg *m)
{
    proto_error e;
    memset(&e, 0, sizeof e);
    proto_buf b = {0};
    b.version = m->h.version;
    uint32_t seq = m->h.seq;
    const uint8_t *pl = m->payload;
    uint32_t n = m->len;
    int rc;
    switch (m->h.type) {
    case PROTO_MSG_HELLO: {
        proto_hello x;
        rc = proto_parse_hello(pl, n, &x, &e);
        if (rc == 0) {
            check_reenc(m, &b, proto_enc_hello(&b, seq, &x));
            proto_error ve;
            int v = proto_pick_version(x.min_version, x.max_version, &ve);
            if (v >= 0 && (v < x.min_version || v > x.max_version || v < (int)PROTO_VERSION_MIN ||
                           v > (int)PROTO_VERSION_MAX))
                fz_fail("proto", "proto_pick_version(%u, %u) chose %d", x.min_version,
                        x.max_version, v);
        }
        break;
    }
    case PROTO_MSG_OPEN: {
        char name[PROTO_MAX_NAME + 1];
        rc = proto_parse_open(pl, n, name, &e);
        if (rc == 0) {
            if (strchr(name, '/') || !strcmp(name, "..") || !strcmp(name, "."))
                fz_fail("proto", "OPEN accepted the name '%s'", name);
            check_reenc(m, &b, proto_enc_open(&b, seq, name));
        }
        break;
    }
    case PROTO_MSG_CAMERA: {
        proto_camera x;
        rc = proto_parse_camera(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_camera(&b, seq, &x));
        break;
    }
    case PROTO_MSG_PARAMS:
        rc = check_params_msg(m, &e);
        break;
    case PROTO_MSG_PREFETCH: {
        proto_prefetch x;
        rc = proto_parse_prefetch(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_prefetch(&b, seq, &x));
        break;
    }
    case PROTO_MSG_STREAM: {
        proto_stream x;
        rc = proto_parse_stream(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_stream(&b, seq, &x));
        break;
    }
    case PROTO_MSG_PING: {
        proto_ping x;
        rc = proto_parse_ping(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_ping(&b, seq, &x));
        break;
    }
    case PROTO_MSG_WELCOME: {
        proto_welcome x;
        rc = proto_parse_welcome(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_welcome(&b, seq, &x));
        break;
    }
    case PROTO_MSG_CLOUDS: {
        proto_clouds x;
        rc = proto_parse_clouds(pl, n, &x, &e);
        if (rc == 0) {
            check_reenc(m, &b, proto_enc_clouds(&b, seq, x.items, x.count));
            proto_clouds_free(&x);
        }
        break;
    }
    case PROTO_MSG_INFO: {
        proto_info x;
        rc = proto_parse_info(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_info(&b, seq, &x));
        break;
    }
    case PROTO_MSG_PROGRESS: {
        proto_progress x;
        rc = proto_parse_progress(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_progress(&b, seq, &x));
        break;
    }
    case PROTO_MSG_FRAME: {
        proto_frame x;
        rc = proto_parse_frame(pl, n, &x, &e);
        if (rc == 0) {
            if (x.data < pl || x.data_len > n || x.data + x.data_len != pl + n)
                fz_fail("proto", "FRAME data does not end where the payload ends");
            check_reenc(m, &b, proto_enc_frame(&b, seq, &x));
        }
        break;
    }
    case PROTO_MSG_PONG: {
        proto_pong x;
        rc = proto_parse_pong(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_pong(&b, seq, &x));
        break;
    }
    case PROTO_MSG_ERROR: {
        proto_errmsg x;
        rc = proto_parse_error(pl, n, &x, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_error(&b, seq, x.code, x.text));
        break;
    }
    default: /* LIST, RENDER, BYE, OK: the decoder lets no unknown type through */
        if (!proto_msg_dir(m->h.type))
            fz_fail("proto", "the decoder passed unknown message type %u", m->h.type);
        rc = proto_parse_empty(m->h.type, n, &e);
        if (rc == 0) check_reenc(m, &b, proto_enc_empty(&b, m->h.type, seq));
        break;
    }
    check_proto_err(rc, &e, proto_msg_name(m->h.type));
    proto_buf_free(&b);
    return rc;
}

/* What one pass of the decoder over the stream saw. */
typedef struct dec_run {
    uint64_t hash;    /* of every message (header + payload) and the final code */
    unsigned msgs;
    int rc;           /* the first decoder error, 0 when none */
    int parse_rc;     /* the first parser error, 0 when none */
} dec_run;

static void decoder_setup(proto_decoder *d, uint8_t cfg)
{
    proto_decoder_init(d, (uint8_t)(cfg & 3));
    d->preauth = (cfg >> 2) & 1;
    d->version = (cfg >> 3) & 1;
    if (cfg & 0x10) d->max_payload = 4u << 20;
}

/* run_decoder: feeds data to a fresh decoder chunk bytes at a time (parse: also parses each
 * message) and records what came out in r. */
static void run_decoder(uint8_t cfg, const uint8_t *data, size_t len, size_t chunk, int parse,
                        dec_run *r)
{
    proto_decoder d;
    decoder_setup(&d, cfg);
    memset(r, 0, sizeof *r);
    r->hash = 1469598103934665603ull;
    size_t pos = 0;
    while (pos < len) {
        size_t n = len - pos < chunk ? len - pos : chunk, used = 99;
        proto_msg m;
        proto_error e;
        memset(&e, 0, sizeof e);
        int rc = proto_decode(&d, data + pos, n, &used, &m, &e);
        if (used > n) fz_fail("proto", "proto_decode used %zu of %zu bytes", used, n);
        pos += used;
        if (rc < 0) {
            check_proto_err(rc, &e, "proto_decode");
            if (rc != -PROTO_E_BAD_MAGIC && rc != -PROTO_E_BAD_VERSION &&
                rc != -PROTO_E_UNKNOWN_TYPE && rc != -PROTO_E_TOO_LARGE &&
                rc != -PROTO_E_AUTH_REQUIRED)
                fz_fail("proto", "proto_decode returned %d (%s), not a documented code", rc,
                        proto_err_name(rc));
            size_t u2 = 99;
            proto_error e2;
            memset(&e2, 0, sizeof e2);
            int rc2 = proto_decode(&d, data + pos, len - pos, &u2, &m, &e2);
            if (rc2 != rc || u2 != 0)
                fz_fail("proto", "decoder error %d is not sticky: next call gave %d, used %zu",
                        rc, rc2, u2);
            r->rc = rc;
            break;
        }
        if (rc == PROTO_NEED_MORE) {
            if (used != n) fz_fail("proto", "NEED_MORE after using %zu of %zu bytes", used, n);
            continue;
        }
        if (rc != PROTO_ONE_MSG) fz_fail("proto", "proto_decode returned %d", rc);
        uint8_t hb[PROTO_HEADER_LEN];
        proto_put_header(hb, &m.h);
        if (m.len != m.h.len) fz_fail("proto", "message len %u, header len %u", m.len, m.h.len);
        r->hash = fnv(fnv(r->hash, hb, sizeof hb), m.payload, m.len);
        r->msgs++;
        if (parse) {
            int prc = fuzz_parse_msg(&m);
            if (prc < 0 && !r->parse_rc) r->parse_rc = prc;
        }
    }
    r->hash = fnv(r->hash, &r->rc, sizeof r->rc);
    proto_decoder_free(&d);
}

int fuzz_one_proto(const uint8_t *data, size_t len)
{
    if (len < 1) return 0;
    uint8_t cfg = data[0];
    data++;
    len--;
    size_t chunk = 1 + (size_t)(cfg >> 5) * 7;
    dec_run a, b;
    run_decoder(cfg, data, len, chunk, 1, &a);
    run_decoder(cfg, data, len, len ? len : 1, 0, &b);
    if (a.hash != b.hash || a.msgs != b.msgs || a.rc != b.rc)
        fz_fail("proto", "fed in %zu-byte chunks the decoder gave %u messages and code %d; fed "
                "at once, %u messages and code %d (or different bytes)", chunk, a.msgs, a.rc,
                b.msgs, b.rc);
    return a.rc ? a.rc : a.parse_rc;
}

/* ---- file readers ------------------------------------------------------------------------ */

typedef int (*reader_fn)(const char *path, pc_raw *raw, sd_err *err);

/* check_sd_err: a failure is a known SD_E* code with a message naming the file. */
static void check_sd_err(int rc, const sd_err *err, const char *path, const char *what)
{
    if (rc == 0) return;
    if (rc < SD_ENOTFOUND || rc > SD_EIO)
        fz_fail(what, "returned %d, not 0 or an SD_E* code", rc);
    if (err->code != rc || !err->msg[0])
        fz_fail(what, "returned %d but the error holds code %d, message '%s'", rc, err->code,
                err->msg);
    if (!strstr(err->msg, path))
        fz_fail(what, "the error message does not name the file %s: '%s'", path, err->msg);
}

void fuzz_check_sd_err(int rc, const sd_err *err, const char *path, const char *what)
{
    check_sd_err(rc, err, path, what);
}

/* touch: reads every byte of an n-element array so that ASan sees one that is too short. */
static unsigned touch(const void *p, size_t n, size_t elem, uint32_t attrs, uint32_t bit,
                      const char *what, const char *name)
{
    if (bit && !(attrs & bit)) return 0;
    if (n == 0) return 0;
    if (!p) fz_fail(what, "attribute %s is set but its array is NULL", name);
    const uint8_t *b = p;
    unsigned s = 0;
    for (size_t i = 0; i < n * elem; i++) s += b[i];
    return s;
}

/* check_raw: what any reader leaves in raw (success or failure) fits what len file bytes can
 * hold, and on success every present attribute array holds n points. */
static void check_raw(const pc_raw *raw, size_t len, int ok, const char *what)
{
    /* The densest encoding is PCD binary_compressed: LZF makes at most 88 bytes of one input
     * byte, and a point takes at least 3 bytes (x y z of 1 byte each), so under 30 points
     * per file byte. Everything else needs at least 3 bytes per point. */
    size_t bound = 30 * len + 64;
    if (raw->cap > bound || raw->n > raw->cap)
        fz_fail(what, "%zu points reserved (%zu read) for a %zu-byte file", raw->cap, raw->n,
                len);
    if (!memchr(raw->format, 0, sizeof raw->format) ||
        !memchr(raw->scalar_name, 0, sizeof raw->scalar_name))
        fz_fail(what, "format or scalar_name is not NUL-terminated");
    if (!ok) return;
    if (!raw->format[0]) fz_fail(what, "the reader succeeded but set no format string");
    size_t n = raw->n;
    unsigned s = touch(raw->xyz, n, 3 * sizeof(double), raw->attrs, 0, what, "xyz");
    s += touch(raw->rgba, n, 4, raw->attrs, PC_ATTR_RGB, what, "rgb");
    s += touch(raw->normal, n, 3 * sizeof(float), raw->attrs, PC_ATTR_NORMAL, what, "normal");
    s += touch(raw->intensity, n, sizeof(float), raw->attrs, PC_ATTR_INTENSITY, what, "intensity");
    s += touch(raw->cls, n, 1, raw->attrs, PC_ATTR_CLASS, what, "class");
    s += touch(raw->radius, n, sizeof(float), raw->attrs, PC_ATTR_RADIUS, what, "radius");
    s += touch(raw->scalar, n, sizeof(float), raw->attrs, PC_ATTR_SCALAR, what, "scalar");
    s += touch(raw->scan, n, sizeof(uint16_t), raw->attrs, PC_ATTR_SCAN, what, "scan");
    (void)s;
}

/* check_cloud: pc_finalize kept the finite points of n, with a finite bounding box that holds
 * them and a finite offset. */
static void check_cloud(const pc_cloud *c, size_t n, const char *what)
{
    if (c->n == 0 || c->n + c->n_dropped != n)
        fz_fail(what, "pc_finalize kept %zu and dropped %llu of %zu points", c->n,
                (unsigned long long)c->n_dropped, n);
    for (int k = 0; k < 3; k++)
        if (!isfinite(c->bmin[k]) || !isfinite(c->bmax[k]) || !(c->bmin[k] <= c->bmax[k]) ||
            !isfinite(c->offset[k]))
            fz_fail(what, "pc_finalize: axis %d bounds [%g, %g], offset %g", k, c->bmin[k],
                    c->bmax[k], c->offset[k]);
    /* pc_finalize refuses a cloud whose half span passes FLT_MAX, so every kept point converts
     * to finite float coordinates. */
    for (size_t i = 0; i < 3 * c->n; i++)
        if (!isfinite(c->pos[i]))
            fz_fail(what, "pc_finalize: point %zu has a non-finite float coordinate %g", i / 3,
                    (double)c->pos[i]);
    unsigned s = touch(c->pos, c->n, 3 * sizeof(float), c->attrs, 0, what, "pos");
    s += touch(c->rgba, c->n, 4, c->attrs, PC_ATTR_RGB, what, "rgb");
    s += touch(c->normal, c->n, 3 * sizeof(float), c->attrs, PC_ATTR_NORMAL, what, "normal");
    s += touch(c->intensity, c->n, sizeof(float), c->attrs, PC_ATTR_INTENSITY, what, "intensity");
    s += touch(c->cls, c->n, 1, c->attrs, PC_ATTR_CLASS, what, "class");
    s += touch(c->radius, c->n, sizeof(float), c->attrs, PC_ATTR_RADIUS, what, "radius");
    s += touch(c->scalar, c->n, sizeof(float), c->attrs, PC_ATTR_SCALAR, what, "scalar");
    s += touch(c->scan, c->n, sizeof(uint16_t), c->attrs, PC_ATTR_SCAN, what, "scan");
    (void)s;
}

/* fuzz_reader: data as a file through a memfd; reader, then pc_finalize, then the checks.
 * Returns the first non-zero code. */
int fuzz_memfd(const uint8_t *data, size_t len, char *path, size_t plen)
{
    int fd = memfd_create("splatd-fuzz", MFD_CLOEXEC);
    if (fd < 0) {
        perror("memfd_create");
        abort(); /* not the input's fault: the harness cannot run here */
    }
    for (size_t off = 0; off < len;) {
        ssize_t w = write(fd, data + off, len - off);
        if (w <= 0) {
            perror("write to memfd");
            abort();
        }
        off += (size_t)w;
    }
    snprintf(path, plen, "/proc/self/fd/%d", fd);
    return fd;
}

static int fuzz_reader(reader_fn rd, const char *what, const uint8_t *data, size_t len)
{
    char path[64];
    int fd = fuzz_memfd(data, len, path, sizeof path);
    pc_raw raw;
    memset(&raw, 0, sizeof raw);
    sd_err err;
    memset(&err, 0, sizeof err);
    int rc = rd(path, &raw, &err);
    check_sd_err(rc, &err, path, what);
    check_raw(&raw, len, rc == 0, what);
    if (rc == 0) {
        size_t n = raw.n;
        pc_cloud c;
        memset(&err, 0, sizeof err);
        rc = pc_finalize(&raw, &c, path, &err);
        check_sd_err(rc, &err, path, "pc_finalize");
        if (rc == 0) check_cloud(&c, n, what);
        else if (rc != SD_EEMPTY && rc != SD_ELIMIT) fz_fail(what, "pc_finalize returned %d", rc);
        pc_cloud_free(&c);
    }
    pc_raw_free(&raw);
    close(fd);
    return rc;
}

int fuzz_one_ply(const uint8_t *data, size_t len) { return fuzz_reader(pc_read_ply, "ply", data, len); }
int fuzz_one_pcd(const uint8_t *data, size_t len) { return fuzz_reader(pc_read_pcd, "pcd", data, len); }
int fuzz_one_las(const uint8_t *data, size_t len) { return fuzz_reader(pc_read_las, "las", data, len); }
int fuzz_one_xyz(const uint8_t *data, size_t len) { return fuzz_reader(pc_read_xyz, "xyz", data, len); }
int fuzz_one_laz(const uint8_t *data, size_t len) { return fuzz_reader(pc_read_laz, "laz", data, len); }

/* ---- COPC's top levels (io_copc.c) -------------------------------------------------------- */

/* copc_read: path through pc_read_copc_levels(max_level) (budget 0) or pc_read_copc_budget
 * into raw, with the reader's checks; *deepest gets the deepest level read (from the format
 * string for the levels reader). Returns the reader's code. */
static int copc_read(const char *path, size_t len, int max_level, uint64_t budget, pc_raw *raw,
                     int *deepest)
{
    memset(raw, 0, sizeof *raw);
    sd_err err;
    memset(&err, 0, sizeof err);
    int lv = -1;
    int rc = budget ? pc_read_copc_budget(path, budget, raw, &lv, &err)
                    : pc_read_copc_levels(path, max_level, raw, &err);
    check_sd_err(rc, &err, path, "copclevels");
    check_raw(raw, len, rc == 0, "copclevels");
    if (rc == 0 && !budget) {
        const char *l = strstr(raw->format, ", levels 0-");
        if (!l || sscanf(l, ", levels 0-%d", &lv) != 1)
            fuzz_fail("copclevels", "format '%s' does not say its levels", raw->format);
    }
    if (rc == 0 && (lv < 0 || lv > (budget ? 24 : max_level) || raw->n == 0))
        fuzz_fail("copclevels", "deepest level %d (at most %d asked), %zu points", lv,
                  budget ? 24 : max_level, raw->n);
    *deepest = lv;
    return rc;
}

int fuzz_one_copclevels(const uint8_t *data, size_t len)
{
    if (len < 1) return SD_EINVAL;
    int max_level = data[0] & 7;
    char path[64];
    int fd = fuzz_memfd(data + 1, len - 1, path, sizeof path);
    pc_raw a, b;
    int la, lb;
    int rc = copc_read(path, len, max_level, 0, &a, &la);
    /* the budget reader walks the whole hierarchy (to level 24): its answers are compared
     * where the whole hierarchy and its nodes read */
    int whole = -1;
    if (rc == 0 && copc_read(path, len, 24, 0, &b, &lb) == 0) whole = lb;
    if (rc == 0) pc_raw_free(&b);
    if (whole >= 0) {
        /* a budget of exactly the points of levels 0..la keeps exactly those levels: the
         * same points in the same order */
        int brc = copc_read(path, len, 0, a.n, &b, &lb);
        if (brc != 0 || lb != la || b.n != a.n || memcmp(a.xyz, b.xyz, 3 * a.n * sizeof *a.xyz))
            fuzz_fail("copclevels", "levels 0-%d hold %zu points, but a budget of %zu keeps "
                      "levels 0-%d, %zu points (code %d)", la, a.n, a.n, lb, b.n, brc);
        pc_raw_free(&b);
        /* one point less: a shallower level, unless the shallowest level read is la itself */
        brc = copc_read(path, len, 0, a.n - 1 ? a.n - 1 : 1, &b, &lb);
        if (brc != 0 || lb > la || (lb == la) != (b.n == a.n) || b.n > a.n)
            fuzz_fail("copclevels", "levels 0-%d hold %zu points; a budget of %zu keeps levels "
                      "0-%d, %zu points (code %d)", la, a.n, a.n - 1, lb, b.n, brc);
        pc_raw_free(&b);
    }
    if (rc == 0) {
        size_t n = a.n;
        pc_cloud c;
        sd_err err;
        memset(&err, 0, sizeof err);
        rc = pc_finalize(&a, &c, path, &err);
        check_sd_err(rc, &err, path, "pc_finalize");
        if (rc == 0) check_cloud(&c, n, "copclevels");
        else if (rc != SD_EEMPTY && rc != SD_ELIMIT) fz_fail("copclevels", "pc_finalize: %d", rc);
        pc_cloud_free(&c);
    }
    pc_raw_free(&a);
    close(fd);
    return rc;
}

/* ---- LZF --------------------------------------------------------------------------------- */

/* ref_lzf: the LZF format decoded one byte at a time, as lzf.h describes it; 0 when in
 * decodes to exactly out_len bytes, -1 when not. */
static int ref_lzf(const uint8_t *in, size_t in_len, uint8_t *out, size_t out_len)
{
    size_t ip = 0, op = 0;
    while (ip < in_len) {
        unsigned c = in[ip++];
        if (c < 32) {
            for (unsigned k = 0; k <= c; k++) {
                if (ip >= in_len || op >= out_len) return -1;
                out[op++] = in[ip++];
            }
            continue;
        }
        size_t l = c >> 5;
        if (l == 7) {
            if (ip >= in_len) return -1;
            l += in[ip++];
        }
        if (ip >= in_len) return -1;
        size_t dist = ((size_t)(c & 31) << 8) + in[ip++] + 1;
        if (dist > op) return -1;
        for (size_t k = 0; k < l + 2; k++) {
            if (op >= out_len) return -1;
            out[op] = out[op - dist];
            op++;
        }
    }
    return op == out_len ? 0 : -1;
}

int fuzz_one_lzf(const uint8_t *data, size_t len)
{
    if (len < 3) return 0;
    size_t out_len = (size_t)data[0] | (size_t)data[1] << 8 | (size_t)(data[2] & 0x0f) << 16;
    const uint8_t *in = data + 3;
    size_t in_len = len - 3;
    uint8_t *out = malloc(out_len ? out_len : 1), *ref = malloc(out_len ? out_len : 1);
    if (!out || !ref) {
        free(out);
        free(ref);
        return SD_ENOMEM;
    }
    sd_err err;
    memset(&err, 0, sizeof err);
    int rc = pc_lzf_decompress(in, in_len, out, out_len, "lzf-input", 1000, &err);
    check_sd_err(rc, &err, "lzf-input", "lzf");
    if (rc != 0 && rc != SD_ETRUNC && rc != SD_EFORMAT)
        fz_fail("lzf", "pc_lzf_decompress returned %d", rc);
    int rrc = ref_lzf(in, in_len, ref, out_len);
    if ((rc == 0) != (rrc == 0))
        fz_fail("lzf", "pc_lzf_decompress says %d (%s), the reference decoder %s", rc, err.msg,
                rrc == 0 ? "decodes it" : "rejects it");
    if (rc == 0 && out_len && memcmp(out, ref, out_len) != 0)
        fz_fail("lzf", "pc_lzf_decompress and the reference decoder disagree on the bytes");
    free(out);
    free(ref);
    return rc;
}

/* ---- parameters -------------------------------------------------------------------------- */

/* close_enough: b is a within the precision "%g" prints (6 significant digits). */
static int close_enough(double a, double b)
{
    return fabs(a - b) <= 1e-5 * fmax(1.0, fabs(a));
}

/* check_vec3_text: an accepted vec3 value, read independently over its whole length (the
 * ','-separated non-empty tokens, each a whole finite strtod number, exactly three), must be
 * what was stored. */
static void check_vec3_text(const char *kv, const char *value, const float stored[3])
{
    double v[3];
    int k = 0;
    const char *p = value;
    while (*p) {
        const char *e = strchr(p, ',');
        size_t n = e ? (size_t)(e - p) : strlen(p);
        if (n > 0) {
            char tok[4097];
            memcpy(tok, p, n);
            tok[n] = 0;
            char *end;
            double x = strtod(tok, &end);
            if (k == 3 || end == tok || *end || !isfinite(x))
                fz_fail("params", "'%.80s...' (%zu bytes) was accepted, but its value is not "
                        "three numbers", kv, strlen(kv));
            v[k++] = x;
        }
        p += n;
        if (*p == ',') p++;
    }
    if (k != 3)
        fz_fail("params", "'%.80s' was accepted with %d numbers", kv, k);
    for (k = 0; k < 3; k++)
        if ((float)v[k] != stored[k])
            fz_fail("params", "'%.80s...' (%zu bytes) stored component %d as %g; the text says "
                    "%g", kv, strlen(kv), k, (double)stored[k], v[k]);
}

int fuzz_one_params(const uint8_t *data, size_t len)
{
    char s[4097];
    size_t n = len < sizeof s - 1 ? len : sizeof s - 1;
    memcpy(s, data, n);
    s[n] = 0;
    sp_params p, before;
    sp_params_defaults(&p);
    before = p;
    char err[256] = "";
    int rc = sp_param_set_kv(&p, s, err, sizeof err);
    if (rc != 0) {
        if (rc != -1 || !err[0])
            fz_fail("params", "sp_param_set_kv returned %d with message '%s'", rc, err);
        if (!params_equal(&p, &before))
            fz_fail("params", "sp_param_set_kv failed (%s) but changed a parameter", err);
        return -1;
    }
    const char *eq = strchr(s, '=');
    char name[64];
    size_t l = eq ? (size_t)(eq - s) : 0;
    if (!eq || l == 0 || l >= sizeof name) fz_fail("params", "accepted '%s'", s);
    memcpy(name, s, l);
    name[l] = 0;
    int id = sp_param_find(name);
    if (id < 0) fz_fail("params", "accepted unknown parameter '%s'", name);
    for (int k = 0; k < SP_PARAM_COUNT; k++) {
        if (k == id) continue;
        proto_param_rec ra, rb;
        proto_param_rec_from(&p, k, &ra);
        proto_param_rec_from(&before, k, &rb);
        if (memcmp(&ra, &rb, sizeof ra) != 0)
            fz_fail("params", "setting '%s' changed '%s'", name, sp_param_table[k].name);
    }
    /* The stored value prints and reads back. */
    char txt[256], err2[256] = "";
    sp_param_get_text(&p, id, txt, sizeof txt);
    sp_params q;
    sp_params_defaults(&q);
    if (sp_param_set_text(&q, name, txt, err2, sizeof err2) != 0)
        fz_fail("params", "'%s' was accepted but its printed value '%s' is not (%s)", s, txt, err2);
    proto_param_rec rp, rq;
    proto_param_rec_from(&p, id, &rp);
    proto_param_rec_from(&q, id, &rq);
    int same = 1;
    switch (rp.type) {
    case SP_T_ENUM: same = rp.u.e == rq.u.e; break;
    case SP_T_INT: same = rp.u.i == rq.u.i; break;
    case SP_T_FLOAT: same = close_enough(rp.u.f, rq.u.f); break;
    case SP_T_VEC3:
        for (int k = 0; k < 3; k++) same &= close_enough(rp.u.v[k], rq.u.v[k]);
        break;
    }
    if (!same) fz_fail("params", "'%s' prints as '%s', which reads back differently", s, txt);
    if (rp.type == SP_T_VEC3) check_vec3_text(s, eq + 1, rp.u.v);
    /* What the text syntax accepts, the wire accepts too (same table, same ranges). */
    proto_error pe;
    memset(&pe, 0, sizeof pe);
    sp_params w;
    sp_params_defaults(&w);
    if (proto_param_apply(&rp, &w, NULL, &pe) != 0)
        fz_fail("params", "'%s' is accepted as text but refused on the wire: %s", s, pe.msg);
    return 0;
}

/* ---- the prep-cache loader --------------------------------------------------------------- */

/* A 3-point XYZ source the cache claims to describe (its size, time and hash go in by
 * cache__seal; what is in it does not matter to the loader). */
static const char CACHE_SRC[] = "0 0 0\n1 0 0\n0 1 0\n";

/* write_file: path := data. Aborts on failure (the harness's fault, not the input's). */
static void write_file(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    if (!f || (len && fwrite(data, 1, len, f) != len) || fclose(f) != 0) {
        perror(path);
        abort();
    }
}

void fuzz_write_file(const char *path, const void *data, size_t len)
{
    write_file(path, data, len);
}

void fuzz_mkdtemp(char *dir, size_t len, const char *tag)
{
    const char *tmp = getenv("TMPDIR");
    if (access("/dev/shm", W_OK) == 0) tmp = "/dev/shm";
    snprintf(dir, len, "%s/splatd-fuzz-%s.XXXXXX", tmp && *tmp ? tmp : "/tmp", tag);
    if (!mkdtemp(dir)) {
        perror("mkdtemp");
        abort();
    }
}

/* cache_files: a new directory (tmpfs when there is one: a file system round trip per input
 * is most of the cost) holding the source src (CACHE_SRC) and the cache file cpath named
 * c.EXT with data. */
static void cache_files(const char *ext, const uint8_t *data, size_t len, char *dir,
                        char *src, char *cpath)
{
    fuzz_mkdtemp(dir, 512, "cache");
    snprintf(src, 600, "%s/s.xyz", dir);
    snprintf(cpath, 600, "%s/c.%s", dir, ext);
    write_file(src, CACHE_SRC, sizeof CACHE_SRC - 1);
    write_file(cpath, data, len);
}

static void cache_files_rm(const char *dir, const char *src, const char *cpath)
{
    unlink(cpath);
    unlink(src);
    rmdir(dir);
}

int fuzz_one_cache(const uint8_t *data, size_t len)
{
    char dir[512], src[600], cpath[600];
    cache_files("splc", data, len, dir, src, cpath);
    int sealed = cache__seal(cpath, src) == 0;
    if (!sealed && len >= 4096) fz_fail("cache", "cache__seal failed on a %zu-byte file", len);
    pc_prepared p;
    memset(&p, 0, sizeof p);
    char why[256] = "";
    int rc = cache__load(cpath, src, PREP_DEFAULT_K, &p, why, sizeof why);
    if (rc < -1 || rc > 1) fz_fail("cache", "cache__load returned %d", rc);
    if (rc != 1 && !why[0]) fz_fail("cache", "refused (%d) without a reason", rc);
    if (rc == 1) {
        /* What the loader accepts is what the renderer trusts: a block of exactly the layout's
         * length inside the mapping, batches tiling [0, n), terminated strings. */
        if (!sealed) fz_fail("cache", "an unsealed file was loaded");
        uint64_t want = pc_prepared_block_len(p.n, p.attrs, p.nbatches);
        if (p.n == 0 || p.nbatches == 0 || p.block_len != want || p.map_len != 4096 + want ||
            (const uint8_t *)p.block != (const uint8_t *)p.map + 4096)
            fz_fail("cache", "loaded n %llu, %llu batches, block %llu bytes (layout %llu), map %zu",
                    (unsigned long long)p.n, (unsigned long long)p.nbatches,
                    (unsigned long long)p.block_len, (unsigned long long)want, p.map_len);
        uint64_t next = 0;
        for (uint64_t i = 0; i < p.nbatches; i++) {
            if (p.batches[i].first != next || p.batches[i].count == 0)
                fz_fail("cache", "batch %llu does not follow", (unsigned long long)i);
            next += p.batches[i].count;
        }
        if (next != p.n) fz_fail("cache", "batches hold %llu of %llu points",
                                 (unsigned long long)next, (unsigned long long)p.n);
        if (!memchr(p.format, 0, sizeof p.format) || !memchr(p.scalar_name, 0, sizeof p.scalar_name))
            fz_fail("cache", "format or scalar name not terminated");
        unsigned t = touch(p.pos, p.n, 3 * sizeof(float), 0, 0, "cache", "pos");
        t += touch(p.normal, p.n, 3 * sizeof(float), 0, 0, "cache", "normal");
        t += touch(p.radius, p.n, sizeof(float), 0, 0, "cache", "radius");
        t += touch(p.F, p.n, sizeof(float), 0, 0, "cache", "F");
        t += touch(p.block, (size_t)p.block_len, 1, 0, 0, "cache", "block");
        (void)t;
        pc_prepared_free(&p);
    }
    cache_files_rm(dir, src, cpath);
    return rc == 1 ? 0 : rc < 0 ? SD_ESTALE : SD_EUNSUP;
}

/* ---- the LOD cache loader ------------------------------------------------------------------ */

/* The options the splod seeds were built with (tests/fuzz/make_corpus.py). */
static const lod_desc SPLOD_DESC = {.grid_bits = 2, .leaf_max = 64};

int fuzz_one_splod(const uint8_t *data, size_t len)
{
    char dir[512], src[600], cpath[600];
    cache_files("splod", data, len, dir, src, cpath);
    int sealed = lod__seal(cpath, src, &SPLOD_DESC) == 0;
    if (!sealed && len >= 4096) fz_fail("splod", "lod__seal failed on a %zu-byte file", len);
    lod_cloud c;
    char why[256] = "";
    int rc = lod_load_file(cpath, src, &SPLOD_DESC, &c, why, sizeof why);
    if (rc < -1 || rc > 1) fz_fail("splod", "lod_load_file returned %d", rc);
    if (rc != 1 && !why[0]) fz_fail("splod", "refused (%d) without a reason", rc);
    if (rc == 1) {
        /* What the loader accepts is what the renderer trusts: a tree of nnodes nodes, parents
         * before children, every node's data inside the file, the counts adding up to n. */
        if (!sealed) fz_fail("splod", "an unsealed file was loaded");
        if (!c.nnodes || !c.n || c.nodes[0].parent != UINT32_MAX || !c.file ||
            c.map_len != (size_t)len)
            fz_fail("splod", "loaded %llu nodes, %llu points, map %zu of %zu bytes",
                    (unsigned long long)c.nnodes, (unsigned long long)c.n, c.map_len, len);
        uint64_t total = 0;
        for (uint64_t i = 0; i < c.nnodes; i++) {
            const lod_node *nd = &c.nodes[i];
            if (nd->offset + lod_node_bytes(nd->count) > c.map_len ||
                (i && nd->parent >= i) ||
                (nd->nchildren && nd->first_child + (uint64_t)nd->nchildren > c.nnodes))
                fz_fail("splod", "node %llu is outside the file or the tree",
                        (unsigned long long)i);
            total += nd->count;
            /* its data: copied and checked (a node that does not match fails, never more) */
            void *buf = malloc(lod_node_bytes(nd->count));
            if (!buf) abort();
            sd_err err = {0};
            int nrc = lod_node_copy(&c, i, buf, &err);
            if (nrc != 0 && (nrc != SD_ESTALE || !err.msg[0]))
                fz_fail("splod", "node %llu: code %d '%s'", (unsigned long long)i, nrc, err.msg);
            if (nrc == 0 && lod_node_verify(&c, i) != 1)
                fz_fail("splod", "node %llu copies but does not verify", (unsigned long long)i);
            free(buf);
        }
        if (total != c.n) fz_fail("splod", "nodes hold %llu of %llu points",
                                  (unsigned long long)total, (unsigned long long)c.n);
        if (!memchr(c.format, 0, sizeof c.format)) fz_fail("splod", "format not terminated");
        lod_cloud_free(&c);
    }
    cache_files_rm(dir, src, cpath);
    return rc == 1 ? 0 : rc < 0 ? SD_ESTALE : SD_EUNSUP;
}

/* ---- the client's frame decoder ---------------------------------------------------------- */

int fuzz_one_frame(const uint8_t *data, size_t len)
{
    if (len < 3) return FD_ETRUNC;
    static const int fmts[4] = {SP_FMT_JPEG, SP_FMT_LZ4, SP_FMT_RAW, SP_FMT_PNG};
    int fmt = fmts[data[0] & 3], w = data[1], h = data[2];
    const uint8_t *pl = data + 3;
    size_t plen = len - 3;
    if (data[0] & 4) {
        /* The whole FRAME payload as a server sends it: the client decodes what it parsed. */
        proto_frame f;
        proto_error pe;
        memset(&pe, 0, sizeof pe);
        if (proto_parse_frame(pl, (uint32_t)plen, &f, &pe) < 0) {
            if (!pe.msg[0]) fz_fail("frame", "FRAME refused without a message");
            return -pe.code;
        }
        if (f.data_len > plen || (f.data_len && (f.data < pl || f.data + f.data_len > pl + plen)))
            fz_fail("frame", "FRAME data (%u bytes) outside its %zu-byte payload", f.data_len, plen);
        if (f.width > 1u << 16 || f.height > 1u << 16) return FD_ELIMIT;
        fmt = f.format;
        w = (int)f.width;
        h = (int)f.height;
        pl = f.data;
        plen = f.data_len;
    }
    char err[400] = "";
    fd_ctx *d = fd_create(err, sizeof err);
    if (!d) {
        fprintf(stderr, "fd_create: %s\n", err);
        abort();
    }
    const uint8_t *rgba = NULL;
    int ow = -1, oh = -1;
    int rc = fd_decode(d, fmt, pl, plen, w, h, &rgba, &ow, &oh, err, sizeof err);
    if (rc < 0) {
        if (rc < FD_EINVAL || !err[0]) fz_fail("frame", "fd_decode returned %d, message '%s'", rc, err);
    } else {
        if (rc != 0 || !rgba || ow <= 0 || oh <= 0 || (w > 0 && ow != w) || (h > 0 && oh != h))
            fz_fail("frame", "fd_decode returned %d, %dx%d for a %dx%d frame", rc, ow, oh, w, h);
        if (fmt == SP_FMT_RAW && (rgba != pl || plen != (size_t)ow * (size_t)oh * 4))
            fz_fail("frame", "raw %dx%d from %zu bytes", ow, oh, plen);
        if (fmt == SP_FMT_LZ4) {
            int hw = 0, hh = 0;
            char e2[400];
            if (fd_lz4_header(pl, plen, &hw, &hh, e2, sizeof e2) != 0 || hw != ow || hh != oh)
                fz_fail("frame", "LZ4 frame decoded at %dx%d, its header says %dx%d", ow, oh, hw, hh);
        }
        (void)touch(rgba, (size_t)ow * (size_t)oh, 4, 0, 0, "frame", "rgba");
    }
    fd_destroy(d);
    return rc;
}

/* ---- lookup ------------------------------------------------------------------------------ */

fuzz_fn fuzz_target_find(const char *name)
{
    static const struct { const char *name; fuzz_fn fn; } targets[] = {
        {"proto", fuzz_one_proto}, {"ply", fuzz_one_ply}, {"pcd", fuzz_one_pcd},
        {"las", fuzz_one_las},     {"xyz", fuzz_one_xyz}, {"lzf", fuzz_one_lzf},
        {"params", fuzz_one_params}, {"ws", fuzz_one_ws},
        {"laz", fuzz_one_laz},     {"copc", fuzz_one_copc},
        {"cache", fuzz_one_cache}, {"frame", fuzz_one_frame},
        {"e57", fuzz_one_e57},     {"e57xml", fuzz_one_e57xml}, {"e57bits", fuzz_one_e57bits},
        {"splod", fuzz_one_splod},
        {"copclevels", fuzz_one_copclevels}, {"lodsrc", fuzz_one_lodsrc},
        {"campath", fuzz_one_campath}, {"shard", fuzz_one_shard}, {"token", fuzz_one_token},
        {"mpimsg", fuzz_one_mpimsg},
    };
    for (size_t i = 0; i < sizeof targets / sizeof targets[0]; i++)
        if (!strcmp(targets[i].name, name)) return targets[i].fn;
    return NULL;
}

/* ---- WebSocket framing and HTTP request heads (server/net/ws.c, http.c) ---- */

typedef struct ws_trace {
    uint8_t *out;              /* every payload byte produced, in order */
    size_t out_len;
    int ev[256], code[256];    /* events and their codes (close / error) */
    size_t ev_len[256];
    int nev;
    int err;                   /* the close code of an error, 0 when none */
} ws_trace;

/* ws_run: in[0..n) through a fresh decoder d0 (settings copied) fed step bytes at a time with
 * an output buffer of cap bytes; records what came out. */
static void ws_run(const ws_decoder *d0, const uint8_t *in, size_t n, size_t step, size_t cap,
                   ws_trace *t)
{
    ws_decoder d = *d0;
    uint8_t buf[4096];
    size_t off = 0;
    memset(t->ev, 0, sizeof t->ev);
    t->nev = 0;
    t->err = 0;
    t->out_len = 0;
    for (int guard = 0; off < n && guard < 1 << 22; guard++) {
        size_t lim = n - off < step ? n - off : step, used = 0, prod = 0;
        ws_event ev;
        int rc = ws_decode(&d, in + off, lim, &used, buf, cap, &prod, &ev);
        if (used > lim || prod > cap)
            fz_fail("ws", "ws_decode used %zu of %zu, produced %zu of %zu", used, lim, prod, cap);
        memcpy(t->out + t->out_len, buf, prod);
        t->out_len += prod;
        off += used;
        if (rc == WS_EV_ERROR) {
            if ((ev.code != 1002 && ev.code != 1003 && ev.code != 1009) || !ev.why[0])
                fz_fail("ws", "ws_decode error with code %u, text '%s'", ev.code, ev.why);
            t->err = ev.code;
            return;
        }
        if (rc != WS_EV_NONE && t->nev < 256) {
            t->ev[t->nev] = rc;
            t->code[t->nev] = rc == WS_EV_CLOSE ? ev.code : 0;
            t->ev_len[t->nev] = rc == WS_EV_END ? 0 : ev.len;
            t->nev++;
        }
        if (rc == WS_EV_NONE && used == 0 && prod == 0) break; /* needs more than there is */
    }
}

int fuzz_one_ws(const uint8_t *data, size_t len)
{
    if (len < 1) return -1;
    uint8_t cfg = data[0];
    const uint8_t *in = data + 1;
    size_t n = len - 1;
    static const uint64_t caps[8] = {0, 125, 126, 65535, 65536, 65552, 1 << 20, 3};
    ws_decoder d0 = {.require_mask = (cfg >> 3) & 1, .binary_only = (cfg >> 4) & 1,
                     .max_message = caps[cfg >> 5]};
    ws_trace a = {.out = malloc(n + 1)}, b = {.out = malloc(n + 1)};
    if (!a.out || !b.out) abort();
    /* All at once with a roomy output, and in chunks of 1..128 bytes with a 7-byte output:
     * the same bytes, events and error either way. */
    ws_run(&d0, in, n, n ? n : 1, 4096, &a);
    ws_run(&d0, in, n, (size_t)1 << (cfg & 7), 7, &b);
    if (a.out_len != b.out_len || memcmp(a.out, b.out, a.out_len) != 0)
        fz_fail("ws", "%zu bytes at once, %zu in pieces (or different bytes)", a.out_len,
                b.out_len);
    if (a.err != b.err || a.nev != b.nev || memcmp(a.ev, b.ev, sizeof a.ev) != 0 ||
        memcmp(a.code, b.code, sizeof a.code) != 0)
        fz_fail("ws", "events or error differ between whole and pieces (%d/%d, %d/%d)", a.nev,
                  b.nev, a.err, b.err);
    if (a.out_len > n) fz_fail("ws", "%zu payload bytes from %zu input bytes", a.out_len, n);
    int rc = a.err ? -a.err : 0;
    free(a.out);
    free(b.out);
    /* The same bytes as an HTTP request head. */
    http_req r;
    char err[200] = "";
    int h = http_parse_request((const char *)in, n, &r, err, sizeof err);
    /* a head ends in an empty line: LF LF, each LF optionally after a CR (RFC 9112 2.2) */
    int ends = h >= 2 && in[h - 1] == '\n' &&
               (in[h - 2] == '\n' || (h >= 3 && in[h - 2] == '\r' && in[h - 3] == '\n'));
    if (h > 0 && ((size_t)h > n || !ends))
        fz_fail("http", "head length %d of %zu bytes does not end in an empty line", h, n);
    if (h == 0 && n >= HTTP_HEAD_MAX) fz_fail("http", "needs more after %zu bytes", n);
    if (h < 0 && ((h != -400 && h != -414 && h != -431 && h != -505) || !err[0]))
        fz_fail("http", "status %d, text '%s'", -h, err);
    return rc;
}

/* ---- E57 (server/io/e57_*.c) ---- */

int fuzz_one_e57(const uint8_t *data, size_t len)
{
    uint8_t *d = malloc(len ? len : 1);
    if (!d) abort();
    if (len) memcpy(d, data, len);
    /* the checksums made to match, so that inputs reach past page 0 (test_io_e57 covers them) */
    uint64_t page = 0;
    for (int i = 7; len >= 48 && i >= 0; i--) page = page << 8 | d[40 + i];
    if (page >= 64 && page <= (1u << 20) && page % 4 == 0) e57w_fix_crcs(d, len, (uint32_t)page);
    int rc = fuzz_reader(pc_read_e57, "e57", d, len);
    free(d);
    return rc;
}

/* xml_desc: the document in pieces of chunk bytes through e57_xml, then e57_desc_read. */
static int xml_desc(const uint8_t *p, size_t n, size_t chunk, e57_desc *d, sd_err *err)
{
    e57_xml *x = e57_xml_new();
    if (!x) abort();
    int rc = 0;
    for (size_t i = 0; rc == 0 && (i < n || i == 0); i += chunk) {
        size_t m = n - i < chunk ? n - i : chunk;
        rc = e57_xml_feed(x, (const char *)p + i, m, i + m >= n, "xml", err);
        if (n == 0) break;
    }
    memset(d, 0, sizeof *d);
    if (rc == 0) rc = e57_desc_read(e57_xml_root(x), d, "xml", err);
    e57_xml_free(x);
    return rc;
}

int fuzz_one_e57xml(const uint8_t *data, size_t len)
{
    if (len < 1) return 0;
    size_t chunk = 1 + data[0] % 64;
    e57_desc a, b;
    sd_err ea = {0}, eb = {0};
    int rc = xml_desc(data + 1, len - 1, chunk, &a, &ea);
    int rc1 = xml_desc(data + 1, len - 1, len, &b, &eb); /* all at once */
    check_sd_err(rc, &ea, "xml", "e57xml");
    if (rc != rc1 || (rc == 0 && a.nscans != b.nscans))
        fz_fail("e57xml", "in pieces of %zu: %d (%s); at once: %d (%s)", chunk, rc, ea.msg, rc1,
                eb.msg);
    for (uint32_t i = 0; rc == 0 && i < a.nscans; i++) {
        const e57_scan *s = &a.scans[i];
        if (s->nfields > E57_MAX_FIELDS) fz_fail("e57xml", "scan %u: %u fields", i, s->nfields);
        for (int r = 0; r < E57_R_COUNT; r++)
            if (s->role[r] >= (int)s->nfields || (s->role[r] >= 0 && s->fields[s->role[r]].role != r))
                fz_fail("e57xml", "scan %u: role %d at field %d", i, r, s->role[r]);
        for (uint32_t f = 0; f < s->nfields; f++) {
            const e57_field *fl = &s->fields[f];
            int want = fl->kind == E57_FLOAT ? 32 : fl->kind == E57_DOUBLE ? 64 : -1;
            uint64_t range = (uint64_t)fl->max - (uint64_t)fl->min;
            if (want < 0) want = range ? 64 - __builtin_clzll(range) : 0;
            if (fl->bits != want || ((fl->kind == E57_INTEGER || fl->kind == E57_SCALED) && fl->min > fl->max))
                fz_fail("e57xml", "scan %u field %u: %d bits, kind %d", i, f, fl->bits, fl->kind);
        }
        /* the pose's rotation is orthonormal (a normalised quaternion) */
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++) {
                double dot = 0;
                for (int k = 0; k < 3; k++) dot += s->rot[3 * r + k] * s->rot[3 * c + k];
                if (!(fabs(dot - (r == c)) < 1e-9))
                    fz_fail("e57xml", "scan %u: rotation rows %d, %d: dot %g", i, r, c, dot);
            }
        int cart = s->role[E57_R_CX] >= 0 && s->role[E57_R_CY] >= 0 && s->role[E57_R_CZ] >= 0;
        if ((s->coords == E57_CARTESIAN) != cart)
            fz_fail("e57xml", "scan %u: coordinates %d, cartesian fields %d", i, s->coords, cart);
    }
    if (rc == 0) e57_desc_free(&a);
    if (rc1 == 0) e57_desc_free(&b);
    return rc;
}

int fuzz_one_e57bits(const uint8_t *data, size_t len)
{
    if (len < 5) return 0;
    e57_field f = {.kind = data[1] % 4, .scale = 0.5, .offset = -3};
    f.bits = f.kind == E57_FLOAT ? 32 : f.kind == E57_DOUBLE ? 64 : data[0] % 65;
    /* the raw range: 2^bits - 1 less the amount in data[2] (values above it are errors) */
    uint64_t full = f.bits == 64 ? UINT64_MAX : f.bits ? (UINT64_C(1) << f.bits) - 1 : 0;
    uint64_t range = full > data[2] ? full - data[2] : 0;
    if (f.bits && range && 64 - __builtin_clzll(range) != f.bits) range = full; /* keep the width */
    f.min = f.bits == 64 ? INT64_MIN : -7;
    f.max = (int64_t)((uint64_t)f.min + range);
    size_t piece = 1 + data[3] % 16;
    const uint8_t *s = data + 5;
    size_t n = len - 5;
    size_t total = f.bits ? n * 8 / (size_t)f.bits : (size_t)data[4];
    double *got = malloc((total ? total : 1) * sizeof *got);
    if (!got) abort();
    e57_bp b = {0};
    size_t fed = 0, done = 0;
    int64_t bad = -1;
    while (done < total) {
        size_t a = e57_bp_avail(&b, f.bits);
        if (a == 0) {
            size_t m = n - fed < piece ? n - fed : piece;
            if (m == 0) fz_fail("e57bits", "ran dry at value %zu of %zu", done, total);
            if (e57_bp_append(&b, s + fed, m) < 0) abort();
            fed += m;
            continue;
        }
        if (a > total - done) a = total - done;
        int64_t r = e57_bp_decode(&b, &f, got + done, a);
        if (r >= 0 && bad < 0) bad = (int64_t)done + r;
        done += a;
    }
    if (b.len > piece + 8) fz_fail("e57bits", "%zu bytes held with pieces of %zu", b.len, piece);
    e57_bp_free(&b);
    /* the reference: bit k of the stream is bit k % 8 of byte k / 8, one at a time */
    for (size_t i = 0; i < total; i++) {
        uint64_t raw = 0;
        for (int k = 0; k < f.bits; k++) {
            size_t bit = i * (size_t)f.bits + (size_t)k;
            raw |= (uint64_t)((s[bit / 8] >> (bit % 8)) & 1u) << k;
        }
        double want;
        if (f.kind == E57_FLOAT) {
            uint32_t w = (uint32_t)raw;
            float x;
            memcpy(&x, &w, 4);
            want = x;
        } else if (f.kind == E57_DOUBLE) {
            memcpy(&want, &raw, 8);
        } else {
            if (raw > range) {
                if (bad < 0 || (size_t)bad > i) fz_fail("e57bits", "value %zu over the range unflagged", i);
                if ((size_t)bad == i) break; /* the reader stops at the first */
                continue;
            }
            int64_t v = (int64_t)((uint64_t)f.min + raw);
            want = f.kind == E57_SCALED ? (double)v * f.scale + f.offset : (double)v;
        }
        if (memcmp(&want, &got[i], 8) != 0 && !(isnan(want) && isnan(got[i])))
            fz_fail("e57bits", "width %d kind %d value %zu: %.17g, the reference %.17g", f.bits,
                    f.kind, i, got[i], want);
    }
    free(got);
    return bad >= 0 ? SD_EFORMAT : 0;
}
