/* lzf.c — LZF decompression through liblzf (Debian liblzf-dev), with errors that say where
 * (see lzf.h for the stream format). */
#include "lzf.h"

#include <errno.h>
#include <limits.h>
#include <liblzf/lzf.h> /* by its folder: the name lzf.h alone is this module's header */
#include <string.h>

/* explain: liblzf refused the stream (or decoded too little) and says only that: walks the
 * chunks again, copying nothing, to name the first one at fault and why. Always returns an
 * error code with err filled. */
static int explain(const uint8_t *in, size_t in_len, size_t out_len, const char *name,
                   uint64_t base, int lib_errno, sd_err *err)
{
    size_t ip = 0, op = 0;
    while (ip < in_len) {
        unsigned long long at = (unsigned long long)(base + ip);
        unsigned c = in[ip++];
        if (c < 32) {
            size_t run = (size_t)c + 1;
            if (run > in_len - ip)
                return sd_errf(err, SD_ETRUNC, "%s: LZF literal run of %zu bytes at offset %llu "
                               "is cut off by the end of the compressed data (%zu bytes left)",
                               name, run, at, in_len - ip);
            if (run > out_len - op)
                return sd_errf(err, SD_EFORMAT, "%s: LZF literal run of %zu bytes at offset %llu "
                               "overruns the declared uncompressed size %zu (at output byte %zu)",
                               name, run, at, out_len, op);
            ip += run;
            op += run;
            continue;
        }
        size_t len = c >> 5;
        if (len == 7 && ip < in_len) len += in[ip++];
        if (ip >= in_len)
            return sd_errf(err, SD_ETRUNC, "%s: LZF back reference at offset %llu is cut off by "
                           "the end of the compressed data", name, at);
        size_t dist = ((size_t)(c & 31) << 8) + in[ip++] + 1;
        len += 2;
        if (dist > op)
            return sd_errf(err, SD_EFORMAT, "%s: LZF back reference at offset %llu reaches %zu "
                           "bytes back but only %zu bytes have been decoded", name, at, dist, op);
        if (len > out_len - op)
            return sd_errf(err, SD_EFORMAT, "%s: LZF back reference of %zu bytes at offset %llu "
                           "overruns the declared uncompressed size %zu (at output byte %zu)",
                           name, len, at, out_len, op);
        op += len;
    }
    if (op != out_len)
        return sd_errf(err, SD_ETRUNC, "%s: LZF data ending at offset %llu decodes to %zu bytes, "
                       "but the header declares %zu", name, (unsigned long long)(base + in_len),
                       op, out_len);
    return sd_errf(err, SD_EFORMAT, "%s: liblzf refused the LZF data at offset %llu (%s)", name,
                   (unsigned long long)base, strerror(lib_errno));
}

int pc_lzf_decompress(const uint8_t *in, size_t in_len, uint8_t *out, size_t out_len,
                      const char *name, uint64_t base, sd_err *err)
{
    if (in_len > UINT_MAX || out_len > UINT_MAX)
        return sd_errf(err, SD_ELIMIT, "%s: LZF block at offset %llu is over 4 GiB (%zu bytes "
                       "compressed, %zu declared)", name, (unsigned long long)base, in_len, out_len);
    if (in_len == 0 && out_len == 0) return 0; /* liblzf's 0 would read as a failure */
    errno = 0;
    unsigned n = in_len ? lzf_decompress(in, (unsigned)in_len, out, (unsigned)out_len) : 0;
    if (n == out_len && n > 0) return 0;
    return explain(in, in_len, out_len, name, base, errno, err);
}
