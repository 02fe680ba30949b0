#version 430
// kawata_splat.vert — one triangle covering the frame (the scissor limits it to the cloud's
// rectangle), for kawata_splat.frag.glsl.

void main()
{
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
