/* io_text.h — small helpers shared by the file readers (io_ply.c, io_xyz.c): the whole file
 * mapped read-only, a fast exact number parser that never reads past an end pointer, and
 * line/token scanning.
 *
 * Internal to the pc_ module, hence the pc__ prefix. None of these functions allocate except
 * pc__file_open, and none reads a byte at or after the end pointer it is given. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

/* A file mapped (or, for an empty file, not mapped) read-only in memory. */
typedef struct pc__file {
    const uint8_t *data; /* size bytes; a valid empty string when size is 0 */
    size_t size;
    void *map;           /* what munmap needs, NULL when nothing was mapped */
} pc__file;

/* pc__file_open: maps the regular file path read-only into f. Returns 0, or SD_EIO with err
 * naming the file and the system's reason (not a regular file: a FIFO is refused at once,
 * without waiting for a writer). f is zeroed on failure. Parse the bytes under pc__guarded. */
int pc__file_open(const char *path, pc__file *f, sd_err *err);

/* pc__file_close: unmaps f and zeroes it; safe to call twice. */
void pc__file_close(pc__file *f);

/* pc__guarded: returns parse(arg), run so that the file f shrinking under it (a SIGBUS on its
 * mapping) ends the parse with SD_EIO and err saying the file changed, instead of killing the
 * process. After such an end, parse has stopped mid-way: whatever it allocated must be
 * reachable from arg for the caller to free. Not reentrant within one thread. */
int pc__guarded(const pc__file *f, const char *path, int (*parse)(void *arg), void *arg,
                sd_err *err);

/* pc__is_space: 1 for the token separators of the text formats (space, tab, \r, \v, \f). */
static inline int pc__is_space(int c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* pc__parse_num: parses one decimal number (optionally signed, with fraction and exponent, or
 * nan/inf spelled as strtod accepts them) from [s, end). Returns the pointer just after the
 * number, or NULL when [s, end) does not start with a number. The result is correctly rounded:
 * short mantissas take the exact fast path (Clinger), everything else goes to strtod on a
 * NUL-terminated copy. Tokens longer than 400 bytes are rejected (NULL). */
const char *pc__parse_num(const char *s, const char *end, double *out);

/* pc__line_end: returns the pointer to the '\n' ending the line that starts at s, or end when
 * the last line has none. */
const char *pc__line_end(const char *s, const char *end);

/* pc__trim_cr: for a line [s, e) returns e moved back over one trailing '\r'. */
static inline const char *pc__trim_cr(const char *s, const char *e)
{
    return (e > s && e[-1] == '\r') ? e - 1 : e;
}
