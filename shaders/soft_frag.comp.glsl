#version 430
#include "lib_bindings.glsl"
// soft_frag.comp — the per-pixel fragment lists of model=base and model=concentric
// (soft_lists.c), after the Soft Transparency paper's sec. 4 and [MCTB12]. One invocation per
// soft point (any order: the lists are sorted per pixel later). Each soft point is a sphere of
// radius R = radius * splat_scale around its position; for every pixel of its conservative
// screen box within rows [u_rows.x, u_rows.x + u_rows.y), the pixel centre's eye ray is
// intersected with it exactly (ray distance s along the unnormalised ray direction's unit
// vector; eye depth = s / |d|). The part of the chord in front of the near plane and in front of
// the solid surface (the splat keys, T_SPLAT_KEYS) is kept: the exit is clipped there, so the
// density integral stops at the solid surface.
//   PASS 1  adds the pixel's sample count to counts[pixel]: Base 2 (enter, exit); Concentric 2
//           per concentric sphere the ray meets, N = 1 + floor(R_px / 4) spheres of radii
//           R (1 - i / N), i.e. one more every 4 pixels of screen radius.
//   PASS 2  (counts scanned into offsets by soft_scan.comp) writes the samples at
//           offsets[pixel] - u_base + atomicAdd(fill[pixel]); samples at or past u_cap are
//           dropped (the frame is then flagged, soft_lists.c); so are samples past a pixel's
//           range, which PASS 1 keeps under u_pxcap (the sphere is counted in fill[u_npx]).
// A sample is a vec4: x = +s (enter) or -s (exit); Base: y = z^m (the chord's midpoint), z = d
// (the ray's distance from the centre), w = the point index's bits; Concentric: y = the step of
// the point's density on entering shell i, kappa (mu'_i - mu'_(i-1)), mu' of eq. 13 and 15:
// inside shell i the density is the innermost shell's alone (eq. 16-18); kappa = R K[N] makes
// the sphere's density integrated over its disc the Base-Model's (soft_lists.h); z = the colour
// weight (1 - d / R) on the outermost shell's samples and 0 on the inner ones (eq. 11 per
// point), w = the index's bits.
layout(local_size_x = 64) in;

layout(binding = T_POS) uniform samplerBuffer u_pos;
layout(binding = T_RAD) uniform samplerBuffer u_rad;
layout(binding = T_SOFT_IDX) uniform usamplerBuffer u_idx;
layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys;
layout(std430, binding = B_SOFT_CELLS) buffer Counts { uint counts[]; };
layout(std430, binding = B_SOFT_FILL) buffer Fill { uint fill[]; };
layout(std430, binding = B_SOFT_FRAGS) buffer Frags { vec4 frags[]; };
#include "lib_fetch.glsl"

uniform mat4 u_view, u_proj;
uniform vec4 u_rayo, u_rayd;
uniform ivec2 u_size;
uniform ivec2 u_rows;      // first row and rows of this pass
uniform ivec2 u_stripe;    // the keys' first row and rows
uniform int u_keys_on;
uniform float u_scale, u_znear;
uniform uint u_n;          // soft points
uniform uint u_base, u_cap;
uniform int u_concentric;
uniform int u_row0;        // the counts' first row (the stripe's)
uniform uint u_pxcap;      // samples a pixel may count (soft_lists.c)
uniform uint u_npx;        // the stripe's pixels: fill[u_npx] counts lost spheres
uniform float u_kappa[65]; // Concentric: the density scale per N (soft_lists.c)

