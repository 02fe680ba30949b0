/* attrs.h — the per-point attributes a cloud may carry, as bits of INFO's `attrs` field (and of
 * the daemon's clouds, server/cloud.h). One list: bit, name. The public header
 * client/splat_client.h repeats the bits as SPC_ATTR_* (it is installed alone); splat_client.c
 * checks at compile time that they agree. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#define SP_ATTR_LIST(X)                                                                       \
    X(RGB, 0, "rgb")                 /* rgba: 4 x uint8 per point (alpha 255) */             \
    X(NORMAL, 1, "normal")           /* 3 x float per point, unit length */                  \
    X(INTENSITY, 2, "intensity")     /* float per point, the file's units */                 \
    X(CLASS, 3, "classification")    /* uint8 per point (LAS classes) */                     \
    X(RADIUS, 4, "radius")           /* float per point (the file's, or prep eq. 20) */      \
    X(SCALAR, 5, "scalar")           /* float per point (quality, confidence, scalar_*) */   \
    X(F, 6, "F")                     /* uncertainty in [0,1] (prep eq. 21) */                \
    X(SCAN, 7, "scan")               /* uint16 per point: the scan it came from (E57) */

enum {
#define SP_ATTR_ENUM_(id, bit, name) SP_ATTR_##id = 1u << (bit),
    SP_ATTR_LIST(SP_ATTR_ENUM_)
#undef SP_ATTR_ENUM_
};

/* sp_attr_names: writes the names of the set bits of attrs, space-separated ("rgb normal F"),
 * to buf (truncated to len). */
void sp_attr_names(uint32_t attrs, char *buf, size_t len);
