#version 430
// kawata_splat.vert — pass 5's geometry (kawata_splat.frag.glsl): two triangles per 8x8 tile of
// buffer pixels (instance u_t0 + (i % u_tcols, i / u_tcols)), covering the frame pixels whose
// centres fall in its buffer pixels, or nothing (a degenerate triangle) where kawata_fit.comp
// marked no splat within reach. llvmpipe runs a fragment's every instruction for every lane,
// masked, so the gather over the whole rectangle paid as much for the empty frame pixels as for
// covered ones; skipped tiles are never rasterised.

#include "lib_bindings.glsl"

layout(binding = T_KAWATA_TILES) uniform usamplerBuffer u_tiles;
uniform ivec2 u_bsize;
uniform ivec2 u_t0;     // the first tile drawn
uniform int u_tcols;    // tiles a row drawn

void main()
{
    ivec2 bsize = u_bsize;
    int i = gl_InstanceID, v = gl_VertexID, cols = u_tcols;
    ivec2 t = u_t0 + ivec2(i % cols, i / cols);
    bool on = texelFetch(u_tiles, t.y * ((bsize.x + 7) >> 3) + t.x).x != 0u;
    // corners (0,0) (1,0) (0,1), (1,0) (1,1) (0,1)
    ivec2 c = ivec2(v == 1 || v == 3 || v == 4 ? 1 : 0, v == 2 || v == 4 || v == 5 ? 1 : 0);
    vec2 p = vec2((t + c) * 8) / vec2(bsize) * 2.0 - 1.0;
    gl_Position = on ? vec4(p, 0.0, 1.0) : vec4(-2.0, -2.0, 0.0, 1.0);
}