void sphere(uint k)
{
    uint i = texelFetch(u_idx, int(k)).x;
    vec3 c = (u_view * vec4(fetch3(u_pos, i), 1.0)).xyz;
    float R = texelFetch(u_rad, int(i)).x * u_scale;
    float depth = -c.z;
    if (!(R > 0.0) || depth + R <= u_znear) return;
    // Conservative screen box: the centre's projection +- the radius at the sphere's nearest depth.
    float dn = max(depth - R, u_znear);
    vec4 cc = u_proj * vec4(c.xy, -max(depth, u_znear), 1.0);
    vec2 ctr = (cc.xy / cc.w * 0.5 + 0.5) * vec2(u_size);
    float ortho = u_proj[3][3];
    float rpx = R * u_proj[1][1] * 0.5 * float(u_size.y) / (ortho != 0.0 ? 1.0 : dn);
    float rpx_c = R * u_proj[1][1] * 0.5 * float(u_size.y) / (ortho != 0.0 ? 1.0 : max(depth, u_znear));
    if (depth - R <= u_znear && ortho == 0.0) { ctr = 0.5 * vec2(u_size); rpx = 1e9; } // camera inside
    ivec2 lo = ivec2(max(floor(ctr - rpx - 1.0), vec2(0.0, float(u_rows.x))));
    ivec2 hi = ivec2(min(ceil(ctr + rpx + 1.0), vec2(float(u_size.x - 1), float(u_rows.x + u_rows.y - 1))));
    int N = u_concentric != 0 ? 1 + int(rpx_c / 4.0) : 1;
    N = min(N, 64);
    // kappa = R K[N]: the sphere's total density (its optical depth integrated over the screen
    // disc) becomes the Base-Model's (soft_lists.c makes the table)
    float kappa = R * u_kappa[N];
    uint ibits = i;
    for (int y = lo.y; y <= hi.y; y++)
        for (int x = lo.x; x <= hi.x; x++) {
            float sx = float(x) + 0.5, sy = float(y) + 0.5;
            vec3 o = vec3(u_rayo.x * sx + u_rayo.y, u_rayo.z * sy + u_rayo.w, 0.0);
            vec3 dir = vec3(u_rayd.x * sx + u_rayd.y, u_rayd.z * sy + u_rayd.w, -1.0);
            float L = length(dir);
            vec3 u = dir / L;
            vec3 m = o - c;
            float b = dot(m, u);
            float d2 = max(dot(m, m) - b * b, 0.0);
            if (d2 >= R * R) continue;
            float dd = sqrt(d2);
            float zm = -b;
            float s0 = u_znear * L;
            float s1 = 3.4e38;
            uint px = uint(y - u_row0) * uint(u_size.x) + uint(x);
            if (u_keys_on != 0) {
                uint key = texelFetch(u_keys, (y - u_stripe.x) * u_size.x + x).x;
                if (key != 0u) s1 = uintBitsToFloat(~key) * L;
            }
            // the samples this ray gets, and (pass 2) where they go
            uint nsamp = 0u;
            for (int j = 0; j < N; j++) {
                float rj = R * (1.0 - float(j) / float(N));
                if (dd >= rj) break;
                float h = sqrt(rj * rj - d2);
                if (max(zm - h, s0) < min(zm + h, s1)) nsamp += 2u;
            }
            if (nsamp == 0u) continue;
#if PASS == 1
            // at most about u_pxcap samples a pixel, so that the frame's total stays a uint
            // (the check and the add are not one atomic: a pixel may pass it by what its
            // concurrent spheres add); past it the sphere is counted as lost
            if (counts[px] < u_pxcap) atomicAdd(counts[px], nsamp);
            else atomicAdd(fill[u_npx], 1u);
#else
            uint at = counts[px] - u_base + atomicAdd(fill[px], nsamp);
            uint end = counts[px + 1u] - u_base; // this pixel's samples end here
            if (at + nsamp > end) atomicAdd(fill[u_npx], 1u);
            for (int j = 0; j < N; j++) {
                float rj = R * (1.0 - float(j) / float(N));
                if (dd >= rj) break;
                float h = sqrt(rj * rj - d2);
                float a = max(zm - h, s0), e = min(zm + h, s1);
                if (!(a < e)) continue;
                vec2 yz;
                if (u_concentric != 0) {
                    // inside shell j the point's density is mu'_j alone (eq. 16-18): the sample
                    // carries the step mu'_j - mu'_(j-1), times kappa
                    float mu = R / (float(N) * rj) * (1.0 - dd / rj); // eq. 13, 15 (r_0 = R)
                    float rp = R * (1.0 - float(j - 1) / float(N));
                    float mup = j > 0 ? R / (float(N) * rp) * (1.0 - dd / rp) : 0.0;
                    yz = vec2((mu - mup) * kappa, j == 0 ? 1.0 - dd / R : 0.0);
                } else {
                    yz = vec2(zm, dd);
                }
                if (at < min(u_cap, end)) frags[at] = vec4(a, yz, uintBitsToFloat(ibits));
                if (at + 1u < min(u_cap, end)) frags[at + 1u] = vec4(-e, yz, uintBitsToFloat(ibits));
                at += 2u;
            }
#endif
        }
}

void main()
{
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint k = gl_GlobalInvocationID.x; k < u_n; k += stride) sphere(k);
}
