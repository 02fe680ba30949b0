#version 430
// edl.frag — Eye-Dome Lighting (Boucheny 2009; the form of Potree's edl.fs): the obscurance of
// a pixel is the mean over 4 neighbours at u_radius pixels (right, up, left, down, the radius
// rounded to whole pixels) of max(0, log2 z - log2 z_n), z the eye depth; the output is the shade
// exp(-u_k * sum), which edl.c multiplies into the colour by blending. Only neighbours nearer
// than the pixel darken it, so the far side of a depth step gets a dark rim and the near side
// keeps its colour; a plane facing the camera (one depth) is left as it is (shade exactly 1).
// Background pixels (depth +inf) are discarded, and background neighbours or ones outside the
// rectangle edl.c copied (u_lo, u_hi: the cloud's screen rectangle with a margin, inside the
// frame) add nothing.
//
// The sum of logs is taken as the log of one product, sum log2(z / min(z, z_n)) =
// log2(prod z / min(z, z_n)), each ratio clamped to 2^15 so that the product stays finite: one
// log2 a pixel instead of 4. The depth is read from a buffer texture holding a copy of the
// frame's depth_eye (edl.c): on llvmpipe texelFetch from a buffer texture gathers all SIMD lanes
// at once, where each 2-D texture fetch cost ~3 ms of CPU a 1280x720 frame (measured: 9 fetches
// a pixel through the 2-D texture ~14 ms). 4 neighbours rather than 8 (the issue allows
// either): with 8 the pass cost ~8 ms of CPU (4.5 ms wall) on the 1M scan's frame, over the
// 3 ms target.

#include "lib_bindings.glsl"

layout(binding = T_EDL_DEPTH) uniform samplerBuffer u_depth; // R32F eye depth, +inf = background

uniform ivec2 u_size;
uniform ivec2 u_lo, u_hi;  // the copied rectangle [u_lo, u_hi); the copy holds stale data outside
uniform int u_r;           // the radius in whole pixels
uniform float u_k;         // RND_EDL_SCALE * edl_strength / 4

layout(location = 0) out vec4 o_shade;

// z / min(z, z_n) for the neighbour at p + o, clamped to [1, 2^15]; 1 outside the rectangle.
float ratio(ivec2 p, ivec2 o, float z, ivec2 size)
{
    ivec2 q = p + o;
    if (q.x < u_lo.x || q.y < u_lo.y || q.x >= u_hi.x || q.y >= u_hi.y) return 1.0;
    float zn = texelFetch(u_depth, q.y * size.x + q.x).r;
    return z / clamp(zn, z * (1.0 / 32768.0), z);
}

void main()
{
    ivec2 size = u_size;
    int r = u_r;
    ivec2 p = ivec2(gl_FragCoord.xy);
    float z = texelFetch(u_depth, p.y * size.x + p.x).r;
    if (!(z < 3.0e38)) discard;
    float prod = ratio(p, ivec2(r, 0), z, size) * ratio(p, ivec2(0, r), z, size) *
                 ratio(p, ivec2(-r, 0), z, size) * ratio(p, ivec2(0, -r), z, size);
    float shade = exp(-u_k * log2(prod));
    o_shade = vec4(shade, shade, shade, 1.0);
}
