/* enc_exr.c — EXR frames through the OpenEXR 3.1 C API (OpenEXRCore): one scanline part with
 * channels A, B, G, R (half, from rgba16f) and Z (float, eye-space depth; +inf where empty),
 * increasing-Y line order, PIZ by default. The file is written to memory through a custom
 * write function; enc_write_file then writes those bytes atomically like any other format.
 *
 * Sequence: exr_start_write (custom write_fn) -> exr_add_part -> exr_initialize_required_attr_
 * simple -> exr_add_channel x5 -> exr_write_header -> per chunk of scanlines:
 * exr_write_scanline_chunk_info, exr_encoding_initialize (first) / exr_encoding_update,
 * channel pointers, exr_encoding_choose_default_routines (first), exr_encoding_run ->
 * exr_encoding_destroy -> exr_finish (writes the chunk offset table). */
#include <openexr.h>
#include <stdio.h>
#include <string.h>

#include "enc_internal.h"

/* on_exr_error: OpenEXR's error callback; keeps the detailed message in the context (the
 * default handler would print to stderr, and low-level modules do not log). */
static void on_exr_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *ud = NULL;
    if (exr_get_user_data(ctxt, &ud) != EXR_ERR_SUCCESS || !ud) return;
    enc_ctx *e = ud;
    snprintf(e->lib_msg, sizeof e->lib_msg, "%s (%s)", msg ? msg : "",
             exr_get_error_code_as_string(code));
}

/* on_exr_write: pwrite-like writer into the context's output buffer. The library writes the
 * header, leaves room for the chunk offset table, writes the chunks, then fills the table at
 * exr_finish, so a write may land beyond the current end (the gap is zeroed) or inside it. */
static int64_t on_exr_write(exr_const_context_t ctxt, void *ud, const void *buf, uint64_t sz,
                            uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    enc_ctx *e = ud;
    if (offset > SIZE_MAX - sz ||
        enc__reserve(&e->buf, &e->buf_cap, (size_t)(offset + sz)) != 0) {
        error_cb(ctxt, EXR_ERR_OUT_OF_MEMORY, "out of memory for %llu bytes at offset %llu",
                 (unsigned long long)sz, (unsigned long long)offset);
        return -1;
    }
    if (offset > e->buf_len) memset(e->buf + e->buf_len, 0, (size_t)offset - e->buf_len);
    memcpy(e->buf + offset, buf, (size_t)sz);
    if (offset + sz > e->buf_len) e->buf_len = (size_t)(offset + sz);
    return (int64_t)sz;
}

static exr_compression_t exr_comp(enc_exr_compression c)
{
    switch (c) {
    case ENC_EXR_ZIP: return EXR_COMPRESSION_ZIP;
    case ENC_EXR_RLE: return EXR_COMPRESSION_RLE;
    case ENC_EXR_NONE: return EXR_COMPRESSION_NONE;
    default: return EXR_COMPRESSION_PIZ;
    }
}

/* fill_chunk: copies the chunk's scanlines (EXR rows y0..y0+n-1, top-down) out of the
 * bottom-up frame into the scratch buffer ([n rows RGBA half][n rows Z float]) and points the
 * pipeline's channels at them. */
static void fill_chunk(exr_encode_pipeline_t *enc, const rnd_frame *f, uint8_t *scratch,
                       int y0, int n)
{
    size_t crow = (size_t)f->width * 8, zrow = (size_t)f->width * 4;
    uint8_t *color = scratch, *depth = scratch + crow * (size_t)n;
    for (int i = 0; i < n; i++) {
        size_t src = (size_t)(f->height - 1 - (y0 + i));
        memcpy(color + crow * (size_t)i, (const uint8_t *)f->rgba16f + crow * src, crow);
        memcpy(depth + zrow * (size_t)i, (const uint8_t *)f->depth + zrow * src, zrow);
    }
    for (int c = 0; c < enc->channel_count; c++) {
        exr_coding_channel_info_t *ch = &enc->channels[c];
        const char *name = ch->channel_name;
        if (strcmp(name, "Z") == 0) {
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_bytes_per_element = 4;
            ch->user_pixel_stride = 4;
            ch->user_line_stride = (int32_t)zrow;
            ch->encode_from_ptr = depth;
        } else {
            int k = name[0] == 'R' ? 0 : name[0] == 'G' ? 1 : name[0] == 'B' ? 2 : 3;
            ch->user_data_type = EXR_PIXEL_HALF;
            ch->user_bytes_per_element = 2;
            ch->user_pixel_stride = 8;
            ch->user_line_stride = (int32_t)crow;
            ch->encode_from_ptr = color + 2 * k;
        }
    }
}

