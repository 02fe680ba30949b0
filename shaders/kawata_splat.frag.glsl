#version 430
// kawata_splat.frag — pass 5 of the `kawata` pipeline (pipe_kawata.c): Gaussian splats of the
// image buffer magnified to the frame with normalised blending, as a gather. A splat (from
// kawata_fit.comp: its centre in frame pixels, eye depth, colour) has the weight
// exp(-r^2 / (2 s^2)) at distance r < R = u_cutoff frame pixels from its centre (s: 0.75 buffer
// pixels, R: 2, so that a frame pixel inside an empty buffer pixel still reaches the splats of
// its neighbours), so the splats that reach a frame pixel lie in the 5x5 buffer pixels around
// it. Among those, only the ones within the depth tolerance (u_gamma + u_slope * depth) of the
// nearest take part (the extended z-buffer: a surface behind does not bleed into the one in
// front); the colour and the eye depth are their weighted means. The 25 taps are written out
// rather than looped over arrays: llvmpipe keeps named values in registers
// (splat_resolve.frag.glsl measured loops and arrays at 10x).

#include "lib_bindings.glsl"

// RGBA32F, 2 texels a buffer pixel: (frame x, y, eye depth, valid), colour. A buffer texture:
// on llvmpipe its texelFetch gathers all SIMD lanes at once (a 2-D texelFetch costs several
// times as much, textureLod about twice).
layout(binding = T_KAWATA_SPLATS) uniform samplerBuffer u_splats;

uniform ivec2 u_bsize, u_fsize;
uniform ivec2 u_blo, u_bhi; // the buffer pixels this frame wrote (kawata_fit.comp)
uniform float u_cutoff;   // R, frame pixels
uniform float u_k;        // 1 / (2 s^2), s the kernel's standard deviation in frame pixels
uniform float u_gamma, u_slope;

layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_depth;

const float NONE = 3.0e38;

// (depth, weight) of the splat of buffer pixel q for the frame pixel centre f; (NONE, 0) when
// there is none or it does not reach f.
vec2 tap(ivec2 q, vec2 f, int w, ivec2 blo, ivec2 bhi, float r2max, float k)
{
    if (q.x < blo.x || q.y < blo.y || q.x >= bhi.x || q.y >= bhi.y) return vec2(NONE, 0.0);
    vec4 s = texelFetch(u_splats, 2 * (q.y * w + q.x));
    vec2 d = s.xy - f;
    float r2 = dot(d, d);
    if (s.w == 0.0 || r2 >= r2max) return vec2(NONE, 0.0);
    return vec2(s.z, exp(-k * r2));
}

void add(vec2 t, ivec2 q, int w, float zlim, inout vec4 acc, inout float zs)
{
    if (t.y == 0.0 || t.x > zlim) return;
    acc += t.y * vec4(texelFetch(u_splats, 2 * (q.y * w + q.x) + 1).rgb, 1.0);
    zs += t.y * t.x;
}

