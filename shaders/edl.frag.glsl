#version 430
// edl.frag — Eye-Dome Lighting (Boucheny 2009; the form of Potree's edl.fs): the obscurance of
// a pixel is the mean over 4 neighbours at u_radius pixels (right, up, left, down, the radius
// rounded to whole pixels) of max(0, log2 z - log2 z_n), z the eye depth; the output is the shade
// exp(-u_k * sum), which edl.c multiplies into the colour by blending. Only neighbours nearer
// than the pixel darken it, so the far side of a depth step gets a dark rim and the near side
// keeps its colour; a plane facing the camera (one depth) is left as it is (shade exactly 1).
// Background pixels (depth +inf) get the shade 1, which leaves them as they are; background
// neighbours add nothing.
//
// The sum of logs is taken as the log of one product, sum log2(z / min(z, z_n)) =
// log2(prod z / min(z, z_n)), each ratio clamped to 2^15 so that the product stays finite: one
// log2 a pixel instead of 4. The depth is read from a buffer texture holding a copy of the
// frame's depth_eye over the rectangle edl.c shades, framed by u_r rows and columns of +inf
// (edl.c): every neighbour's texel exists and one outside the rectangle reads as background, so
// the pass has no bounds tests. On llvmpipe texelFetch from a buffer texture gathers all SIMD
// lanes at once, where each 2-D texture fetch cost ~3 ms of CPU a 1280x720 frame (measured: 9
// fetches a pixel through the 2-D texture ~14 ms). 4 neighbours rather than 8 (the issue allows
// either): with 8 the pass cost ~8 ms of CPU (4.5 ms wall) on the 1M scan's frame, over the
// 3 ms target. llvmpipe runs both sides of a branch and every lane of a discarded fragment
// (masked), so neither `discard` nor per-neighbour bounds tests saved work: on Guanyin.ply's
// rectangle (345k pixels) the pass with them cost 5.4 ms of CPU; without, see edl.c.

#include "lib_bindings.glsl"

layout(binding = T_EDL_DEPTH) uniform samplerBuffer u_depth; // R32F eye depth, +inf = background

uniform ivec2 u_org;       // the frame pixel of the copy's texel 0 (the rectangle's corner - u_r)
uniform int u_pw;          // texels a row of the copy: the rectangle's width + 2 u_r
uniform int u_r;           // the radius in whole pixels
uniform float u_k;         // RND_EDL_SCALE * edl_strength / 4

layout(location = 0) out vec4 o_shade;

void main()
{
    int r = u_r, pw = u_pw;
    ivec2 p = ivec2(gl_FragCoord.xy) - u_org;
    int c = p.y * pw + p.x;
    float z = texelFetch(u_depth, c).r;
    // z / min(z, z_n) per neighbour, clamped to [1, 2^15] (1 for a background neighbour)
    float lo = z * (1.0 / 32768.0);
    float prod = (z / clamp(texelFetch(u_depth, c + r).r, lo, z)) *
                 (z / clamp(texelFetch(u_depth, c + r * pw).r, lo, z)) *
                 (z / clamp(texelFetch(u_depth, c - r).r, lo, z)) *
                 (z / clamp(texelFetch(u_depth, c - r * pw).r, lo, z));
    float shade = z < 3.0e38 ? exp(-u_k * log2(prod)) : 1.0;
    o_shade = vec4(shade, shade, shade, 1.0);
}
