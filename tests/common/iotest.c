/* iotest.c — see iotest.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "iotest.h"
#include "testutil.h"

void io_put(io_buf *b, const void *p, size_t n)
{
    if (b->n + n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->n + n) cap *= 2;
        uint8_t *d = realloc(b->d, cap);
        if (!d) fail_msg("iotest: out of memory for %zu bytes", cap);
        b->d = d;
        b->cap = cap;
    }
    if (n) memcpy(b->d + b->n, p, n);
    b->n += n;
}

void io_printf(io_buf *b, const char *fmt, ...)
{
    char small[512];
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(small, sizeof small, fmt, ap);
    va_end(ap);
    if (k < 0) fail_msg("iotest: bad format %s", fmt);
    if ((size_t)k < sizeof small) {
        io_put(b, small, (size_t)k);
        return;
    }
    char *big = malloc((size_t)k + 1);
    if (!big) fail_msg("iotest: out of memory");
    va_start(ap, fmt);
    vsnprintf(big, (size_t)k + 1, fmt, ap);
    va_end(ap);
    io_put(b, big, (size_t)k);
    free(big);
}

void io_put_uint(io_buf *b, uint64_t v, unsigned size, int big)
{
    uint8_t t[8];
    if (size != 1 && size != 2 && size != 4 && size != 8) fail_msg("iotest: size %u", size);
    for (unsigned i = 0; i < size; i++) {
        unsigned shift = 8 * (big ? size - 1 - i : i);
        t[i] = (uint8_t)(v >> shift);
    }
    io_put(b, t, size);
}

void io_put_f32(io_buf *b, float v, int big)
{
    uint32_t bits;
    memcpy(&bits, &v, 4); /* the value's IEEE bit pattern, whatever the host's byte order */
    io_put_uint(b, bits, 4, big);
}

void io_put_f64(io_buf *b, double v, int big)
{
    uint64_t bits;
    memcpy(&bits, &v, 8);
    io_put_uint(b, bits, 8, big);
}

const char *io_save(const io_buf *b, const char *dir, const char *name, char *path, size_t len)
{
    snprintf(path, len, "%s/%s", dir, name);
    if (tu_write_file(path, b->d ? (const void *)b->d : "", b->n) != 0)
        fail_msg("iotest: cannot write %s", path);
    return path;
}

void io_free(io_buf *b)
{
    free(b->d);
    memset(b, 0, sizeof *b);
}

uint64_t io_get_uint(const uint8_t *p, unsigned size, int big)
{
    uint64_t v = 0;
    for (unsigned i = 0; i < size; i++) {
        unsigned shift = 8 * (big ? size - 1 - i : i);
        v |= (uint64_t)p[i] << shift;
    }
    return v;
}

int64_t io_get_int(const uint8_t *p, unsigned size, int big)
{
    uint64_t u = io_get_uint(p, size, big);
    if (size < 8 && (u >> (8 * size - 1)) & 1) u |= ~(uint64_t)0 << (8 * size);
    int64_t v;
    memcpy(&v, &u, 8);
    return v;
}

float io_get_f32(const uint8_t *p, int big)
{
    uint32_t bits = (uint32_t)io_get_uint(p, 4, big);
    float f;
    memcpy(&f, &bits, 4);
    return f;
}

double io_get_f64(const uint8_t *p, int big)
{
    uint64_t bits = io_get_uint(p, 8, big);
    double d;
    memcpy(&d, &bits, 8);
    return d;
}

void io_read_ok(int (*fn)(const char *, pc_raw *, sd_err *), const char *path, pc_raw *raw)
{
    sd_err e = {0};
    memset(raw, 0, sizeof *raw);
    int rc = fn(path, raw, &e);
    if (rc != 0) {
        pc_raw_free(raw);
        fail_msg("%s: %d %s", path, rc, e.msg);
    }
}

double io_ulp(double x)
{
    x = fabs(x);
    return nextafter(x, INFINITY) - x;
}

void io_check_raw_xyz(const pc_raw *raw, const double *want, size_t n, double tol,
                      const char *what)
{
    if (raw->n != n) fail_msg("%s: %zu points read, %zu written", what, raw->n, n);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double got = raw->xyz[3 * i + k], w = want[3 * i + k];
            if (!(fabs(got - w) <= tol))
                fail_msg("%s: point %zu axis %c: read %.17g, written %.17g (tolerance %g)", what,
                         i, "xyz"[k], got, w, tol);
        }
}

void io_check_cloud_xyz(const pc_cloud *c, const double *want, size_t n, double tol,
                        const char *what)
{
    if (c->n != n) fail_msg("%s: %zu points after pc_load, %zu written", what, c->n, n);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double pos = c->pos[3 * i + k], w = want[3 * i + k];
            double got = pos + c->offset[k];
            /* pos = float(want - offset): half a float ulp of |pos| (2^-24 relative), one
             * double rounding in the subtraction and one in the re-addition here. */
            double t = fabs(pos) * 0x1p-24 + io_ulp(w) + io_ulp(got) + tol;
            if (!(fabs(got - w) <= t))
                fail_msg("%s: point %zu axis %c: pos + offset %.17g, written %.17g (tolerance "
                         "%g)", what, i, "xyz"[k], got, w, t);
        }
}