void main()
{
    ivec2 bsize = u_bsize, blo = u_blo, bhi = u_bhi;
    int w = bsize.x;
    vec2 f = gl_FragCoord.xy;
    float rc = u_cutoff, r2max = rc * rc, k = u_k;
    vec2 u = f * vec2(bsize) / vec2(u_fsize); // the frame pixel's centre in buffer pixels
    ivec2 b0 = ivec2(floor(u - 2.0));
    vec2 t00 = tap(b0 + ivec2(0, 0), f, w, blo, bhi, r2max, k);
    vec2 t01 = tap(b0 + ivec2(1, 0), f, w, blo, bhi, r2max, k);
    vec2 t02 = tap(b0 + ivec2(2, 0), f, w, blo, bhi, r2max, k);
    vec2 t03 = tap(b0 + ivec2(3, 0), f, w, blo, bhi, r2max, k);
    vec2 t04 = tap(b0 + ivec2(4, 0), f, w, blo, bhi, r2max, k);
    vec2 t10 = tap(b0 + ivec2(0, 1), f, w, blo, bhi, r2max, k);
    vec2 t11 = tap(b0 + ivec2(1, 1), f, w, blo, bhi, r2max, k);
    vec2 t12 = tap(b0 + ivec2(2, 1), f, w, blo, bhi, r2max, k);
    vec2 t13 = tap(b0 + ivec2(3, 1), f, w, blo, bhi, r2max, k);
    vec2 t14 = tap(b0 + ivec2(4, 1), f, w, blo, bhi, r2max, k);
    vec2 t20 = tap(b0 + ivec2(0, 2), f, w, blo, bhi, r2max, k);
    vec2 t21 = tap(b0 + ivec2(1, 2), f, w, blo, bhi, r2max, k);
    vec2 t22 = tap(b0 + ivec2(2, 2), f, w, blo, bhi, r2max, k);
    vec2 t23 = tap(b0 + ivec2(3, 2), f, w, blo, bhi, r2max, k);
    vec2 t24 = tap(b0 + ivec2(4, 2), f, w, blo, bhi, r2max, k);
    vec2 t30 = tap(b0 + ivec2(0, 3), f, w, blo, bhi, r2max, k);
    vec2 t31 = tap(b0 + ivec2(1, 3), f, w, blo, bhi, r2max, k);
    vec2 t32 = tap(b0 + ivec2(2, 3), f, w, blo, bhi, r2max, k);
    vec2 t33 = tap(b0 + ivec2(3, 3), f, w, blo, bhi, r2max, k);
    vec2 t34 = tap(b0 + ivec2(4, 3), f, w, blo, bhi, r2max, k);
    vec2 t40 = tap(b0 + ivec2(0, 4), f, w, blo, bhi, r2max, k);
    vec2 t41 = tap(b0 + ivec2(1, 4), f, w, blo, bhi, r2max, k);
    vec2 t42 = tap(b0 + ivec2(2, 4), f, w, blo, bhi, r2max, k);
    vec2 t43 = tap(b0 + ivec2(3, 4), f, w, blo, bhi, r2max, k);
    vec2 t44 = tap(b0 + ivec2(4, 4), f, w, blo, bhi, r2max, k);
    float zmin = min(min(min(min(min(min(t00.x, t01.x), min(t02.x, t03.x)), t04.x), min(min(min(t10.x, t11.x), min(t12.x, t13.x)), t14.x)), min(min(min(min(t20.x, t21.x), min(t22.x, t23.x)), t24.x), min(min(min(t30.x, t31.x), min(t32.x, t33.x)), t34.x))),
                     min(min(min(t40.x, t41.x), min(t42.x, t43.x)), t44.x));
    if (zmin >= NONE) discard;
    float zlim = zmin + u_gamma + u_slope * zmin;
    vec4 acc = vec4(0.0);
    float zs = 0.0;
    add(t00, b0 + ivec2(0, 0), w, zlim, acc, zs);
    add(t01, b0 + ivec2(1, 0), w, zlim, acc, zs);
    add(t02, b0 + ivec2(2, 0), w, zlim, acc, zs);
    add(t03, b0 + ivec2(3, 0), w, zlim, acc, zs);
    add(t04, b0 + ivec2(4, 0), w, zlim, acc, zs);
    add(t10, b0 + ivec2(0, 1), w, zlim, acc, zs);
    add(t11, b0 + ivec2(1, 1), w, zlim, acc, zs);
    add(t12, b0 + ivec2(2, 1), w, zlim, acc, zs);
    add(t13, b0 + ivec2(3, 1), w, zlim, acc, zs);
    add(t14, b0 + ivec2(4, 1), w, zlim, acc, zs);
    add(t20, b0 + ivec2(0, 2), w, zlim, acc, zs);
    add(t21, b0 + ivec2(1, 2), w, zlim, acc, zs);
    add(t22, b0 + ivec2(2, 2), w, zlim, acc, zs);
    add(t23, b0 + ivec2(3, 2), w, zlim, acc, zs);
    add(t24, b0 + ivec2(4, 2), w, zlim, acc, zs);
    add(t30, b0 + ivec2(0, 3), w, zlim, acc, zs);
    add(t31, b0 + ivec2(1, 3), w, zlim, acc, zs);
    add(t32, b0 + ivec2(2, 3), w, zlim, acc, zs);
    add(t33, b0 + ivec2(3, 3), w, zlim, acc, zs);
    add(t34, b0 + ivec2(4, 3), w, zlim, acc, zs);
    add(t40, b0 + ivec2(0, 4), w, zlim, acc, zs);
    add(t41, b0 + ivec2(1, 4), w, zlim, acc, zs);
    add(t42, b0 + ivec2(2, 4), w, zlim, acc, zs);
    add(t43, b0 + ivec2(3, 4), w, zlim, acc, zs);
    add(t44, b0 + ivec2(4, 4), w, zlim, acc, zs);
    o_color = vec4(acc.rgb / acc.w, 1.0);
    o_depth = zs / acc.w;
}
