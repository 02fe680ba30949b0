/* encode.c — the encoder context, format dispatch and atomic file output (see encode.h).
 * The codecs live in enc_jpeg.c, enc_png.c, enc_lz4.c (lz4 and raw) and enc_exr.c. */
#include "encode.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <turbojpeg.h>
#include <unistd.h>

#include "enc_internal.h"

enc_ctx *enc_create(sd_err *err)
{
    enc_ctx *e = calloc(1, sizeof *e);
    if (!e) {
        sd_errf(err, SD_ENOMEM, "encoder: out of memory creating an encoder context");
        return NULL;
    }
    e->tj = tjInitCompress();
    if (!e->tj) {
        sd_errf(err, SD_EINVAL, "encoder: TurboJPEG failed to start: %s", tjGetErrorStr2(NULL));
        free(e);
        return NULL;
    }
    e->exr_compression = ENC_EXR_PIZ;
    return e;
}

void enc_destroy(enc_ctx *e)
{
    if (!e) return;
    if (e->tj) tjDestroy(e->tj);
    tjFree(e->jpeg);
    free(e->buf);
    free(e->scratch);
    memset(e, 0, sizeof *e);
    free(e);
}

int enc_set_exr_compression(enc_ctx *e, enc_exr_compression c, sd_err *err)
{
    if (!e || c < ENC_EXR_PIZ || c > ENC_EXR_NONE)
        return sd_errf(err, SD_EINVAL, "encoder: EXR compression %d is not one of piz, zip, rle, "
                       "none (0-3)", (int)c);
    e->exr_compression = c;
    return 0;
}

int enc__reserve(uint8_t **buf, size_t *cap, size_t need)
{
    if (need <= *cap) return 0;
    size_t n = *cap ? *cap : 4096;
    while (n < need) n = n > SIZE_MAX / 2 ? need : n * 2;
    uint8_t *p = realloc(*buf, n);
    if (!p) return SD_ENOMEM;
    *buf = p;
    *cap = n;
    return 0;
}

void enc__flip_rows(uint8_t *dst, const uint8_t *src, size_t row_bytes, int height)
{
    for (int y = 0; y < height; y++)
        memcpy(dst + (size_t)y * row_bytes, src + (size_t)(height - 1 - y) * row_bytes, row_bytes);
}

/* check_frame: 0 when f has a usable size and RGBA8 pixels, else SD_EINVAL with err. */
static int check_frame(const rnd_frame *f, sd_err *err)
{
    if (!f) return sd_errf(err, SD_EINVAL, "encoder: no frame given");
    if (f->width < 1 || f->height < 1 || f->width > ENC_MAX_DIM || f->height > ENC_MAX_DIM)
        return sd_errf(err, SD_EINVAL, "encoder: frame size %dx%d is outside 1x1..%dx%d",
                       f->width, f->height, ENC_MAX_DIM, ENC_MAX_DIM);
    if (!f->rgba8) return sd_errf(err, SD_EINVAL, "encoder: frame %dx%d has no RGBA8 pixels",
                                  f->width, f->height);
    return 0;
}

int enc_encode(enc_ctx *e, const rnd_frame *f, const sp_params *p, const uint8_t **out,
               size_t *out_len, sd_err *err)
{
    if (!e || !p || !out || !out_len)
        return sd_errf(err, SD_EINVAL, "encoder: enc_encode needs a context, parameters and "
                       "output pointers");
    *out = NULL;
    *out_len = 0;
    int rc = check_frame(f, err);
    if (rc) return rc;
    switch (p->format) {
    case SP_FMT_JPEG:
        if (p->quality < 1 || p->quality > 100)
            return sd_errf(err, SD_EINVAL, "encoder: quality %lld is outside 1..100",
                           (long long)p->quality);
        return enc__jpeg(e, f, (int)p->quality, p->subsampling, out, out_len, err);
    case SP_FMT_PNG: return enc__png(e, f, out, out_len, err);
    case SP_FMT_LZ4: return enc__lz4(e, f, out, out_len, err);
    case SP_FMT_RAW: return enc__raw(e, f, out, out_len, err);
    case SP_FMT_EXR: return enc__exr(e, f, out, out_len, err);
    default:
        return sd_errf(err, SD_EINVAL, "encoder: format %d is not one of jpeg, png, lz4, raw, "
                       "exr (0-4)", (int)p->format);
    }
}

