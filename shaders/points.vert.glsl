#version 430
// points.vert — the `points` pipeline as GL_POINTS with the depth test (SPLATD_POINTS_RASTER=gl).
// Attributes come straight from the cloud's buffers (pipe.h rnd_gpu_cloud). The colour rules
// are the same as in points_resolve.frag.glsl: keep them in step.

layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec4 a_rgba;      // RGBA8, normalised
layout(location = 2) in vec3 a_normal;
layout(location = 3) in float a_field;
layout(location = 4) in float a_intensity;
layout(location = 5) in float a_scan;

uniform mat4 u_viewproj;
uniform float u_point_size;
uniform int u_color;          // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity, 5 scan (params.h)
uniform float u_znear, u_zfar;

flat out vec3 v_color;
flat out float v_depth;

#include "lib_colormap.glsl"

void main()
{
    vec4 c = u_viewproj * vec4(a_pos, 1.0);
    gl_Position = c;
    gl_PointSize = u_point_size;
    v_depth = c.w; // the projection's w is the eye-space depth along the view axis
    if (u_color == 1) v_color = colormap(a_field);
    else if (u_color == 2) v_color = a_normal * 0.5 + 0.5;
    else if (u_color == 3)
        v_color = vec3(1.0 - clamp((c.w - u_znear) / (u_zfar - u_znear), 0.0, 1.0));
    else if (u_color == 4) v_color = vec3(clamp(a_intensity, 0.0, 1.0));
    else if (u_color == 5) v_color = colormap(a_scan);
    else v_color = a_rgba.rgb;
}
