/* frame_lz4.c — the SPL4 frame header (frame_lz4.h). */
#include "frame_lz4.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static void put_u32le(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static uint32_t get_u32le(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

__attribute__((format(printf, 4, 5)))
static int fail(char *err, size_t errlen, int code, const char *fmt, ...)
{
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return code;
}

void sp_lz4_header_put(uint8_t out[SP_LZ4_HEADER_SIZE], uint32_t width, uint32_t height)
{
    memcpy(out, SP_LZ4_MAGIC, 4);
    put_u32le(out + 4, width);
    put_u32le(out + 8, height);
    put_u32le(out + 12, (uint32_t)((uint64_t)width * height * 4));
}

int sp_lz4_header_get(const uint8_t *data, size_t len, uint32_t *width, uint32_t *height,
                      char *err, size_t errlen)
{
    if (!data || len < SP_LZ4_HEADER_SIZE)
        return fail(err, errlen, SP_LZ4_ETRUNC, "lz4 frame: %zu bytes, shorter than the %d-byte "
                    "header", data ? len : 0, SP_LZ4_HEADER_SIZE);
    if (memcmp(data, SP_LZ4_MAGIC, 4) != 0)
        return fail(err, errlen, SP_LZ4_EFORMAT, "lz4 frame: bad magic at byte 0 (%02x %02x "
                    "%02x %02x, expected 'SPL4')", data[0], data[1], data[2], data[3]);
    uint32_t w = get_u32le(data + 4), h = get_u32le(data + 8), raw = get_u32le(data + 12);
    if (w < 1 || h < 1 || w > SP_FRAME_MAX_DIM || h > SP_FRAME_MAX_DIM)
        return fail(err, errlen, SP_LZ4_ELIMIT, "lz4 frame header (bytes 4-11): size %ux%u is "
                    "outside 1x1..%dx%d", w, h, SP_FRAME_MAX_DIM, SP_FRAME_MAX_DIM);
    if ((uint64_t)raw != (uint64_t)w * h * 4)
        return fail(err, errlen, SP_LZ4_EFORMAT, "lz4 frame: raw size %u at byte 12 is not "
                    "width*height*4 = %llu", raw, (unsigned long long)w * h * 4);
    uint64_t block = len - SP_LZ4_HEADER_SIZE;
    if ((uint64_t)raw > block * SP_LZ4_MAX_RATIO + 64)
        return fail(err, errlen, SP_LZ4_EFORMAT, "lz4 frame: raw size %u at byte 12 cannot come "
                    "out of a %llu-byte LZ4 block (at most %d:1)", raw, (unsigned long long)block,
                    SP_LZ4_MAX_RATIO);
    *width = w;
    *height = h;
    return SP_LZ4_OK;
}