int enc_format_from_path(const char *path, sd_err *err)
{
    static const struct { const char *ext; int fmt; } exts[] = {
        { "jpg", SP_FMT_JPEG }, { "jpeg", SP_FMT_JPEG }, { "png", SP_FMT_PNG },
        { "exr", SP_FMT_EXR },  { "raw", SP_FMT_RAW },
    };
    if (!path || !*path) return sd_errf(err, SD_EINVAL, "encoder: empty output file name");
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    const char *dot = strrchr(base, '.');
    if (!dot || dot == base || !dot[1])
        return sd_errf(err, SD_EINVAL, "%s: the file name has no extension; use .jpg, .jpeg, "
                       ".png, .exr or .raw", path);
    for (size_t i = 0; i < sizeof exts / sizeof exts[0]; i++)
        if (strcasecmp(dot + 1, exts[i].ext) == 0) return exts[i].fmt;
    return sd_errf(err, SD_EINVAL, "%s: unknown image extension \"%s\"; use .jpg, .jpeg, .png, "
                   ".exr or .raw", path, dot);
}

/* open_temp: creates a new file next to path (same directory, so rename is atomic) named
 * "path.tmp.PID.N" with O_EXCL, mode 0666 before the umask like any new file. Returns the fd
 * and fills tmp, or -1 with errno set. */
static int open_temp(const char *path, char *tmp, size_t tmplen)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    unsigned long n = (unsigned long)ts.tv_nsec ^ ((unsigned long)ts.tv_sec << 20);
    for (int attempt = 0; attempt < 16; attempt++, n = n * 6364136223846793005ul + 1) {
        int k = snprintf(tmp, tmplen, "%s.tmp.%ld.%lx", path, (long)getpid(), n & 0xffffffu);
        if (k < 0 || (size_t)k >= tmplen) { errno = ENAMETOOLONG; return -1; }
        int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd >= 0 || errno != EEXIST) return fd;
    }
    return -1;
}

/* write_all: writes len bytes to fd, retrying short writes and EINTR; 0 or -1 with errno. */
static int write_all(int fd, const uint8_t *p, size_t len)
{
    while (len > 0) {
        ssize_t w = write(fd, p, len);
        if (w < 0) {
            if (errno == EINTR) continue;
            return -1;
        }
        p += w;
        len -= (size_t)w;
    }
    return 0;
}

/* write_atomic: writes bytes to a temporary file beside path and renames it over path. No
 * fsync: a frame is cheap to render again, and the rename already guarantees readers never
 * see a partial file while the system stays up. Returns 0 or SD_EIO with err. */
static int write_atomic(const char *path, const uint8_t *bytes, size_t len, sd_err *err)
{
    char tmp[4096 + 64];
    int fd = open_temp(path, tmp, sizeof tmp);
    if (fd < 0)
        return sd_errf(err, SD_EIO, "%s: cannot create a temporary file beside it: %s", path,
                       strerror(errno));
    int rc = write_all(fd, bytes, len);
    int saved = errno;
    if (close(fd) != 0 && rc == 0) { rc = -1; saved = errno; }
    if (rc != 0) {
        unlink(tmp);
        return sd_errf(err, SD_EIO, "%s: writing %zu bytes failed: %s", path, len,
                       strerror(saved));
    }
    if (rename(tmp, path) != 0) {
        saved = errno;
        unlink(tmp);
        return sd_errf(err, SD_EIO, "%s: cannot rename the finished temporary file into place: "
                       "%s", path, strerror(saved));
    }
    return 0;
}

/* enc_write_file encodes in memory and writes the bytes atomically, for every format: one
 * code path (the daemon's), and the temporary-file logic exists once. An EXR frame is a few
 * MB, so holding it in memory first costs nothing that matters. */
int enc_write_file(const char *path, const rnd_frame *f, const sp_params *p, sd_err *err)
{
    int fmt = enc_format_from_path(path, err);
    if (fmt < 0) return fmt;
    sp_params params;
    if (p) params = *p; else sp_params_defaults(&params);
    params.format = fmt;

    enc_ctx *e = enc_create(err);
    if (!e) return err ? err->code : SD_ENOMEM;
    const uint8_t *bytes;
    size_t len;
    int rc = enc_encode(e, f, &params, &bytes, &len, err);
    if (rc) {
        /* Name the file too: the codec message names only the frame. */
        if (err) {
            char msg[sizeof err->msg];
            memcpy(msg, err->msg, sizeof msg);
            msg[sizeof msg - 1] = 0;
            sd_errf(err, rc, "%s: %.400s", path, msg);
        }
    } else {
        rc = write_atomic(path, bytes, len, err);
    }
    enc_destroy(e);
    return rc;
}
