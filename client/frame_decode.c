/* frame_decode.c — FRAME payload decoding for the client library (see frame_decode.h). */
#include "frame_decode.h"

#include <lz4.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <turbojpeg.h>

#include "frame_lz4.h"
#include "params.h"

struct fd_ctx {
    tjhandle tj;       /* decompression handle */
    uint8_t *out;      /* decoded RGBA8 */
    size_t out_cap;
};

/* fd_errf: writes a message to err (when not NULL) and returns code: the client library's own
 * formatter over a caller's buffer (it shares no error code with the daemon). */
__attribute__((format(printf, 4, 5)))
static int fd_errf(char *err, size_t errlen, int code, const char *fmt, ...)
{
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return code;
}

fd_ctx *fd_create(char *err, size_t errlen)
{
    fd_ctx *d = calloc(1, sizeof *d);
    if (!d) {
        fd_errf(err, errlen, FD_ENOMEM, "frame decoder: out of memory");
        return NULL;
    }
    d->tj = tjInitDecompress();
    if (!d->tj) {
        fd_errf(err, errlen, FD_EINVAL, "frame decoder: TurboJPEG failed to start: %s",
                tjGetErrorStr2(NULL));
        free(d);
        return NULL;
    }
    return d;
}

void fd_destroy(fd_ctx *d)
{
    if (!d) return;
    if (d->tj) tjDestroy(d->tj);
    free(d->out);
    memset(d, 0, sizeof *d);
    free(d);
}

/* reserve: makes d->out hold need bytes (old contents dropped); 0 or FD_ENOMEM. */
static int reserve(fd_ctx *d, size_t need)
{
    if (need <= d->out_cap) return 0;
    uint8_t *p = malloc(need);
    if (!p) return FD_ENOMEM;
    free(d->out);
    d->out = p;
    d->out_cap = need;
    return 0;
}

/* check_dims: 0 when w x h is within 1..SP_FRAME_MAX_DIM and matches the announced size (when
 * given); FD_ELIMIT or FD_EFORMAT with err otherwise. what names the payload. */
static int check_dims(const char *what, long long w, long long h, int want_w, int want_h,
                      char *err, size_t errlen)
{
    if (w < 1 || h < 1 || w > SP_FRAME_MAX_DIM || h > SP_FRAME_MAX_DIM)
        return fd_errf(err, errlen, FD_ELIMIT, "%s: size %lldx%lld is outside 1x1..%dx%d", what,
                       w, h, SP_FRAME_MAX_DIM, SP_FRAME_MAX_DIM);
    if ((want_w > 0 && w != want_w) || (want_h > 0 && h != want_h))
        return fd_errf(err, errlen, FD_EFORMAT, "%s: size %lldx%lld differs from the frame's "
                       "announced %dx%d", what, w, h, want_w, want_h);
    return 0;
}

int fd_lz4_header(const uint8_t *data, size_t len, int *width, int *height, char *err,
                  size_t errlen)
{
    uint32_t w, h;
    switch (sp_lz4_header_get(data, len, &w, &h, err, errlen)) {
    case SP_LZ4_OK: break;
    case SP_LZ4_ETRUNC: return FD_ETRUNC;
    case SP_LZ4_ELIMIT: return FD_ELIMIT;
    default: return FD_EFORMAT;
    }
    *width = (int)w;
    *height = (int)h;
    return 0;
}

/* decode_lz4: SPL4 payload -> d->out. */
static int decode_lz4(fd_ctx *d, const uint8_t *data, size_t len, int want_w, int want_h,
                      int *w, int *h, char *err, size_t errlen)
{
    int rc = fd_lz4_header(data, len, w, h, err, errlen);
    if (rc) return rc;
    if ((rc = check_dims("lz4 frame", *w, *h, want_w, want_h, err, errlen))) return rc;
    size_t raw = (size_t)*w * (size_t)*h * 4, block = len - SP_LZ4_HEADER_SIZE;
    if (block > (size_t)LZ4_MAX_INPUT_SIZE)
        return fd_errf(err, errlen, FD_ELIMIT, "lz4 frame: a %zu-byte LZ4 block is over LZ4's "
                       "limit", block);
    if (reserve(d, raw))
        return fd_errf(err, errlen, FD_ENOMEM, "lz4 frame: out of memory for %zu bytes", raw);
    int n = LZ4_decompress_safe((const char *)data + SP_LZ4_HEADER_SIZE, (char *)d->out,
                                (int)block, (int)raw);
    if (n < 0)
        return fd_errf(err, errlen, FD_EFORMAT, "lz4 frame: the LZ4 block (bytes %d-%zu) is "
                       "corrupt or truncated (error at block byte %d)", SP_LZ4_HEADER_SIZE,
                       len - 1, -n - 1);
    if ((size_t)n != raw)
        return fd_errf(err, errlen, FD_ETRUNC, "lz4 frame: the LZ4 block decodes to %d bytes, "
                       "the header says %zu", n, raw);
    return 0;
}

