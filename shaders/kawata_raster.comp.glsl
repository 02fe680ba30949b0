#version 430
// kawata_raster.comp — passes 1 and 2 of the `kawata` pipeline (pipe_kawata.c): points into the
// low-resolution image buffer (u_bsize). pipe_kawata.c builds it twice, with "#define PASS 1"
// and "#define PASS 2": llvmpipe runs both sides of a branch (masked), so one program with a
// uniform pass number paid for the other pass's instructions too (pass 1: 28 -> 24 ms of CPU
// on the 1M scan). Both compute every point's depth and pixel with the same `precise`
// instructions, as pass 2 compares the depth with pass 1's for equality: two compilations must
// give the same bits, which `precise` guarantees (GLSL 4.50, 4.7.1: the stated order, no fused
// operations) and nothing else does.
//   PASS 1:   depth[b] = min over the points of buffer pixel b of their eye depth (float bits:
//             positive floats order like uints).
//   PASS 2:   the point whose depth equals depth[b] stores its cloud-wide index in near[b]
//             (atomicMin: ties go to the lowest index); a point behind it by at most u_gamma
//             stores atomicMax((1 + quantised step) << u_index_bits | index) in far[b]: the
//             farthest point within gamma (the paper's "write if the depth is larger" test).
// Each invocation handles u_per points, u_threads apart, as points_raster.comp (llvmpipe's
// per-invocation cost); every uniform the loop uses is read once into a local (llvmpipe
// reloads uniforms at each use inside loops).

layout(local_size_x = 64) in;

#include "lib_bindings.glsl"

layout(binding = T_POS) uniform samplerBuffer u_pos;
// The same buffers as textures, for the tests before the atomics (gathers on llvmpipe). depth
// only decreases in pass 1 and far only increases in pass 2, so a stale read costs a needless
// atomic, never a missed one.
layout(binding = T_KAWATA_DEPTH) uniform usamplerBuffer u_depth;
layout(binding = T_KAWATA_FAR) uniform usamplerBuffer u_far;
layout(std430, binding = B_KAWATA_DEPTH) restrict buffer Depth { uint depth[]; };
layout(std430, binding = B_KAWATA_NEAR) restrict buffer Near { uint near[]; };
layout(std430, binding = B_KAWATA_FAR) restrict buffer Far { uint far[]; };
#include "lib_fetch.glsl"
layout(binding = T_RANGES) uniform usamplerBuffer u_ranges;
#include "lib_ranges.glsl"

uniform mat4 u_viewproj;
uniform ivec2 u_bsize;      // image buffer size
uniform float u_znear, u_zfar;
uniform uint u_total, u_nranges, u_first, u_stride, u_threads, u_per, u_base;
uniform uint u_index_bits;
uniform float u_gamma;      // local units
uniform float u_qscale;     // (u_qmax - 1) / u_gamma
uniform uint u_qmax;        // 2^(32 - u_index_bits) - 1

void main()
{
    mat4 viewproj = u_viewproj;
    ivec2 bsize = u_bsize;
    vec2 fb = vec2(bsize);
    float znear = u_znear, zfar = u_zfar, gamma = u_gamma, qscale = u_qscale;
    uint total = u_total, nranges = u_nranges, first = u_first, threads = u_threads;
    uint per = u_per, base = u_base, ibits = u_index_bits, qtop = u_qmax - 1u;
#if PASS == 2
    const int pass = 2;
#else
    const int pass = 1; // also where no PASS is defined (test_gl compiles every shader bare)
#endif
    uint gid = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * u_stride;
    for (uint j = 0u; j < per; j++) {
        uint k = gid + j * threads;
        if (k >= total) break;
        uint i = first + k;
        if (nranges > 1u) i = point_of(u_ranges, nranges, k);
        // c = u_viewproj (p, 1), written out: under `precise` the stated order holds and no
        // product is fused into a sum (GLSL 4.50, 4.7.1), and + and * are correctly rounded
        // (4.7.1's table), so c is the same on every conforming implementation (and the host
        // path's, kawata_cpu.c); only the division may differ there (2.5 ulp).
        vec3 p = fetch3(u_pos, i);
        precise float cx = ((viewproj[0].x * p.x + viewproj[1].x * p.y) + viewproj[2].x * p.z) +
                           viewproj[3].x;
        precise float cy = ((viewproj[0].y * p.x + viewproj[1].y * p.y) + viewproj[2].y * p.z) +
                           viewproj[3].y;
        precise float d = ((viewproj[0].w * p.x + viewproj[1].w * p.y) + viewproj[2].w * p.z) +
                          viewproj[3].w;
        if (!(d >= znear && d <= zfar)) continue;
        precise vec2 b = (vec2(cx, cy) / d * 0.5 + 0.5) * fb;
        if (!(b.x >= 0.0 && b.y >= 0.0 && b.x < fb.x && b.y < fb.y)) continue;
        ivec2 q = min(ivec2(b), bsize - 1);
        int pi = q.y * bsize.x + q.x;
        uint key = floatBitsToUint(d);
        uint d1 = texelFetch(u_depth, pi).x;
        if (pass == 1) {
            if (key < d1) atomicMin(depth[pi], key);
        } else if (key == d1) {
            atomicMin(near[pi], base + i);
        } else {
            float step = d - uintBitsToFloat(d1);
            if (step > gamma) continue;
            uint fk = ((1u + min(uint(step * qscale), qtop - 1u)) << ibits) | (base + i);
            if (fk > texelFetch(u_far, pi).x) atomicMax(far[pi], fk);
        }
    }
}
