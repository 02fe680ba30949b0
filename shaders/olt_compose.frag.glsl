#version 430
#include "lib_bindings.glsl"
// olt_compose.frag — One-Layer Transparency's last step (pipe_olt.c): the first soft layer
// (its resolved colour on T_OLT_COLOR, its visibility keys on T_OLT_KEYS) over what lies behind
// it (already in the target, whose keys are the splat pass's, T_SPLAT_KEYS) with opacity
// lambda, premultiplied for the blend (ONE, ONE_MINUS_SRC_ALPHA). Pixels without a soft layer,
// or whose nearest surface behind the peel is in front of the layer (a solid point), are
// discarded. Keys: ~floatBits(eye depth), 0 empty.
layout(binding = T_OLT_COLOR) uniform sampler2D u_layer;
layout(binding = T_OLT_KEYS) uniform usamplerBuffer u_lkeys;
layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys;
uniform ivec2 u_size;
uniform ivec2 u_stripe;    // first frame row the keys hold, rows they hold
uniform float u_lambda;
layout(location = 0) out vec4 o_color;

void main()
{
    ivec2 q = ivec2(gl_FragCoord.xy);
    int idx = (q.y - u_stripe.x) * u_size.x + q.x;
    uint lk = texelFetch(u_lkeys, idx).x;
    if (lk == 0u) discard;
    uint k = texelFetch(u_keys, idx).x;
    if (k != 0u && uintBitsToFloat(~k) < uintBitsToFloat(~lk)) discard;
    vec3 c = texelFetch(u_layer, q, 0).rgb;
    o_color = vec4(c * u_lambda, u_lambda);
}
