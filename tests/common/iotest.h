/* iotest.h — what the file-reader tests (test_io_*.c) share: a growable byte buffer with its
 * own little- and big-endian writers, the matching independent decoders for reading real files
 * without the readers under test, and point-by-point checks of a reader's output.
 *
 * The writers put every multi-byte value out one byte at a time with shifts, so they do not
 * depend on the host's byte order or on the memcpy/bswap code the readers use. Floats go out
 * as their IEEE bit patterns. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "cloud.h"

typedef struct io_buf {
    uint8_t *d;
    size_t n, cap;
} io_buf;

/* io_put: appends n bytes. io_printf: appends formatted text (no terminating NUL). */
void io_put(io_buf *b, const void *p, size_t n);
void io_printf(io_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* io_put_uint: appends the low size bytes (1, 2, 4 or 8) of v, most significant byte first
 * when big is non-zero, least significant first otherwise. Signed values go in as their
 * two's-complement bits: io_put_uint(b, (uint64_t)(int64_t)-5, 2, 0). */
void io_put_uint(io_buf *b, uint64_t v, unsigned size, int big);
void io_put_f32(io_buf *b, float v, int big);
void io_put_f64(io_buf *b, double v, int big);

/* io_save: writes the buffer to dir/name, puts the path in path and returns it. */
const char *io_save(const io_buf *b, const char *dir, const char *name, char *path, size_t len);
void io_free(io_buf *b);

/* Independent decoders: the value of size bytes at p in the given byte order (signed ones
 * sign-extended), and IEEE floats from their bytes. */
uint64_t io_get_uint(const uint8_t *p, unsigned size, int big);
int64_t io_get_int(const uint8_t *p, unsigned size, int big);
float io_get_f32(const uint8_t *p, int big);
double io_get_f64(const uint8_t *p, int big);

/* io_read_ok: the reader fn on path into raw (zeroed first); fails the test on an error. */
void io_read_ok(int (*fn)(const char *, pc_raw *, sd_err *), const char *path, pc_raw *raw);

/* io_check_raw_xyz: raw holds exactly n points and point i is want[3i..3i+2] within tol on
 * every axis (tol 0: the same double). what names the file in the failure message. */
void io_check_raw_xyz(const pc_raw *raw, const double *want, size_t n, double tol,
                      const char *what);

/* io_check_cloud_xyz: the finalised cloud c holds exactly n points in the file's order and
 * pos + offset of point i equals want[3i..] within the rounding of pos to float (half an ulp
 * of |pos|, plus the double rounding of the subtraction and of the re-addition) plus tol. */
void io_check_cloud_xyz(const pc_cloud *c, const double *want, size_t n, double tol,
                        const char *what);

/* io_ulp: the gap between |x| and the next larger double (the unit in the last place). */
double io_ulp(double x);
