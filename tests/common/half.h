/* half.h — IEEE 754 binary16 ("half") <-> binary32 conversion, own code, no libraries.
 *
 * half_from_float rounds to nearest, ties to even (the rounding GL and Imath use), so values
 * above the largest half (65504) that round up become +-inf, and tiny values become signed
 * zero or subnormals. NaN stays NaN (quiet, sign kept). half_to_float is exact. */
#pragma once
#include <stdint.h>

/* half_from_float: the half nearest to f (ties to even). */
uint16_t half_from_float(float f);

/* half_to_float: the float equal to half h (every half is exactly representable). */
float half_to_float(uint16_t h);
