/* datadir.h — the daemon's data directory: listing the clouds in it and resolving a client's
 * cloud name to a file inside it, safely.
 *
 * A name is a plain file name: no '/', not "." or "..", no control characters, at most 255
 * bytes. The resolved file's realpath must lie inside the realpath of the data directory, so a
 * symlink pointing outside is refused. A name without a supported extension (pc_supported_ext)
 * resolves to the unique file "NAME.ext" with one. Low-level: returns codes, never logs. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

/* Why a name was refused, for the protocol's error codes. */
typedef enum {
    DD_OK = 0,
    DD_BAD_NAME,     /* not a plain file name (slash, "..", absolute, control characters, empty) */
    DD_OUTSIDE,      /* resolves (through a symlink) outside the data directory */
    DD_NOT_FOUND,    /* no such cloud */
    DD_AMBIGUOUS,    /* a name without extension matches several files */
    DD_NOT_CLOUD,    /* not a regular file, or an unsupported extension */
} dd_why;

typedef struct dd_entry {
    char name[256];  /* file name in the data directory, with extension */
    uint64_t size;   /* bytes */
} dd_entry;

/* dd_check_dir: 0 when dir is an existing, readable directory; SD_EIO/SD_EINVAL with err. */
int dd_check_dir(const char *dir, sd_err *err);

/* dd_list: the clouds in dir (regular files with a supported extension that resolve inside dir),
 * sorted by name, in a malloc'd array (*out, *n; free with free()). Returns 0 or SD_EIO/SD_ENOMEM. */
int dd_list(const char *dir, dd_entry **out, size_t *n, sd_err *err);

/* dd_resolve: the real path of cloud name in dir, written to path (pathlen bytes). Returns 0,
 * or a negative SD_E* code with *why (when not NULL) saying which rule failed and err naming
 * the name: SD_EINVAL (DD_BAD_NAME, DD_OUTSIDE, DD_AMBIGUOUS, DD_NOT_CLOUD), SD_ENOTFOUND. */
int dd_resolve(const char *dir, const char *name, char *path, size_t pathlen, dd_why *why,
               sd_err *err);
