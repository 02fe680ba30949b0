/* e57_scan.h — what the E57 XML says about each scan: the /data3D children as the reader needs
 * them (pose, limits, where the points are and the prototype of their records).
 *
 * Each scan's `points` is a CompressedVector (fileOffset: the physical offset of its binary
 * section; recordCount) whose `prototype` lists the fields of a record. Every numeric leaf of
 * the prototype, depth first, is one bytestream of the bit-pack codec (e57_bitpack.h):
 *   Integer        minimum, maximum (default the int64 range): value - minimum in
 *                  ceil(log2(maximum - minimum + 1)) bits (0 bits: always minimum);
 *   ScaledInteger  the same raw integer, value = raw * scale + offset (defaults 1 and 0);
 *   Float          precision "single" (32-bit IEEE) or "double" (64-bit, the default).
 * A String leaf cannot be bit-packed: such a prototype is refused. Fields the reader does not
 * use (rowIndex, columnIndex, timeStamp, returnIndex, ...) keep their place and are never read.
 * Only the bit-pack codec exists in E2807; a `codecs` vector naming another is refused.
 *
 * The pose (rotation quaternion w, x, y, z and translation; identity when absent) is turned
 * into a rotation matrix (the quaternion normalised; a zero or non-finite one is refused).
 * intensityLimits and colorLimits give the range mapped to [0, 1] and [0, 255]; without them
 * the prototype's Integer/ScaledInteger bounds or finite Float bounds are used, and colours
 * with neither are taken as [0, 255] (intensities with neither are kept as they are). */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "e57_xml.h"
#include "sd_err.h"

/* The fields the reader uses (a prototype leaf's role), by their E57 element names. */
#define E57_ROLES(X)                                                               \
    X(CX, "cartesianX") X(CY, "cartesianY") X(CZ, "cartesianZ")                       \
    X(RANGE, "sphericalRange") X(AZIMUTH, "sphericalAzimuth")                      \
    X(ELEVATION, "sphericalElevation")                                             \
    X(CART_INVALID, "cartesianInvalidState") X(SPH_INVALID, "sphericalInvalidState") \
    X(INTENSITY, "intensity") X(INTENSITY_INVALID, "isIntensityInvalid")           \
    X(RED, "colorRed") X(GREEN, "colorGreen") X(BLUE, "colorBlue")                 \
    X(COLOR_INVALID, "isColorInvalid")                                             \
    X(NX, "normalX") X(NY, "normalY") X(NZ, "normalZ") /* E57_NS_NOR only */

enum {
#define E57_ROLE_ENUM_(id, name) E57_R_##id,
    E57_ROLES(E57_ROLE_ENUM_)
#undef E57_ROLE_ENUM_
    E57_R_COUNT,
    E57_R_NONE = -1
};

/* e57_role_name: the element name of role (E57_R_*). */
const char *e57_role_name(int role);

enum { E57_INTEGER, E57_SCALED, E57_FLOAT, E57_DOUBLE };

/* One bytestream of a record. */
typedef struct e57_field {
    int kind;               /* E57_INTEGER, E57_SCALED, E57_FLOAT (single), E57_DOUBLE */
    int role;               /* E57_R_*, or E57_R_NONE (read past, never decoded) */
    int bits;               /* bits per value in the bytestream (0-64) */
    int64_t min, max;       /* Integer, ScaledInteger: the raw bounds */
    double scale, offset;   /* ScaledInteger */
    double fmin, fmax;      /* Float: the prototype's bounds (±HUGE_VAL when absent) */
} e57_field;

enum { E57_CARTESIAN, E57_SPHERICAL };
enum { E57_MAX_FIELDS = 1024, E57_MAX_SCANS = 65535 };

typedef struct e57_scan {
    uint32_t index;               /* position in /data3D */
    unsigned long line;           /* of the scan's element in the XML */
    uint64_t cv_offset;           /* physical offset of the compressed vector section */
    uint64_t records;             /* recordCount */
    uint32_t nfields;
    uint32_t field0;              /* index of the first in e57_desc.fields */
    e57_field *fields;            /* nfields, in bytestream order */
    int role[E57_R_COUNT];        /* field index of each role, -1 when absent */
    int coords;                   /* E57_CARTESIAN (preferred when both) or E57_SPHERICAL */
    double rot[9], trans[3];      /* pose: world = rot * p + trans (rot row-major) */
    int has_intensity, has_color, has_normals;
    double ilo, ihi;              /* intensity range to [0, 1]; ihi <= ilo: keep as is */
    double clo[3], chi[3];        /* colour range to [0, 255], per channel */
} e57_scan;

typedef struct e57_desc {
    uint32_t nscans;
    e57_scan *scans;
    e57_field *fields;            /* every scan's fields (one allocation) */
    uint32_t nimages;             /* /images2D children (skipped) */
} e57_desc;

/* e57_desc_read: the scans of the XML tree root into d. what prefixes messages; each names the
 * XML line of the element at fault. Offsets are not checked here against the file (the
 * compressed vector reader does). Returns 0, or SD_EFORMAT, SD_EUNSUP (another codec, a String
 * field), SD_ELIMIT, SD_ENOMEM. */
int e57_desc_read(const e57_node *root, e57_desc *d, const char *what, sd_err *err);
void e57_desc_free(e57_desc *d);
