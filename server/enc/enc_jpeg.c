/* enc_jpeg.c — JPEG frames through TurboJPEG 2.1 (tjCompress2; the tj3 API does not exist in
 * 2.1.5). One tjhandle per encoder context and one worst-case output buffer, allocated with
 * tjBufSize for the frame size and reused with TJFLAG_NOREALLOC, as VirtualGL does: no
 * allocation per frame, and the buffer address handed out stays the same from frame to frame. */
#include <limits.h>
#include <turbojpeg.h>

#include "enc_internal.h"

/* tj_subsamp: the TurboJPEG subsampling of an SP_SUB_* value, or -1. */
static int tj_subsamp(int s)
{
    switch (s) {
    case SP_SUB_444: return TJSAMP_444;
    case SP_SUB_422: return TJSAMP_422;
    case SP_SUB_420: return TJSAMP_420;
    case SP_SUB_GRAY: return TJSAMP_GRAY;
    default: return -1;
    }
}

int enc__jpeg(enc_ctx *e, const rnd_frame *f, int quality, int subsampling, const uint8_t **out,
              size_t *len, sd_err *err)
{
    int samp = tj_subsamp(subsampling);
    if (samp < 0)
        return sd_errf(err, SD_EINVAL, "encoder: subsampling %d is not one of 444, 422, 420, "
                       "gray (0-3)", subsampling);
    /* Size the buffer for 4:4:4, the largest worst case, so that switching the subsampling
     * between frames does not reallocate either. */
    unsigned long need = tjBufSize(f->width, f->height, TJSAMP_444);
    if (need == (unsigned long)-1 || need > (unsigned long)INT_MAX)
        return sd_errf(err, SD_EINVAL, "encoder: TurboJPEG cannot size a %dx%d JPEG: %s",
                       f->width, f->height, tjGetErrorStr2(e->tj));
    if (need > e->jpeg_cap) {
        tjFree(e->jpeg);
        e->jpeg_cap = 0;
        e->jpeg = tjAlloc((int)need);
        if (!e->jpeg)
            return sd_errf(err, SD_ENOMEM, "encoder: out of memory for a %lu-byte JPEG buffer",
                           need);
        e->jpeg_cap = need;
    }
    unsigned char *dst = e->jpeg;
    unsigned long size = e->jpeg_cap;
    /* BOTTOMUP: the frame's rows are in GL order; TurboJPEG reads them bottom-up for free.
     * NOREALLOC: the buffer is big enough by construction; never let TurboJPEG swap it. */
    if (tjCompress2(e->tj, f->rgba8, f->width, f->width * 4, f->height, TJPF_RGBA, &dst, &size,
                    samp, quality, TJFLAG_NOREALLOC | TJFLAG_BOTTOMUP) != 0)
        return sd_errf(err, SD_EIO, "encoder: TurboJPEG failed on a %dx%d frame: %s", f->width,
                       f->height, tjGetErrorStr2(e->tj));
    *out = dst;
    *len = size;
    return 0;
}
