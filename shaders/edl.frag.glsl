#version 430
// edl.frag — Eye-Dome Lighting (Boucheny 2009; the form of Potree's edl.fs): the obscurance of
// a pixel is the mean over 8 neighbours at u_radius pixels (directions k * 45 degrees, rounded
// to the nearest pixel) of max(0, log2 z - log2 z_n), z the eye depth; the output is the shade
// exp(-u_k * sum), which edl.c multiplies into the colour by blending. Only neighbours nearer
// than the pixel darken it, so the far side of a depth step gets a dark rim and the near side
// keeps its colour; a plane facing the camera (one depth) is left as it is (shade exactly 1).
// Background pixels (depth +inf) are discarded, and background neighbours or ones outside the
// frame add nothing.

#include "lib_bindings.glsl"

layout(binding = T_EDL_DEPTH) uniform sampler2D u_depth; // R32F eye depth, +inf = background

uniform ivec2 u_size;
uniform float u_radius;  // pixels
uniform float u_k;       // RND_EDL_SCALE * edl_strength / 8

layout(location = 0) out vec4 o_shade;

// The obscurance term of the neighbour at offset o of pixel p with log depth lz.
float term(ivec2 p, vec2 o, float lz, ivec2 size)
{
    ivec2 q = p + ivec2(round(o));
    if (q.x < 0 || q.y < 0 || q.x >= size.x || q.y >= size.y) return 0.0;
    float zn = texelFetch(u_depth, q, 0).r;
    if (!(zn < 3.0e38)) return 0.0;
    return max(0.0, lz - log2(zn));
}

void main()
{
    ivec2 size = u_size;
    float r = u_radius, d = u_radius * 0.70710678;
    ivec2 p = ivec2(gl_FragCoord.xy);
    float z = texelFetch(u_depth, p, 0).r;
    if (!(z < 3.0e38)) discard;
    float lz = log2(z);
    float s = term(p, vec2(r, 0.0), lz, size) + term(p, vec2(d, d), lz, size) +
              term(p, vec2(0.0, r), lz, size) + term(p, vec2(-d, d), lz, size) +
              term(p, vec2(-r, 0.0), lz, size) + term(p, vec2(-d, -d), lz, size) +
              term(p, vec2(0.0, -r), lz, size) + term(p, vec2(d, -d), lz, size);
    float shade = exp(-u_k * s);
    o_shade = vec4(shade, shade, shade, 1.0);
}
