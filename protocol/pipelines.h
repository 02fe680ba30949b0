/* pipelines.h — the one list of rendering pipelines.
 *
 * Each row is X(ID, name): ID gives the C enum value SP_PIPE_<ID> (the value of the parameter
 * `pipeline`, and the pipeline byte of a FRAME), name its text form, and, in the daemon, the
 * implementation `pipe_<name>` (server/pipe_<name>.c) that render.c's table takes from this
 * same list. Adding a pipeline is one file plus one row here; test_params checks that the
 * renderer's table and the parameter agree. The order is the wire order: append only. */
#pragma once

#define SP_PIPELINE_LIST(X) \
    X(POINTS, points)       \
    X(SPLAT, splat)         \
    X(KAWATA, kawata)       \
    X(SOFT, soft)           \
    X(OLT, olt)

enum {
#define SP_PIPE_ID_(id, name) SP_PIPE_##id,
    SP_PIPELINE_LIST(SP_PIPE_ID_)
#undef SP_PIPE_ID_
    SP_PIPE_COUNT
};

/* SP_PIPELINE_VALUES: "points|splat|...", the enum values of the `pipeline` parameter. */
#define SP_PIPE_NAME_(id, name) "|" #name
#define SP_PIPELINE_VALUES ("" SP_PIPELINE_LIST(SP_PIPE_NAME_) + 1)
