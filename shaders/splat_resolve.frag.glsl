#version 430
#include "lib_bindings.glsl"
#include "lib_shade.glsl"
// splat_resolve.frag — EWA splatting pass 3, a fragment pass over the rectangle of pixels pass 1
// touched, grown by one pixel (splat_resolve.vert; the stripe's rows by the scissor): llvmpipe
// shades whole pixel quads at once, where compute image stores go lane by lane. Per pixel:
//  1. the rest of the low-pass filter: a 3x3 Gaussian (weights u_post: centre, edge, corner)
//     over the accumulated sums of the neighbourhood, depth-aware like the extended z-buffer:
//     only neighbours whose depth lies within u_epsg * z of the nearest one take part, so a
//     surface never bleeds into the one in front of it (with lowpass 0 or ewa=exact, u_post =
//     (1, 0, 0), only the centre counts);
//  2. normalisation: divide by the summed weight;
//  3. deferred shading from the normalised normal (ambient + Lambert + a little Blinn-Phong);
//  4. writes colour (alpha 1 = covered) and the eye depth of the visible surface; background
//     pixels are discarded and keep what the renderer cleared them to.
// The sums are read through a buffer texture over the accumulation buffer (texelFetch is
// vectorised on llvmpipe, storage-buffer reads at varying addresses are not): texel 2i =
// (w r, w g, w b, w), texel 2i + 1 = (w nx, w ny, w nz, unused); the keys (~floatBits(depth),
// 0 empty) come from their own compact buffer, u_keys.
// pipe_splat.c inserts "#define FLOAT_ATOMICS 0|1" after the #version line (the number format
// of the sums, see splat_raster.comp).
#if FLOAT_ATOMICS
layout(binding = T_SPLAT_SUMS) uniform samplerBuffer u_acc;
#define SUMS(t) (t)
#define NSUM(t) (t).xyz
#else
layout(binding = T_SPLAT_SUMS) uniform usamplerBuffer u_acc;
#define SUMS(t) vec4(vec3((t).xyz) / 255.0, float((t).w))
#define NSUM(t) vec3(ivec3((t).xyz))
#endif

layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys; // R32UI: the visibility keys, one a pixel

layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_depth;

uniform ivec2 u_size;     // frame width, height
uniform ivec2 u_stripe;   // first frame row held by the accumulation buffer, rows it holds
uniform vec3 u_post;      // 3x3 low-pass weights: centre, edge, corner
uniform float u_epsg;     // depth tolerance of the gather, relative to the depth
uniform vec3 u_light;     // unit direction towards the light, eye space
uniform int u_color;      // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity
uniform float u_znear, u_zfar; // color=depth: grey 1 at znear to 0 at zfar, as `points`
uniform mat4 u_view;      // local -> eye (color=normal shows local normals, as `points`)

// The key of neighbour (dx, dy) of pixel p; 0 (empty) outside the frame or the stripe, or when
// `use` is false. A fragment's key is never 0, so 0 also means "takes no part".
uint key_at(ivec2 p, int dx, int dy, ivec2 size, ivec2 stripe, bool use)
{
    int xx = p.x + dx, yy = p.y + dy;
    bool ok = use && xx >= 0 && xx < size.x && yy >= stripe.x && yy < stripe.x + stripe.y;
    return ok ? texelFetch(u_keys, (yy - stripe.x) * size.x + xx).x : 0u;
}

// Adds h times the sums of neighbour (dx, dy), whose key is k, when its surface lies within
// zlim.
void gather(uint k, ivec2 p, int dx, int dy, float h, float zlim, ivec2 size, ivec2 stripe,
            inout vec4 acc, inout vec3 n)
{
    if (k == 0u || uintBitsToFloat(~k) > zlim) return;
    int i = (p.y + dy - stripe.x) * size.x + p.x + dx;
    acc += h * SUMS(texelFetch(u_acc, 2 * i));
    n += h * NSUM(texelFetch(u_acc, 2 * i + 1));
}

void main()
{
    // Uniforms into locals first, and the 3x3 neighbourhood as nine named values rather than
    // arrays and loops: llvmpipe reloads a uniform at every use (see splat_raster.comp), and
    // the loop-and-array form of this shader cost ~45 ms for a full 1280x720 frame against
    // ~4 ms for the bare pass.
    ivec2 size = u_size, stripe = u_stripe;
    vec3 post = u_post;
    ivec2 p = ivec2(gl_FragCoord.xy);
    bool wide = post.y > 0.0;
    uint k0 = key_at(p, -1, -1, size, stripe, wide), k1 = key_at(p, 0, -1, size, stripe, wide);
    uint k2 = key_at(p, 1, -1, size, stripe, wide), k3 = key_at(p, -1, 0, size, stripe, wide);
    uint k4 = key_at(p, 0, 0, size, stripe, true), k5 = key_at(p, 1, 0, size, stripe, wide);
    uint k6 = key_at(p, -1, 1, size, stripe, wide), k7 = key_at(p, 0, 1, size, stripe, wide);
    uint k8 = key_at(p, 1, 1, size, stripe, wide);
    uint kmax = max(max(max(k0, k1), max(k2, k3)), max(max(k4, k5), max(max(k6, k7), k8)));
    if (kmax == 0u) discard; // background: the renderer cleared it
    float zref = uintBitsToFloat(~kmax);
    float zlim = zref * (1.0 + u_epsg);
    vec4 acc = vec4(0.0);
    vec3 n = vec3(0.0);
    // Weights: centre post.x, edges post.y, corners post.z.
    gather(k0, p, -1, -1, post.z, zlim, size, stripe, acc, n);
    gather(k1, p, 0, -1, post.y, zlim, size, stripe, acc, n);
    gather(k2, p, 1, -1, post.z, zlim, size, stripe, acc, n);
    gather(k3, p, -1, 0, post.y, zlim, size, stripe, acc, n);
    gather(k4, p, 0, 0, post.x, zlim, size, stripe, acc, n);
    gather(k5, p, 1, 0, post.y, zlim, size, stripe, acc, n);
    gather(k6, p, -1, 1, post.z, zlim, size, stripe, acc, n);
    gather(k7, p, 0, 1, post.y, zlim, size, stripe, acc, n);
    gather(k8, p, 1, 1, post.z, zlim, size, stripe, acc, n);
    if (!(acc.w > 0.0)) discard;
    // The pixel's own surface when it is the visible one, else the nearest neighbour's.
    float z4 = uintBitsToFloat(~k4);
    float zc = k4 != 0u && z4 <= zlim ? z4 : zref;
    vec3 col = acc.rgb / acc.w;
    float nl = dot(n, n);
    n = nl > 0.0 ? n * inversesqrt(nl) : vec3(0.0, 0.0, 1.0);
    int color = u_color;
    if (color == 2) {
        col = transpose(mat3(u_view)) * n * 0.5 + 0.5;
    } else if (color == 3) {
        float znear = u_znear, zfar = u_zfar;
        col = vec3(1.0 - clamp((zc - znear) / (zfar - znear), 0.0, 1.0));
    } else {
        // lib_shade.glsl, the specular term scaled by the colour: a surface facing a light along
        // the view axis keeps exactly its colour; nothing exceeds it.
        col *= shade(n, u_light);
    }
    o_color = vec4(col, 1.0);
    o_depth = zc;
}
