/* sd_err.c — error buffer helpers (see sd_err.h). */
#include "sd_err.h"

#include <stdarg.h>
#include <stdio.h>

int sd_errf(sd_err *e, int code, const char *fmt, ...)
{
    if (e) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(e->msg, sizeof e->msg, fmt, ap);
        va_end(ap);
        e->code = code;
    }
    return code;
}

const char *sd_strerror(int code)
{
    switch (code) {
#define SD_CASE_(name, val, text) case name: return text;
        SD_ERRORS(SD_CASE_)
#undef SD_CASE_
    case 0: return "success";
    default: return "unknown error";
    }
}
