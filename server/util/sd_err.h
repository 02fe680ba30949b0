/* sd_err.h — the one error convention of splatd.
 *
 * Functions return int: 0 on success, a negative SD_E* code on failure, and fill the caller's
 * sd_err with a full sentence that names what was wrong and where (file and byte offset or line,
 * parameter and range). Low-level modules never log; the caller decides what to print. */
#pragma once
#include <stddef.h>

#define SD_ERRORS(X)                                                  \
    X(SD_EIO,       -1, "input/output error")                         \
    X(SD_EFORMAT,   -2, "malformed input")                            \
    X(SD_EUNSUP,    -3, "unsupported feature or version")             \
    X(SD_ENOMEM,    -4, "out of memory")                              \
    X(SD_EINVAL,    -5, "invalid argument")                           \
    X(SD_ETRUNC,    -6, "input truncated")                            \
    X(SD_ELIMIT,    -7, "size over a limit")                          \
    X(SD_EGL,       -8, "graphics error")                             \
    X(SD_ESTALE,    -9, "stale or corrupt cache")                     \
    X(SD_EEMPTY,   -10, "no points")                                  \
    X(SD_ENOTFOUND,-11, "not found")

enum {
#define SD_ENUM_(name, val, text) name = val,
    SD_ERRORS(SD_ENUM_)
#undef SD_ENUM_
};

typedef struct sd_err {
    int code;        /* last SD_E* code, 0 when none */
    char msg[512];   /* full sentence: what was wrong and where */
} sd_err;

/* sd_errf: fills e (if not NULL) with code and a printf-formatted message; returns code so that
 * callers can write `return sd_errf(e, SD_EFORMAT, "%s: ...", path);`. */
int sd_errf(sd_err *e, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* sd_strerror: the fixed text of an SD_E* code ("malformed input"); never NULL. */
const char *sd_strerror(int code);
