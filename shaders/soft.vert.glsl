#version 430
#include "lib_bindings.glsl"
// soft.vert — the soft discs of order=axis (pipe_soft.c) as GL_POINTS, one vertex each, drawn
// without vertex attributes: vertex k is the k-th disc back to front, projected by
// soft_bin.comp PASS 0 (in parallel, where llvmpipe runs vertex shaders on one thread) into two
// texels: (centre x, y in window pixels, radius in pixels, eye depth) and (colour, W of eq. 22).
// The sprite is the disc's bounding square plus a pixel; a disc behind the near plane has
// radius 0 and is moved outside the clip volume.

layout(binding = T_SOFT_PROJ) uniform samplerBuffer u_projt; // RGBA32F, 2 texels a disc
layout(binding = T_SOFT_IDX) uniform usamplerBuffer u_idx;    // the axis order (soft_bin.comp)
uniform uint u_base, u_n;
uniform int u_rev;

uniform ivec2 u_size;      // frame width, height
uniform float u_maxsize;   // the largest point size the GL allows

flat out vec3 v_color;
flat out vec3 v_disc;      // centre (window pixels) and radius (pixels)
flat out float v_depth;    // eye depth of the disc's centre
flat out float v_w;        // W(F) of eq. 22, 1 when the modulation is off

void main()
{
    uint kk = uint(gl_VertexID);
    int k = int(texelFetch(u_idx, int(u_base + (u_rev != 0 ? u_n - 1u - kk : kk))).x);
    vec4 g = texelFetch(u_projt, 2 * k), cw = texelFetch(u_projt, 2 * k + 1);
    v_disc = g.xyz;
    v_depth = g.w;
    v_color = cw.rgb;
    v_w = cw.w;
    gl_Position = g.z > 0.0 ? vec4(g.xy / vec2(u_size) * 2.0 - 1.0, 0.0, 1.0) : vec4(2.0, 2.0, 2.0, 1.0);
    gl_PointSize = clamp(2.0 * g.z + 2.0, 1.0, u_maxsize);
}
