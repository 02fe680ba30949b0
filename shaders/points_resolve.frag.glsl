#version 430
// points_resolve.frag — after points_raster.comp.glsl: for every pixel a point won, writes its
// colour (alpha 1 = covered) and eye depth; other pixels are discarded and keep the background
// and +inf the renderer cleared them to. A full-frame fragment pass rather than a compute
// pass, because llvmpipe runs fragment shaders on whole pixel quads while its compute
// invocations and image stores go lane by lane. Colour rules as in points.vert.glsl.

layout(std430, binding = 0) readonly restrict buffer Pos { float pos[]; };
layout(std430, binding = 1) readonly restrict buffer Rgba { uint rgba[]; };
layout(std430, binding = 2) readonly restrict buffer Normal { float normal[]; };
layout(std430, binding = 3) readonly restrict buffer Field { float field[]; };
layout(std430, binding = 4) readonly restrict buffer Intensity { float intensity[]; };
layout(std430, binding = 5) readonly restrict buffer Depth { uint depth[]; };
layout(std430, binding = 6) readonly restrict buffer Index { uint index[]; };

uniform int u_width;
uniform uint u_index_bits;    // 0: exact mode (index[] holds the point); else packed keys
uniform mat4 u_viewproj;
uniform int u_color;          // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity (params.h)
uniform float u_znear, u_zfar;

layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_depth;

#include "lib_colormap.glsl"

void main()
{
    ivec2 q = ivec2(gl_FragCoord.xy);
    uint pi = uint(q.y) * uint(u_width) + uint(q.x);
    uint i;
    float d;
    if (u_index_bits == 0u) {
        i = index[pi];
        if (i == 0xFFFFFFFFu) discard;
        d = uintBitsToFloat(depth[pi]);
    } else {
        uint key = depth[pi];
        if (key == 0xFFFFFFFFu) discard;
        i = key & ((1u << u_index_bits) - 1u);
        // The exact depth of the winner (the key holds a quantised one), computed as the
        // raster pass did.
        d = (u_viewproj * vec4(pos[3u * i], pos[3u * i + 1u], pos[3u * i + 2u], 1.0)).w;
    }
    vec3 col;
    if (u_color == 1) col = colormap(field[i]);
    else if (u_color == 2)
        col = vec3(normal[3u * i], normal[3u * i + 1u], normal[3u * i + 2u]) * 0.5 + 0.5;
    else if (u_color == 3) col = vec3(1.0 - clamp((d - u_znear) / (u_zfar - u_znear), 0.0, 1.0));
    else if (u_color == 4) col = vec3(clamp(intensity[i], 0.0, 1.0));
    else col = unpackUnorm4x8(rgba[i]).rgb;
    o_color = vec4(col, 1.0);
    o_depth = d;
}
