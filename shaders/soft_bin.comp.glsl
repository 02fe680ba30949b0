#version 430
#include "lib_bindings.glsl"
// soft_bin.comp — the soft compositor's binning (pipe_soft.c), order-preserving without a sort.
//   PASS 0  one invocation per soft point j, in point order: projects it (centre and radius in
//           pixels, eye depth, colour, W of eq. 22) into proj[2 j], proj[2 j + 1]. The
//           back-to-front order is the index array of the axis nearest the view direction
//           (u_base), read forwards or backwards: the k-th disc is proj of j = idx[u_base + k]
//           (order=axis's sprites, soft.vert, and the passes below read them so).
// The ordered points are cut into u_nblocks consecutive blocks, one invocation each, which walks
// its block serially, so within a block the order is kept.
//   PASS 1  counts per (tile, block) cell the points whose disc touches the tile's pixel
//           centres; each cell belongs to one invocation (no atomics).
//   PASS 3  (after soft_scan.comp turned the counts into tile-major offsets) writes each
//           point's number j into the tile lists at its cell's offset, incrementing it.
// A tile's list is then its cells' ranges in block order, each in point order: back to front.
layout(local_size_x = 32) in;

layout(binding = T_POS) uniform samplerBuffer u_pos;
layout(binding = T_NRM) uniform samplerBuffer u_nrm;
layout(binding = T_RAD) uniform samplerBuffer u_rad;
layout(binding = T_SRC) uniform usamplerBuffer u_src;
layout(binding = T_SOFT_F) uniform usamplerBuffer u_f;
layout(binding = T_SOFT_IDX) uniform usamplerBuffer u_idx;

layout(std430, binding = B_SOFT_PROJ) buffer Proj { vec4 proj[]; };   // 2 per point, draw order
layout(std430, binding = B_SOFT_CELLS) buffer Cells { uint cells[]; }; // (tile, block), tile-major
layout(std430, binding = B_SOFT_LIST) buffer List { uint list[]; };

#include "lib_fetch.glsl"
#include "lib_colormap.glsl"
#include "lib_shade.glsl"

uniform mat4 u_view, u_proj;
uniform ivec2 u_size;
uniform float u_scale;
uniform int u_color;
uniform float u_znear, u_zfar;
uniform float u_t, u_lm;
uniform vec3 u_light;      // unit, eye space (splat's)
uniform uint u_base, u_n;
uniform int u_rev;
uniform uint u_nblocks;
uniform int u_tile, u_ntx, u_nty;

void main()
{
#if PASS == 0
    // a grid of at most 4096 groups (pipe_soft.c): each invocation takes every stride-th disc
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    // soft point j in point order: sequential reads and writes (proj[2 j], proj[2 j + 1]).
    // The uniforms are read once into locals: llvmpipe reloads a uniform at every use inside a
    // loop (see splat_raster.comp).
    mat4 view = u_view, projm = u_proj;
    vec2 size = vec2(u_size);
    float scale = u_scale, znear = u_znear, zfar = u_zfar, t = u_t, lm = u_lm;
    int color = u_color;
    uint n = u_n;
    vec3 light = u_light;
    bool persp = projm[3][3] == 0.0;
    float rscale = projm[1][1] * 0.5 * size.y;
    for (uint j = gl_GlobalInvocationID.x; j < n; j += stride) {
        uint i = texelFetch(u_idx, int(j)).x;
        vec3 p = fetch3(u_pos, i);
        vec4 e = view * vec4(p, 1.0);
        float depth = -e.z;
        float r = texelFetch(u_rad, int(i)).x * scale;
        vec4 c = projm * e;
        float rpx = depth > znear ? r * rscale / depth : 0.0;
        vec2 px = depth > znear ? (c.xy / c.w * 0.5 + 0.5) * size : vec2(-1e9);
        float f = uintBitsToFloat(texelFetch(u_f, int(i)).x);
        float w = lm > t ? clamp((f - t) / (lm - t), 0.0, 1.0) : 1.0;
        vec3 col;
        uint src = texelFetch(u_src, int(i)).x;
        if (color == 0) col = unpackUnorm4x8(src).rgb;
        else if (color == 1 || color == 5) col = colormap(uintBitsToFloat(src));
        else if (color == 4) col = vec3(clamp(uintBitsToFloat(src), 0.0, 1.0));
        else if (color == 3) col = vec3(1.0 - clamp((depth - znear) / (zfar - znear), 0.0, 1.0));
        else col = vec3(0.5, 0.5, 1.0);
        if (color == 0 || color == 1 || color == 4 || color == 5) {
            // Lambert shading as splat's resolve (the paper shades all points), from the
            // point's normal turned towards the viewer
            vec3 nn = mat3(view) * fetch3(u_nrm, i);
            float nl2 = dot(nn, nn);
            nn = nl2 > 0.0 ? nn * inversesqrt(nl2) : vec3(0.0, 0.0, 1.0);
            if (dot(nn, persp ? e.xyz : vec3(0.0, 0.0, -1.0)) > 0.0) nn = -nn;
            col *= shade(nn, light);
        }
        proj[2u * j] = vec4(px, rpx, depth);
        proj[2u * j + 1u] = vec4(col, w);
    }
#else
    uint b = gl_GlobalInvocationID.x;
    if (b >= u_nblocks) return;
    uint per = (u_n + u_nblocks - 1u) / u_nblocks;
    uint k0 = min(u_n, b * per), k1 = min(u_n, k0 + per);
    for (uint k = k0; k < k1; k++) {
        uint j = texelFetch(u_idx, int(u_base + (u_rev != 0 ? u_n - 1u - k : k))).x;
        vec4 q = proj[2u * j];
        vec2 px = q.xy;
        float rpx = q.z;
        if (!(rpx > 0.0)) continue;
        // Pixels whose centre x + 0.5 lies within rpx of the centre.
        int x0 = max(0, int(ceil(px.x - rpx - 0.5))), x1 = min(u_size.x - 1, int(floor(px.x + rpx - 0.5)));
        int y0 = max(0, int(ceil(px.y - rpx - 0.5))), y1 = min(u_size.y - 1, int(floor(px.y + rpx - 0.5)));
        if (x1 < x0 || y1 < y0) continue;
        for (int ty = y0 / u_tile; ty <= y1 / u_tile; ty++)
            for (int tx = x0 / u_tile; tx <= x1 / u_tile; tx++) {
                uint cell = uint(ty * u_ntx + tx) * u_nblocks + b;
#if PASS == 1
                cells[cell] += 1u;
#else
                list[cells[cell]] = j;
                cells[cell] += 1u;
#endif
            }
    }
#endif
}