/* write_parts: defines the part and writes every chunk into the open context ctx. Returns an
 * exr_result_t; *step names the call that failed. */
static exr_result_t write_parts(exr_context_t ctx, enc_ctx *e, const rnd_frame *f,
                                const char **step)
{
    static const char *names[] = { "A", "B", "G", "R", "Z" }; /* sorted, as EXR stores them */
    int part = 0;
    exr_result_t r;
    *step = "exr_add_part";
    if ((r = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part))) return r;
    *step = "exr_initialize_required_attr_simple";
    if ((r = exr_initialize_required_attr_simple(ctx, part, f->width, f->height,
                                                 exr_comp(e->exr_compression))))
        return r;
    *step = "exr_add_channel";
    for (int c = 0; c < 5; c++) {
        if ((r = exr_add_channel(ctx, part, names[c], c == 4 ? EXR_PIXEL_FLOAT : EXR_PIXEL_HALF,
                                 c == 4 ? EXR_PERCEPTUALLY_LINEAR : EXR_PERCEPTUALLY_LOGARITHMIC,
                                 1, 1)))
            return r;
    }
    *step = "exr_write_header";
    if ((r = exr_write_header(ctx))) return r;
    int32_t lines = 0;
    *step = "exr_get_scanlines_per_chunk";
    if ((r = exr_get_scanlines_per_chunk(ctx, part, &lines))) return r;
    if (lines < 1) return EXR_ERR_INVALID_ARGUMENT;
    size_t need = (size_t)f->width * 12 * (size_t)lines;
    *step = "allocating the chunk buffer";
    if (enc__reserve(&e->scratch, &e->scratch_cap, need)) return EXR_ERR_OUT_OF_MEMORY;

    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int started = 0;
    for (int y = 0; y < f->height && r == EXR_ERR_SUCCESS; y += lines) {
        exr_chunk_info_t ci;
        *step = "exr_write_scanline_chunk_info";
        if ((r = exr_write_scanline_chunk_info(ctx, part, y, &ci))) break;
        *step = started ? "exr_encoding_update" : "exr_encoding_initialize";
        r = started ? exr_encoding_update(ctx, part, &ci, &enc)
                    : exr_encoding_initialize(ctx, part, &ci, &enc);
        if (r) break;
        fill_chunk(&enc, f, e->scratch, ci.start_y, ci.height);
        if (!started) {
            started = 1;
            *step = "exr_encoding_choose_default_routines";
            if ((r = exr_encoding_choose_default_routines(ctx, part, &enc))) break;
        }
        *step = "exr_encoding_run";
        r = exr_encoding_run(ctx, part, &enc);
    }
    if (started) {
        exr_result_t r2 = exr_encoding_destroy(ctx, &enc);
        if (r == EXR_ERR_SUCCESS) { r = r2; *step = "exr_encoding_destroy"; }
    }
    return r;
}

int enc__exr(enc_ctx *e, const rnd_frame *f, const uint8_t **out, size_t *len, sd_err *err)
{
    if (!f->rgba16f || !f->depth)
        return sd_errf(err, SD_EINVAL, "encoder: EXR needs the float colour and depth of the "
                       "frame (%dx%d), and the frame has no %s; render it with float output",
                       f->width, f->height, !f->rgba16f ? "half RGBA" : "depth");
    e->buf_len = 0;
    e->lib_msg[0] = 0;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = on_exr_error;
    init.user_data = e;
    init.write_fn = on_exr_write;
    init.max_image_width = ENC_MAX_DIM;
    init.max_image_height = ENC_MAX_DIM;
    exr_context_t ctx = NULL;
    const char *step = "exr_start_write";
    /* The name is only informational with a custom write_fn. */
    exr_result_t r = exr_start_write(&ctx, "frame.exr", EXR_WRITE_FILE_DIRECTLY, &init);
    if (r == EXR_ERR_SUCCESS) r = write_parts(ctx, e, f, &step);
    if (ctx) {
        exr_result_t r2 = exr_finish(&ctx);
        if (r == EXR_ERR_SUCCESS && r2 != EXR_ERR_SUCCESS) { r = r2; step = "exr_finish"; }
    }
    if (r != EXR_ERR_SUCCESS)
        return sd_errf(err, r == EXR_ERR_OUT_OF_MEMORY ? SD_ENOMEM : SD_EIO,
                       "encoder: OpenEXR failed in %s on a %dx%d frame: %s%s%s", step, f->width,
                       f->height, exr_get_default_error_message(r), e->lib_msg[0] ? ": " : "",
                       e->lib_msg);
    *out = e->buf;
    *len = e->buf_len;
    return 0;
}
