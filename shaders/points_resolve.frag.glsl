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

vec3 colormap(float t)
{
    t = clamp(t, 0.0, 1.0);
    const vec3 c0 = vec3(0.2777273272, 0.0054073445, 0.3340998053);
    const vec3 c1 = vec3(0.1050930431, 1.4046135299, 1.3845901626);
    const vec3 c2 = vec3(-0.3308618287, 0.2148475595, 0.0950951630);
    const vec3 c3 = vec3(-4.6342304990, -5.7991009734, -19.3324409563);
    const vec3 c4 = vec3(6.2282699363, 14.1799333668, 56.6905526007);
    const vec3 c5 = vec3(4.7763849977, -13.7451453777, -65.3530326334);
    const vec3 c6 = vec3(-5.4354558559, 4.6458526122, 26.3124352496);
    return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
}

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
