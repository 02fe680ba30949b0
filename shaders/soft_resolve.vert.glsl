#version 430
// soft_resolve.vert — two triangles over the whole frame (the stripe's rows by the scissor).
void main()
{
    const vec2 c[6] = vec2[6](vec2(-1, -1), vec2(1, -1), vec2(-1, 1), vec2(-1, 1), vec2(1, -1), vec2(1, 1));
    gl_Position = vec4(c[gl_VertexID], 0.0, 1.0);
}
