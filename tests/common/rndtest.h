/* rndtest.h — renderer calls for the rendering tests that fail the running cmocka test with the
 * renderer's message instead of returning a code. */
#pragma once
#include <stdint.h>

#include "render.h"

/* tu_upload: rnd_upload of pc; fails the test when it returns no id. */
uint32_t tu_upload(rnd_ctx *r, const pc_prepared *pc);

/* tu_render: rnd_render of cloud id; fails the test on an error. */
void tu_render(rnd_ctx *r, uint32_t id, const rnd_camera *cam, const sp_params *p,
               int want_float, rnd_frame *f);