/* decode_jpeg: JPEG payload -> d->out as RGBA8 (grayscale JPEGs are expanded to RGB). */
static int decode_jpeg(fd_ctx *d, const uint8_t *data, size_t len, int want_w, int want_h,
                       int *w, int *h, char *err, size_t errlen)
{
    int samp = 0, cs = 0;
    if (!data || len == 0 || len > 0xffffffffu)
        return fd_errf(err, errlen, FD_EFORMAT, "jpeg frame: %zu bytes is not a JPEG size", len);
    if (tjDecompressHeader3(d->tj, data, (unsigned long)len, w, h, &samp, &cs) != 0)
        return fd_errf(err, errlen, FD_EFORMAT, "jpeg frame: bad header: %s",
                       tjGetErrorStr2(d->tj));
    int rc = check_dims("jpeg frame", *w, *h, want_w, want_h, err, errlen);
    if (rc) return rc;
    size_t raw = (size_t)*w * (size_t)*h * 4;
    if (reserve(d, raw))
        return fd_errf(err, errlen, FD_ENOMEM, "jpeg frame: out of memory for %zu bytes", raw);
    /* A warning (e.g. premature end of data) also returns -1: a damaged frame is an error. */
    if (tjDecompress2(d->tj, data, (unsigned long)len, d->out, *w, *w * 4, *h, TJPF_RGBA, 0) != 0)
        return fd_errf(err, errlen, FD_EFORMAT, "jpeg frame: %dx%d: %s", *w, *h,
                       tjGetErrorStr2(d->tj));
    return 0;
}

int fd_decode(fd_ctx *d, int fmt, const uint8_t *data, size_t len, int width, int height,
              const uint8_t **rgba, int *out_w, int *out_h, char *err, size_t errlen)
{
    if (!d || !rgba) return fd_errf(err, errlen, FD_EINVAL, "frame decoder: no decoder given");
    *rgba = NULL;
    int w = 0, h = 0, rc;
    switch (fmt) {
    case SP_FMT_JPEG: rc = decode_jpeg(d, data, len, width, height, &w, &h, err, errlen); break;
    case SP_FMT_LZ4: rc = decode_lz4(d, data, len, width, height, &w, &h, err, errlen); break;
    case SP_FMT_RAW:
        if (width < 1 || height < 1)
            return fd_errf(err, errlen, FD_EINVAL, "raw frame: the frame size must be given");
        if ((rc = check_dims("raw frame", width, height, 0, 0, err, errlen))) return rc;
        if (!data || len != (size_t)width * (size_t)height * 4)
            return fd_errf(err, errlen, len < (size_t)width * height * 4 ? FD_ETRUNC : FD_EFORMAT,
                           "raw frame: %zu bytes, expected %dx%dx4 = %zu", len, width, height,
                           (size_t)width * height * 4);
        *rgba = data;
        if (out_w) *out_w = width;
        if (out_h) *out_h = height;
        return 0;
    default: {
        char name[16];
        const char *n = sp_enum_name(SP_FORMAT, fmt, name, sizeof name);
        return fd_errf(err, errlen, FD_EUNSUP, "frame decoder: format %s is not decoded by the "
                       "client (jpeg, lz4 and raw are)", n ? n : "(unknown)");
    }
    }
    if (rc) return rc;
    *rgba = d->out;
    if (out_w) *out_w = w;
    if (out_h) *out_h = h;
    return 0;
}
