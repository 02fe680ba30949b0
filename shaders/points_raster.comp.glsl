#version 430
// points_raster.comp — the `points` pipeline as a compute rasteriser (the default form; Schütz
// et al. 2021, "Rendering Point Clouds with Compute Shaders"). llvmpipe has no 64-bit atomics,
// so the per-pixel key is 32 bits, in one of two ways:
//   packed (u_pass 2, one pass): key = quantised log depth << u_index_bits | point index, by
//             atomicMin into depth[pixel]. Used while at least 12 bits are left for the depth
//             (clouds up to 2^20 - 1 points): points closer than 1/4096 of log(far/near) to
//             each other may be ordered by index instead of depth. Ties go to the lower index.
//   exact (two passes): u_pass 0: atomicMin of the eye depth's float bits (positive floats
//             order like uints) into depth[pixel]; u_pass 1: points whose depth equals the
//             winner write atomicMin(index[pixel], point), so ties go to the lowest index, as
//             with GL_POINTS and GL_LESS (first drawn wins).
// points_resolve.frag.glsl then turns the key or index into colour and depth. Each point covers
// the pixels whose centres lie in the square of side u_point_size around its projection (the
// GL_POINTS rule), clipped to the frame but not dropped when its centre is outside it.
//
// Each invocation handles u_per points, u_threads apart (adjacent invocations read adjacent
// points): llvmpipe pays ~50 ns per invocation whatever it does, so on a CPU u_per is 32.

layout(local_size_x = 64) in;

#include "lib_bindings.glsl"

// Positions as a buffer texture: texelFetch gathers all SIMD lanes at once on llvmpipe, where
// storage-buffer reads at varying addresses run lane by lane.
layout(binding = T_POS) uniform samplerBuffer u_pos;     // R32F: x y z per point (lib_fetch.glsl)
// depth[] again as a buffer texture, for the test before the atomic (the same gather).
// Keys only ever decrease during the pass, so a stale read can cost a needless atomic but
// never skip a needed one.
layout(binding = T_POINTS_DEPTH) uniform usamplerBuffer u_depth;  // R32UI over Depth
layout(std430, binding = B_POINTS_DEPTH) restrict buffer Depth { uint depth[]; };
layout(std430, binding = B_POINTS_INDEX) restrict buffer Index { uint index[]; };
#include "lib_fetch.glsl"
// Visible ranges after culling: x = first point, y = position of that point in the sequence of
// visible points (an exclusive prefix sum of the counts), as an RG32UI buffer texture.
layout(binding = T_RANGES) uniform usamplerBuffer u_ranges;
#include "lib_ranges.glsl"

uniform mat4 u_viewproj;
uniform ivec2 u_size;
uniform float u_point_size;
uniform float u_znear, u_zfar;
uniform uint u_total;     // visible points
uniform uint u_nranges;
uniform uint u_first;     // the first point of range 0
uniform uint u_stride;    // invocations per row of work groups (2-D dispatch)
uniform uint u_threads;   // invocations in the dispatch
uniform uint u_per;       // points per invocation
uniform int u_pass;
uniform uint u_index_bits;  // packed: bits of the point index
uniform uint u_base;        // the cloud-wide index of this buffer set's first point
uniform float u_log_near;   // packed: log2(near)
uniform float u_log_scale;  // packed: (2^(32 - u_index_bits) - 1) / log2(far / near)

// The pass's operation on pixel pi for point i with key.
void touch(int pass, uint pi, uint key, uint i)
{
    if (pass != 1) {
        if (key < texelFetch(u_depth, int(pi)).x) atomicMin(depth[pi], key);
    } else if (depth[pi] == key) {
        atomicMin(index[pi], i);
    }
}

void main()
{
    // Every uniform the loop uses is read once, here: llvmpipe reloads a uniform at each use
    // inside a loop, which cost 6x the projection's arithmetic (splat_raster.comp measured it).
    mat4 viewproj = u_viewproj;
    ivec2 size = u_size;
    float point_size = u_point_size, znear = u_znear, zfar = u_zfar;
    uint total = u_total, nranges = u_nranges, first = u_first, threads = u_threads;
    uint per = u_per, index_bits = u_index_bits, base = u_base;
    int pass = u_pass;
    float log_near = u_log_near, log_scale = u_log_scale;
    // packed: the largest depth level (index_bits is 0 in the exact passes, which need none)
    float dmax = index_bits > 0u ? float((1u << (32u - index_bits)) - 1u) : 0.0;

    uint gid = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * u_stride;
    float h = 0.5 * point_size;
    for (uint j = 0u; j < per; j++) {
        uint k = gid + j * threads;
        if (k >= total) break;
        uint i = first + k; // one range (everything visible): no table look-up
        if (nranges > 1u) i = point_of(u_ranges, nranges, k);
        vec4 c = viewproj * vec4(fetch3(u_pos, i), 1.0);
        float d = c.w;
        if (!(d >= znear && d <= zfar)) continue;
        vec2 px = (c.xy / c.w * 0.5 + 0.5) * vec2(size);
        // Pixels x with x + 0.5 in [px - h, px + h).
        ivec2 p0 = max(ivec2(ceil(px - h - 0.5)), ivec2(0));
        ivec2 p1 = min(ivec2(ceil(px + h - 0.5)) - 1, size - 1);
        uint key;
        if (pass == 2) {
            uint dq = uint(clamp((log2(d) - log_near) * log_scale, 0.0, dmax));
            key = (dq << index_bits) | (base + i);
        } else {
            key = floatBitsToUint(d);
        }
        if (point_size == 1.0) {
            // One pixel, without the loops (5 % faster on llvmpipe, and the common case).
            if (p0.x <= p1.x && p0.y <= p1.y)
                touch(pass, uint(p0.y) * uint(size.x) + uint(p0.x), key, base + i);
            continue;
        }
        for (int y = p0.y; y <= p1.y; y++)
            for (int x = p0.x; x <= p1.x; x++) touch(pass, uint(y) * uint(size.x) + uint(x), key, base + i);
    }
}
