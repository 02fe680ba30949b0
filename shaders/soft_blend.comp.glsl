#version 430
#include "lib_bindings.glsl"
// soft_blend.comp — the soft compositor's per-pixel blend (pipe_soft.c): one work group per
// tile of the stripe, one invocation per pixel, walking the tile's list (back to front, see
// soft_bin.comp) and applying the premultiplied "over" in registers to the soft layer L
// (premultiplied colour, alpha), starting from nothing: L = Phi c + (1 - Phi) L. Eq. 19 and 22
// as in soft.frag.glsl; discs at or behind the solid surface (the splat keys) are skipped. L is
// stored per pixel of the stripe; soft_resolve.frag puts it over the target in one blend.
layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = T_SOFT_PROJ) uniform samplerBuffer u_projt;   // RGBA32F, 2 texels a point
layout(binding = T_SOFT_LIST) uniform usamplerBuffer u_list;   // R32UI
layout(binding = T_SOFT_CELLS) uniform usamplerBuffer u_cells; // R32UI, after the scatter
layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys;
layout(std430, binding = B_SOFT_LAYER) buffer Layer { vec4 layer[]; };

uniform ivec2 u_size;
uniform ivec2 u_stripe;    // the keys' first row and rows
uniform ivec2 u_rows;      // the stripe's first row and rows (the layer's rows)
uniform int u_keys_on;
uniform float u_lambda;
uniform uint u_nblocks;
uniform int u_ntx, u_ty0;

void main()
{
    ivec2 q = ivec2(gl_WorkGroupID.x * 8u + gl_LocalInvocationID.x,
                    (uint(u_ty0) + gl_WorkGroupID.y) * 8u + gl_LocalInvocationID.y);
    bool inside = q.x < u_size.x && q.y >= u_rows.x && q.y < u_rows.x + u_rows.y;
    int tile = (u_ty0 + int(gl_WorkGroupID.y)) * u_ntx + int(gl_WorkGroupID.x);
    uint last = uint(tile + 1) * u_nblocks - 1u;
    uint end = texelFetch(u_cells, int(last)).x;
    uint start = tile > 0 ? texelFetch(u_cells, int(last - u_nblocks)).x : 0u;
    if (!inside) return;
    float zsolid = 3.4e38;
    if (u_keys_on != 0) {
        uint key = texelFetch(u_keys, (q.y - u_stripe.x) * u_size.x + q.x).x;
        if (key != 0u) zsolid = uintBitsToFloat(~key);
    }
    vec2 pc = vec2(q) + 0.5;
    vec4 L = vec4(0.0);
    for (uint j = start; j < end; j++) {
        int k = int(texelFetch(u_list, int(j)).x);
        vec4 g = texelFetch(u_projt, 2 * k);
        float d = length(pc - g.xy) / g.z;
        if (!(d < 1.0) || g.w >= zsolid) continue;
        vec4 cw = texelFetch(u_projt, 2 * k + 1);
        float phi = u_lambda * (cos(3.14159265358979 * d) + 1.0) * 0.5;
        phi = mix(1.0 - d, phi, cw.w);
        L = vec4(cw.rgb * phi, phi) + (1.0 - phi) * L;
    }
    layer[(q.y - u_rows.x) * u_size.x + q.x] = L;
}
