#version 430
#include "lib_bindings.glsl"
// splat_resolve.vert — two triangles covering the rectangle of pixels pass 1 touched in this
// stripe (splat_raster.comp's Rect), grown by one pixel for the 3x3 gather and clipped to the
// frame, for splat_resolve.frag.glsl: pixels outside it have no neighbour with weight and
// would be discarded. An empty rectangle gives degenerate triangles.

layout(std430, binding = B_SPLAT_RECT) readonly restrict buffer Rect { ivec4 rect; };

uniform ivec2 u_size; // frame width, height

void main()
{
    const vec2 corner[6] = vec2[6](vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(0.0, 1.0),
                                   vec2(0.0, 1.0), vec2(1.0, 0.0), vec2(1.0, 1.0));
    ivec4 r = rect;
    vec2 lo = vec2(0.0), hi = vec2(0.0);
    if (r.x <= r.z && r.y <= r.w) {
        lo = vec2(max(r.xy - 1, ivec2(0)));
        hi = vec2(min(r.zw + 2, u_size));
    }
    vec2 p = mix(lo, hi, corner[gl_VertexID]) / vec2(u_size) * 2.0 - 1.0;
    gl_Position = vec4(p, 0.0, 1.0);
}
