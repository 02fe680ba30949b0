/* rndtest.c — see rndtest.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "rndtest.h"

uint32_t tu_upload(rnd_ctx *r, const pc_prepared *pc)
{
    sd_err err = {0};
    int64_t id = rnd_upload(r, pc, &err);
    if (id <= 0) fail_msg("upload: %s", err.msg);
    return (uint32_t)id;
}

void tu_render(rnd_ctx *r, uint32_t id, const rnd_camera *cam, const sp_params *p,
               int want_float, rnd_frame *f)
{
    sd_err err = {0};
    int rc = rnd_render(r, id, cam, p, want_float, f, &err);
    if (rc < 0) fail_msg("render: %s", err.msg);
}
