#version 430
#include "lib_bindings.glsl"
// soft_fblend.comp — the last pass of model=base and model=concentric (soft_lists.c): per pixel
// of rows [u_rows.x, u_rows.x + u_rows.y), its samples (soft_frag.comp) sorted by ray distance
// in place (insertion sort up to 32 samples, Shell sort beyond), then walked front to back: each
// segment between two consecutive samples gets the optical depth of the spheres the ray is
// inside and their colour by eq. 11 (weights 1 - d / r), and is blended front to back,
// L += T alpha C, T *= 1 - alpha, alpha = 1 - exp(-lambda tau / u^2) with u the length unit
// (soft_lists.c). The layer (premultiplied L, 1 - T) goes to SOFT_LAYER, which
// soft_resolve.frag puts over the target.
//   Base (CONCENTRIC 0): tau = sum over the open spheres of the exact integral of
//     rho = r - sqrt(z^2 + d^2) (eq. 5) between the segment's ends relative to the sphere's
//     midpoint z^m: P(b - z^m) - P(a - z^m), P(z) = r z - z sqrt(z^2 + d^2) / 2
//     - d^2 asinh(z / d) / 2 (eq. 7, odd in z; eq. 8-10). The open spheres are kept in a local
//     array of MAXOPEN; a sphere beyond that is left out and counted in fill[u_npx] (the frame is
//     flagged).
//   Concentric (CONCENTRIC 1): tau = (sum of the open spheres' densities) times the segment's
//     length (eq. 14-18); running sums, no array.
layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = T_POS) uniform samplerBuffer u_pos;
layout(binding = T_NRM) uniform samplerBuffer u_nrm;
layout(binding = T_RAD) uniform samplerBuffer u_rad;
layout(binding = T_SRC) uniform usamplerBuffer u_src;
layout(std430, binding = B_SOFT_CELLS) buffer Counts { uint offs[]; };
layout(std430, binding = B_SOFT_FILL) buffer Fill { uint fill[]; };
layout(std430, binding = B_SOFT_FRAGS) buffer Frags { vec4 frags[]; };
layout(std430, binding = B_SOFT_LAYER) buffer Layer { vec4 layer[]; };
#include "lib_colormap.glsl"
#include "lib_fetch.glsl"
#include "lib_shade.glsl"

uniform ivec2 u_size;
uniform ivec2 u_rows;      // rows of this pass (the layer's rows)
uniform int u_row0;        // the offsets' first row (the stripe's)
uniform uint u_base, u_cap, u_npx;
uniform float u_k;         // lambda / u^2
uniform float u_scale;
uniform int u_color;
uniform mat4 u_view, u_proj;
uniform vec3 u_light;      // unit, eye space (splat's)

#define MAXOPEN 32

// The colour of point i, Lambert-shaded as splat's resolve (the paper shades all points) from
// its normal turned towards the viewer.
vec3 colour_of(uint i)
{
    vec3 c;
    if (u_color == 0) c = unpackUnorm4x8(texelFetch(u_src, int(i)).x).rgb;
    else if (u_color == 1 || u_color == 5) c = colormap(uintBitsToFloat(texelFetch(u_src, int(i)).x));
    else if (u_color == 4) c = vec3(clamp(uintBitsToFloat(texelFetch(u_src, int(i)).x), 0.0, 1.0));
    else return vec3(1.0);
    mat3 v = mat3(u_view);
    vec3 n = v * fetch3(u_nrm, i);
    float nl2 = dot(n, n);
    n = nl2 > 0.0 ? n * inversesqrt(nl2) : vec3(0.0, 0.0, 1.0);
    vec3 e = (u_view * vec4(fetch3(u_pos, i), 1.0)).xyz;
    if (dot(n, u_proj[3][3] == 0.0 ? e : vec3(0.0, 0.0, -1.0)) > 0.0) n = -n;
    return c * shade(n, u_light);
}

float key(uint j) { return abs(frags[j].x); }

// P(z) = integral from 0 to z of r - sqrt(t^2 + d^2) dt (eq. 7 with the constant removed).
float P(float z, float r, float d)
{
    float q = sqrt(z * z + d * d);
    float l = d > 1e-7 * r ? d * d * asinh(z / d) : 0.0;
    return r * z - 0.5 * z * q - 0.5 * l;
}

