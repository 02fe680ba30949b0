/* lzf.c — bounds-checked LZF decompression (see lzf.h for the stream format). */
#include "lzf.h"

#include <string.h>

/* The error for a back reference whose length or distance byte lies past the input's end. */
static int cut_off(const char *name, uint64_t at, sd_err *err)
{
    return sd_errf(err, SD_ETRUNC, "%s: LZF back reference at offset %llu is cut off by the end "
                   "of the compressed data", name, (unsigned long long)at);
}

int pc_lzf_decompress(const uint8_t *in, size_t in_len, uint8_t *out, size_t out_len,
                      const char *name, uint64_t base, sd_err *err)
{
    size_t ip = 0, op = 0;
    while (ip < in_len) {
        size_t chunk = ip; /* for messages: where this chunk starts */
        unsigned c = in[ip++];
        if (c < 32) {
            size_t run = (size_t)c + 1;
            if (run > in_len - ip)
                return sd_errf(err, SD_ETRUNC,
                               "%s: LZF literal run of %zu bytes at offset %llu is cut off by "
                               "the end of the compressed data (%zu bytes left)",
                               name, run, (unsigned long long)(base + chunk), in_len - ip);
            if (run > out_len - op)
                return sd_errf(err, SD_EFORMAT,
                               "%s: LZF literal run of %zu bytes at offset %llu overruns the "
                               "declared uncompressed size %zu (at output byte %zu)",
                               name, run, (unsigned long long)(base + chunk), out_len, op);
            if (in_len - ip >= 32 && out_len - op >= 32)
                memcpy(out + op, in + ip, 32); /* fixed size: two vector moves; the bytes past
                                                  run are inside out and rewritten later */
            else
                memcpy(out + op, in + ip, run);
            ip += run;
            op += run;
            continue;
        }
        size_t len = c >> 5;
        if (len == 7) {
            if (ip >= in_len) return cut_off(name, base + chunk, err);
            len += in[ip++];
        }
        if (ip >= in_len) return cut_off(name, base + chunk, err);
        size_t dist = ((size_t)(c & 31) << 8) + in[ip++] + 1;
        len += 2;
        if (dist > op)
            return sd_errf(err, SD_EFORMAT,
                           "%s: LZF back reference at offset %llu reaches %zu bytes back but "
                           "only %zu bytes have been decoded",
                           name, (unsigned long long)(base + chunk), dist, op);
        if (len > out_len - op)
            return sd_errf(err, SD_EFORMAT,
                           "%s: LZF back reference of %zu bytes at offset %llu overruns the "
                           "declared uncompressed size %zu (at output byte %zu)",
                           name, len, (unsigned long long)(base + chunk), out_len, op);
        if (dist >= 16 && out_len - op >= ((len + 15) & ~(size_t)15)) {
            /* 16-byte blocks: each reads bytes at least 16 back, all already written. */
            for (size_t k = 0; k < len; k += 16) memcpy(out + op + k, out + op + k - dist, 16);
        } else if (dist >= len) {
            memcpy(out + op, out + op - dist, len);
        } else if (dist == 1) {
            memset(out + op, out[op - 1], len);
        } else {
            /* The copy overlaps its source: the output repeats its last dist bytes. Any
             * multiple of dist back is the same pattern, so copy from ever further back in
             * doubling, non-overlapping chunks (dist, 2 dist, 4 dist, ...). */
            size_t done = 0, period = dist;
            while (done < len) {
                size_t n = len - done < period ? len - done : period;
                memcpy(out + op + done, out + op + done - period, n);
                done += n;
                period *= 2;
            }
        }
        op += len;
    }
    if (op != out_len)
        return sd_errf(err, SD_ETRUNC,
                       "%s: LZF data ending at offset %llu decodes to %zu bytes, but the header "
                       "declares %zu",
                       name, (unsigned long long)(base + in_len), op, out_len);
    return 0;
}
