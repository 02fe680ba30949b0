#version 430
// points.vert — the `points` pipeline as GL_POINTS with the depth test (SPLATD_POINTS_RASTER=gl).
// Attributes come straight from the cloud's buffers (pipe.h rnd_gpu_cloud). The colour rules
// are the same as in points_resolve.frag.glsl (GLSL here has no #include): keep them in step.

layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec4 a_rgba;      // RGBA8, normalised
layout(location = 2) in vec3 a_normal;
layout(location = 3) in float a_field;
layout(location = 4) in float a_intensity;

uniform mat4 u_viewproj;
uniform float u_point_size;
uniform int u_color;          // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity (params.h)
uniform float u_znear, u_zfar;

flat out vec3 v_color;
flat out float v_depth;

// Viridis as a polynomial fit (after Matt Zucconi's CC0 fit of the matplotlib map).
vec3 colormap(float t)
{
    t = clamp(t, 0.0, 1.0);
    const vec3 c0 = vec3(0.2777273272, 0.0054073445, 0.3340998053);
    const vec3 c1 = vec3(0.1050930431, 1.4046135299, 1.3845901626);
    const vec3 c2 = vec3(-0.3308618287, 0.2148475595, 0.0950951630);
    const vec3 c3 = vec3(-4.6342304990, -5.7991009734, -19.3324409563);
    const vec3 c4 = vec3(6.2282699363, 14.1799333668, 56.6905526007);
    const vec3 c5 = vec3(4.7763849977, -13.7451453777, -65.3530326334);
    const vec3 c6 = vec3(-5.4354558559, 4.6458526122, 26.3124352496);
    return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
}

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
    else v_color = a_rgba.rgb;
}
