#version 430
// points.frag — writes the point's colour (alpha = coverage) and its eye-space depth.

flat in vec3 v_color;
flat in float v_depth;

layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_depth;

void main()
{
    o_color = vec4(v_color, 1.0);
    o_depth = v_depth;
}
