#version 430
#include "lib_bindings.glsl"
// soft.vert — the soft points of pipeline=soft (pipe_soft.c) as view-facing discs: one
// GL_POINTS vertex per soft point, drawn without vertex attributes. Vertex k reads the point
// index from the sorted index array (u_idx, R32UI: the set's soft points ordered along one axis),
// forwards or backwards (u_rev), so that the rasteriser's primitive order is back to front.
// The disc's radius is the splat radius times splat_scale, seen face on: its screen radius is
// r * proj[1][1] * height / 2 / depth, and the sprite is the disc's bounding square plus a pixel.

layout(binding = T_POS) uniform samplerBuffer u_pos;    // R32F: x y z per point
layout(binding = T_RAD) uniform samplerBuffer u_rad;    // R32F: splat radius
layout(binding = T_SRC) uniform usamplerBuffer u_src;   // R32UI: rgba8 or float bits (u_color)
layout(binding = T_SOFT_F) uniform usamplerBuffer u_f;  // R32UI: float bits of the field source
layout(binding = T_SOFT_IDX) uniform usamplerBuffer u_idx; // R32UI: sorted soft point indices

#include "lib_fetch.glsl"
#include "lib_colormap.glsl"

uniform mat4 u_view, u_proj;
uniform ivec2 u_size;      // frame width, height
uniform float u_scale;     // splat_scale
uniform float u_maxsize;   // the largest point size the GL allows
uniform int u_color;       // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity
uniform float u_znear, u_zfar;
uniform int u_field;       // 0 uncertainty, 1 height, 2 intensity (params.h SP_FIELD_*)
uniform vec2 u_zrange;     // height: z min and 1 / (z max - z min) (0 for a flat cloud)
uniform float u_t, u_lm;   // threshold t and modulation limit l_m (eq. 22; l_m <= t: off)
uniform uint u_base, u_n;  // this axis' array: first texel, soft points
uniform int u_rev;         // 1: read the array backwards

flat out vec3 v_color;
flat out vec3 v_disc;      // centre (window pixels) and radius (pixels)
flat out float v_depth;    // eye depth of the disc's centre
flat out float v_w;        // W(F) of eq. 22, 1 when the modulation is off

void main()
{
    uint k = uint(gl_VertexID);
    uint i = texelFetch(u_idx, int(u_base + (u_rev != 0 ? u_n - 1u - k : k))).x;
    vec3 p = fetch3(u_pos, i);
    vec4 e = u_view * vec4(p, 1.0);
    float depth = -e.z;
    float r = texelFetch(u_rad, int(i)).x * u_scale;
    vec4 c = u_proj * e;
    gl_Position = c;
    v_depth = depth;
    float rpx = r * u_proj[1][1] * 0.5 * float(u_size.y) / max(depth, 1e-30);
    vec2 px = (c.xy / c.w * 0.5 + 0.5) * vec2(u_size);
    v_disc = vec3(px, rpx);
    gl_PointSize = clamp(2.0 * rpx + 2.0, 1.0, u_maxsize);
    if (depth <= u_znear) gl_Position = vec4(2.0, 2.0, 2.0, 1.0); // behind the near plane: culled

    float f;
    if (u_field == 1) f = clamp((p.z - u_zrange.x) * u_zrange.y, 0.0, 1.0);
    else f = uintBitsToFloat(texelFetch(u_f, int(i)).x);
    v_w = u_lm > u_t ? clamp((f - u_t) / (u_lm - u_t), 0.0, 1.0) : 1.0;

    if (u_color == 0) v_color = unpackUnorm4x8(texelFetch(u_src, int(i)).x).rgb;
    else if (u_color == 1) v_color = colormap(uintBitsToFloat(texelFetch(u_src, int(i)).x));
    else if (u_color == 4) v_color = vec3(clamp(uintBitsToFloat(texelFetch(u_src, int(i)).x), 0.0, 1.0));
    else if (u_color == 3) v_color = vec3(1.0 - clamp((depth - u_znear) / (u_zfar - u_znear), 0.0, 1.0));
    else v_color = vec3(0.5, 0.5, 1.0); // normal: a view-facing disc's normal points at the eye
}
