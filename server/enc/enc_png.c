/* enc_png.c — PNG frames through libpng, written to memory (png_set_write_fn), 8-bit RGBA,
 * top-down rows read straight out of the bottom-up frame (no copy). zlib level 1: on rendered
 * frames it is several times faster than the default 6 for a file a little larger, and PNG is
 * the lossless format for saving frames, not for streaming them (that is LZ4's job). */
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <string.h>

#include "enc_internal.h"

enum { PNG_LEVEL = 1 };

/* on_error: libpng's fatal-error callback; keeps the message and jumps back to enc__png. */
static void on_error(png_structp png, png_const_charp msg)
{
    enc_ctx *e = png_get_error_ptr(png);
    snprintf(e->lib_msg, sizeof e->lib_msg, "%s", msg);
    png_longjmp(png, 1);
}

/* on_warning: libpng warnings are dropped (low-level modules do not log). */
static void on_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* on_write: appends len bytes to the context's output buffer. */
static void on_write(png_structp png, png_bytep data, size_t len)
{
    enc_ctx *e = png_get_io_ptr(png);
    if (enc__reserve(&e->buf, &e->buf_cap, e->buf_len + len)) png_error(png, "out of memory");
    memcpy(e->buf + e->buf_len, data, len);
    e->buf_len += len;
}

static void on_flush(png_structp png)
{
    (void)png;
}

/* write_png: the libpng calls, alone in a function so that nothing but png survives the
 * longjmp (locals changed after setjmp would need volatile). Returns 0 or -1 (message in
 * e->lib_msg). */
static int write_png(png_structp png, png_infop info, enc_ctx *e, const rnd_frame *f)
{
    if (setjmp(png_jmpbuf(png))) return -1;
    png_set_write_fn(png, e, on_write, on_flush);
    png_set_compression_level(png, PNG_LEVEL);
    /* One filter (UP) instead of libpng's adaptive choice: on the bench frame 33 ms and 950 KiB
     * against 50 ms and 913 KiB. */
    png_set_filter(png, 0, PNG_FILTER_UP);
    png_set_IHDR(png, info, (png_uint_32)f->width, (png_uint_32)f->height, 8,
                 PNG_COLOR_TYPE_RGB_ALPHA, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    size_t row = (size_t)f->width * 4;
    for (int y = f->height - 1; y >= 0; y--) png_write_row(png, f->rgba8 + (size_t)y * row);
    png_write_end(png, NULL);
    return 0;
}

int enc__png(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err)
{
    e->buf_len = 0;
    e->lib_msg[0] = 0;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, e, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!info) {
        png_destroy_write_struct(&png, NULL);
        return sd_errf(err, SD_ENOMEM, "encoder: libpng could not start (out of memory)");
    }
    int rc = write_png(png, info, e, f);
    png_destroy_write_struct(&png, &info);
    if (rc)
        return sd_errf(err, strcmp(e->lib_msg, "out of memory") == 0 ? SD_ENOMEM : SD_EIO,
                       "encoder: libpng failed on a %dx%d frame: %s", f->width, f->height,
                       e->lib_msg);
    *out = e->buf;
    *len = e->buf_len;
    return 0;
}
