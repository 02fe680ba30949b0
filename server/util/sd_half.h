/* sd_half.h — IEEE binary16 ("half float", the RGBA16F frames' channels) to and from float, in
 * portable C: the MPI compositor's "over" and the host Eye-Dome Lighting pass. */
#pragma once
#include <stdint.h>

/* sd_half_to_float: exact (zero, subnormals, infinities and NaN kept). sd_float_to_half: round
 * to nearest even; past 65504 rounds to infinity. */
float sd_half_to_float(uint16_t h);
uint16_t sd_float_to_half(float f);