void main()
{
    ivec2 q = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, u_rows.x);
    if (q.x >= u_size.x || q.y >= u_rows.x + u_rows.y) return;
    uint px = uint(q.y - u_row0) * uint(u_size.x) + uint(q.x);
    uint a = offs[px], z = offs[px + 1u];
    a = a >= u_base ? a - u_base : 0u;
    z = z >= u_base ? min(z - u_base, u_cap) : 0u;
    vec4 outc = vec4(0.0);
    if (a < z) {
        uint n = z - a;
        // sort [a, z) by ray distance
        uint gap = n > 32u ? n / 3u : 1u;
        while (true) {
            for (uint j = a + gap; j < z; j++) {
                vec4 v = frags[j];
                float kv = abs(v.x);
                uint m = j;
                while (m >= a + gap && key(m - gap) > kv) {
                    frags[m] = frags[m - gap];
                    m -= gap;
                }
                frags[m] = v;
            }
            if (gap == 1u) break;
            gap = gap / 3u > 0u ? gap / 3u : 1u;
        }
        vec3 L = vec3(0.0);
        float T = 1.0;
        float sprev = abs(frags[a].x);
#if CONCENTRIC
        float dens = 0.0, ws = 0.0;
        vec3 wc = vec3(0.0), cplain = vec3(0.0);
        int nopen = 0;
        for (uint j = a; j < z; j++) {
            vec4 f = frags[j];
            float s = abs(f.x);
            if (nopen > 0 && s > sprev) {
                float alpha = 1.0 - exp(-u_k * max(dens, 0.0) * (s - sprev));
                vec3 col = ws > 1e-6 ? wc / ws : cplain / float(nopen);
                L += T * alpha * col;
                T *= 1.0 - alpha;
            }
            sprev = s;
            vec3 c = colour_of(floatBitsToUint(f.w));
            float sg = f.x >= 0.0 ? 1.0 : -1.0;
            dens += sg * f.y;
            ws += sg * f.z;
            wc += sg * f.z * c;
            cplain += sg * c;
            nopen += f.x >= 0.0 ? 1 : -1;
            if (nopen <= 0) nopen = 0, dens = 0.0, ws = 0.0, wc = vec3(0.0), cplain = vec3(0.0);
        }
#else
        float ozm[MAXOPEN], od[MAXOPEN], orr[MAXOPEN];
        uint oid[MAXOPEN];
        vec3 oc[MAXOPEN];
        int nopen = 0;
        uint lost = 0u;
        for (uint j = a; j < z; j++) {
            vec4 f = frags[j];
            float s = abs(f.x);
            if (nopen > 0 && s > sprev) {
                float tau = 0.0, ws = 0.0;
                vec3 wc = vec3(0.0), cs = vec3(0.0);
                for (int o = 0; o < nopen; o++) {
                    tau += P(s - ozm[o], orr[o], od[o]) - P(sprev - ozm[o], orr[o], od[o]);
                    float w = 1.0 - od[o] / orr[o];
                    ws += w;
                    wc += w * oc[o];
                    cs += oc[o];
                }
                float alpha = 1.0 - exp(-u_k * max(tau, 0.0));
                vec3 col = ws > 1e-6 ? wc / ws : cs / float(nopen);
                L += T * alpha * col;
                T *= 1.0 - alpha;
            }
            sprev = s;
            uint id = floatBitsToUint(f.w);
            if (f.x >= 0.0) {
                if (nopen < MAXOPEN) {
                    ozm[nopen] = f.y, od[nopen] = f.z, oid[nopen] = id;
                    orr[nopen] = texelFetch(u_rad, int(id)).x * u_scale;
                    oc[nopen] = colour_of(id);
                    nopen++;
                } else {
                    lost++;
                }
            } else {
                for (int o = 0; o < nopen; o++)
                    if (oid[o] == id) {
                        nopen--;
                        ozm[o] = ozm[nopen], od[o] = od[nopen], orr[o] = orr[nopen];
                        oid[o] = oid[nopen], oc[o] = oc[nopen];
                        break;
                    }
            }
        }
        if (lost > 0u) atomicAdd(fill[u_npx], lost);
#endif
        outc = vec4(L, 1.0 - T);
    }
    layer[(q.y - u_rows.x) * u_size.x + q.x] = outc;
}
