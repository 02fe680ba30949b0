#version 430
// points_resolve.frag — after points_raster.comp.glsl: for every pixel a point won, writes its
// colour (alpha 1 = covered) and eye depth; other pixels are discarded and keep the background
// and +inf the renderer cleared them to. A full-frame fragment pass rather than a compute
// pass, because llvmpipe runs fragment shaders on whole pixel quads while its compute
// invocations and image stores go lane by lane. Colour rules as in points.vert.glsl.
// Everything is read through buffer textures, as in the raster pass (texelFetch gathers all
// SIMD lanes at once on llvmpipe; storage-buffer reads at varying addresses go lane by lane;
// the measured difference here is within noise), so the cloud is limited by
// GL_MAX_TEXTURE_BUFFER_SIZE (3 texels a point) rather than by the storage-block size (12 bytes
// a point: 11M points on llvmpipe).

#include "lib_bindings.glsl"

layout(binding = T_POS) uniform samplerBuffer u_pos;     // R32F: x y z per point (lib_fetch.glsl)
layout(binding = T_NRM) uniform samplerBuffer u_nrm;     // R32F: nx ny nz per point (u_color 2)
layout(binding = T_SRC) uniform usamplerBuffer u_src;    // R32UI: rgba8 (u_color 0) or the float bits of the field
                                 // (1) or the intensity (4)
layout(binding = T_POINTS_DEPTH) uniform usamplerBuffer u_depth;  // R32UI: the raster pass's per-pixel key or depth bits
layout(binding = T_POINTS_INDEX) uniform usamplerBuffer u_index;  // R32UI: exact mode's per-pixel winning point

uniform int u_width;
uniform uint u_index_bits;    // 0: exact mode (u_index holds the point); else packed keys
uniform uint u_base, u_count; // this pass resolves the winners of points [u_base, +u_count):
                              // one buffer set (a cloud may have several, resolved in turn)
uniform mat4 u_viewproj;
uniform int u_color;          // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity, 5 scan (params.h)
uniform float u_znear, u_zfar;

layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_depth;

#include "lib_fetch.glsl"
#include "lib_colormap.glsl"

void main()
{
    uint index_bits = u_index_bits;
    int color = u_color;
    ivec2 q = ivec2(gl_FragCoord.xy);
    int pi = q.y * u_width + q.x;
    uint i;
    float d;
    if (index_bits == 0u) {
        i = texelFetch(u_index, pi).x;
        if (i == 0xFFFFFFFFu) discard;
        i -= u_base; // wraps for winners of an earlier set: discarded below
        if (i >= u_count) discard;
        d = uintBitsToFloat(texelFetch(u_depth, pi).x);
    } else {
        uint key = texelFetch(u_depth, pi).x;
        if (key == 0xFFFFFFFFu) discard;
        i = (key & ((1u << index_bits) - 1u)) - u_base;
        if (i >= u_count) discard;
        // The exact depth of the winner (the key holds a quantised one), computed as the
        // raster pass did.
        d = (u_viewproj * vec4(fetch3(u_pos, i), 1.0)).w;
    }
    vec3 col;
    if (color == 1 || color == 5) col = colormap(uintBitsToFloat(texelFetch(u_src, int(i)).x));
    else if (color == 2) col = fetch3(u_nrm, i) * 0.5 + 0.5;
    else if (color == 3) col = vec3(1.0 - clamp((d - u_znear) / (u_zfar - u_znear), 0.0, 1.0));
    else if (color == 4) col = vec3(clamp(uintBitsToFloat(texelFetch(u_src, int(i)).x), 0.0, 1.0));
    else col = unpackUnorm4x8(texelFetch(u_src, int(i)).x).rgb;
    o_color = vec4(col, 1.0);
    o_depth = d;
}
