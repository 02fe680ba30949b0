/* host.h — the host paths (pipe.h, rnd_kit.host): the passes a software renderer runs as C
 * on the host over every core instead of through its GL, in one table. rnd_kit_init chooses
 * the table once from the back end's capability (rnd_host_cpu where the GL is the CPU, NULL on
 * a GPU; rnd_desc.host_paths forces either), so a pipeline holds one test, `k->host`, and calls
 * the pass through the table; none of them asks what the renderer is.
 *
 * What is here is what measured faster on real scans in the default settings
 * (docs/performance.md, "Host paths": kawata's passes 1-3 1.3-2.2x a frame, soft's compositor
 * 1.2-3.6x, soft's projection 1.2-1.4x); host copies of kawata's plane fit and of Eye-Dome
 * Lighting were measured too and removed (under 1.15x a frame, or only under a non-default
 * setting). Each host pass computes
 * what its shader computes; tests compare both within the precision the GLSL specification
 * allows the shader (test_render_kawata, test_render_soft, test_soft_proj), not bit for bit. */
#pragma once
#include <stdint.h>

#include "kawata_cpu.h"
#include "pipe.h"
#include "soft_cpu.h"
#include "soft_proj.h"

struct rnd_host {
    const char *name;
    /* kawata: passes 1 and 2 into the image buffer, and the list of covered buffer pixels with
     * pass 3's first half (kawata_cpu.h); the fit and the gather stay in the GL */
    int (*kawata_raster)(const kawata_cpu_job *job);
    uint32_t (*kawata_resolve)(const kawata_cpu_resolve_job *job);
    /* soft, model=express with order=auto: the compositor of the soft discs (soft_cpu.h) */
    int (*soft_composite)(soft_cpu_job *job);
    int (*soft_bin)(soft_cpu_job *job);
    int (*soft_blend)(soft_cpu_job *job);
    /* soft: the compositor's discs projected (soft_bin.comp PASS 0; soft_proj.h), but for
     * color=field */
    void (*soft_project)(const soft_proj_job *job);
};
