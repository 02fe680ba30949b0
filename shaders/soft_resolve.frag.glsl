#version 430
#include "lib_bindings.glsl"
// soft_resolve.frag — puts the soft layer (soft_blend.comp: premultiplied colour, alpha) over
// the target with the blend (ONE, ONE_MINUS_SRC_ALPHA); pixels no soft disc reached are
// discarded.
layout(binding = T_SOFT_LAYER) uniform samplerBuffer u_layer; // RGBA32F per stripe pixel
uniform ivec2 u_size;
uniform ivec2 u_rows;
layout(location = 0) out vec4 o_color;

void main()
{
    ivec2 q = ivec2(gl_FragCoord.xy);
    vec4 L = texelFetch(u_layer, (q.y - u_rows.x) * u_size.x + q.x);
    if (L.a <= 0.0) discard;
    o_color = L;
}
