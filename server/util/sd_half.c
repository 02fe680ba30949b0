/* sd_half.c — IEEE binary16 conversions (sd_half.h). */
#include "sd_half.h"

#include <math.h>
#include <string.h>

float sd_half_to_float(uint16_t h)
{
    uint32_t sign = (uint32_t)(h >> 15) << 31, e = (h >> 10) & 31u, m = h & 1023u;
    float f;
    if (e == 0) {
        f = ldexpf((float)m, -24); /* zero and subnormals */
        return sign ? -f : f;
    }
    uint32_t u = e == 31 ? sign | 0x7f800000u | m << 13 : sign | (e + 112u) << 23 | m << 13;
    memcpy(&f, &u, 4);
    return f;
}

uint16_t sd_float_to_half(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    uint16_t sign = (uint16_t)((u >> 16) & 0x8000u);
    uint32_t a = u & 0x7fffffffu;
    if (a >= 0x7f800000u) return sign | (a > 0x7f800000u ? 0x7e00u : 0x7c00u); /* NaN, inf */
    if (a >= 0x477ff000u) return sign | 0x7c00u; /* rounds past 65504: inf */
    if (a < 0x38800000u) { /* below the smallest normal half: a subnormal, rounded */
        float v;
        memcpy(&v, &a, 4);
        return sign | (uint16_t)lrintf(v * 16777216.0f); /* units of 2^-24, nearest even */
    }
    /* normal: drop 13 mantissa bits, round to nearest even */
    uint32_t r = a + 0xfffu + ((a >> 13) & 1u);
    return sign | (uint16_t)((r - 0x38000000u) >> 13);
}
