#version 430
#include "lib_bindings.glsl"
// soft.frag — one fragment of a soft disc (soft.vert): the Express-Model's opacity, eq. 19,
// Phi = lambda (cos(pi d / r) + 1) / 2 at distance d from the disc's centre, modulated near the
// threshold by eq. 22, Phi_f = (1 - d/r) (1 - W) + Phi W with W = (F - t) / (l_m - t) (pipe_soft.c
// says why the lambda of the paper's "lambda (1 - d)" is left out), written premultiplied for
// the "over" blend (ONE, ONE_MINUS_SRC_ALPHA). Fragments behind the solid surface (the splat
// pipeline's visibility key of the pixel: ~floatBits(eye depth), 0 empty) are discarded; no
// depth is written.

layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys;

uniform ivec2 u_size;
uniform ivec2 u_stripe;    // first frame row the keys hold, rows they hold
uniform int u_keys_on;     // 0: no solid point in the frame
uniform float u_lambda;

flat in vec3 v_color;
flat in vec3 v_disc;
flat in float v_depth;
flat in float v_w;

layout(location = 0) out vec4 o_color;

void main()
{
    float d = length(gl_FragCoord.xy - v_disc.xy) / v_disc.z;
    if (!(d < 1.0)) discard;
    if (u_keys_on != 0) {
        ivec2 q = ivec2(gl_FragCoord.xy);
        uint key = texelFetch(u_keys, (q.y - u_stripe.x) * u_size.x + q.x).x;
        if (key != 0u && v_depth >= uintBitsToFloat(~key)) discard;
    }
    float phi = u_lambda * (cos(3.14159265358979 * d) + 1.0) * 0.5;
    phi = mix(1.0 - d, phi, v_w);
    o_color = vec4(v_color * phi, phi);
}
