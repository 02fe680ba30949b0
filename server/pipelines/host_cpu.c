/* host_cpu.c — the host paths' table for a software renderer (host.h). */
#include "host.h"

const rnd_host rnd_host_cpu = {
    .name = "cpu",
    .kawata_raster = kawata_cpu_raster,
    .kawata_resolve = kawata_cpu_resolve,
    .soft_composite = soft_cpu_composite,
    .soft_bin = soft_cpu_bin,
    .soft_blend = soft_cpu_blend,
    .soft_project = soft_proj_run,
};
