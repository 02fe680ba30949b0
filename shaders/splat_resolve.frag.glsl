#version 430
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
uniform samplerBuffer u_acc;
#define SUMS(t) (t)
#define NSUM(t) (t).xyz
#else
uniform usamplerBuffer u_acc;
#define SUMS(t) vec4(vec3((t).xyz) / 255.0, float((t).w))
#define NSUM(t) vec3(ivec3((t).xyz))
#endif

uniform usamplerBuffer u_keys; // R32UI: the visibility keys, one a pixel

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

void main()
{
    // Uniforms into locals first: llvmpipe reloads a uniform at every use (see
    // splat_raster.comp).
    ivec2 U_size = u_size;
    ivec2 U_stripe = u_stripe;
    vec3 U_post = u_post;
    float U_epsg = u_epsg;
    vec3 U_light = u_light;
    int U_color = u_color;
    float U_znear = u_znear;
    float U_zfar = u_zfar;
    mat4 U_view = u_view;
    ivec2 p = ivec2(gl_FragCoord.xy);
    int y = p.y;
    // The 3x3 neighbourhood's keys, fetched once (constant loops: unrolled, in registers).
    bool wide = U_post.y > 0.0;
    uint kk[9];
    bool ok[9];
    uint kmax = 0u;
    for (int j = 0; j < 9; j++) {
        int xx = p.x + j % 3 - 1, yy = y + j / 3 - 1;
        ok[j] = (wide || j == 4) && xx >= 0 && xx < U_size.x && yy >= U_stripe.x &&
                yy < U_stripe.x + U_stripe.y;
        int i = (yy - U_stripe.x) * U_size.x + xx;
        kk[j] = ok[j] ? texelFetch(u_keys, i).x : 0u;
        kmax = max(kmax, kk[j]);
    }
    if (kmax == 0u) discard; // background: the renderer cleared it
    float zref = uintBitsToFloat(~kmax);
    float zlim = zref * (1.0 + U_epsg);
    vec4 acc = vec4(0.0);
    vec3 n = vec3(0.0);
    float zc = zref;
    for (int j = 0; j < 9; j++) {
        uint k = kk[j];
        float z = uintBitsToFloat(~k);
        if (!ok[j] || k == 0u || z > zlim) continue;
        int i = (y + j / 3 - 1 - U_stripe.x) * U_size.x + p.x + j % 3 - 1;
        float h = j == 4 ? U_post.x : (j & 1) == 1 ? U_post.y : U_post.z;
        acc += h * SUMS(texelFetch(u_acc, 2 * i));
        n += h * NSUM(texelFetch(u_acc, 2 * i + 1));
        if (j == 4) zc = z; // the pixel's own surface when it is the visible one
    }
    if (!(acc.w > 0.0)) discard;
    vec3 col = acc.rgb / acc.w;
    float nl = dot(n, n);
    n = nl > 0.0 ? n * inversesqrt(nl) : vec3(0.0, 0.0, 1.0);
    if (U_color == 2) {
        col = transpose(mat3(U_view)) * n * 0.5 + 0.5;
    } else if (U_color == 3) {
        col = vec3(1.0 - clamp((zc - U_znear) / (U_zfar - U_znear), 0.0, 1.0));
    } else {
        // Ambient + Lambert + Blinn-Phong with an infinite viewer (v = +z), weights summing to 1,
        // and the specular term scaled by the colour: a surface facing a light along the view
        // axis keeps exactly its colour; nothing exceeds it.
        vec3 l = U_light;
        vec3 hv = l + vec3(0.0, 0.0, 1.0);
        float hl = dot(hv, hv);
        float ndl = max(dot(n, l), 0.0);
        float ndh = hl > 0.0 ? max(dot(n, hv * inversesqrt(hl)), 0.0) : 0.0;
        col *= 0.2 + 0.7 * ndl + 0.1 * pow(ndh, 32.0);
    }
    o_color = vec4(col, 1.0);
    o_depth = zc;
}
