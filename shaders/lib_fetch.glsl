// lib_fetch.glsl — a vec3 attribute (position, normal) of point i from a buffer texture over
// the tightly packed float array, bound as R32F: three single-float texelFetch. On llvmpipe an
// RGB32F buffer texture (12-byte texels) is fetched by a slow generic path, while R32F fetches
// are plain gathers; the splat pipeline measured 15 % faster per frame (1M points, 1280x720).
// The price: 3 texels a point, so GL_MAX_TEXTURE_BUFFER_SIZE / 3 points (44M at llvmpipe's
// 2^27); the pipelines check it.
vec3 fetch3(samplerBuffer t, uint i)
{
    int k = 3 * int(i);
    return vec3(texelFetch(t, k).x, texelFetch(t, k + 1).x, texelFetch(t, k + 2).x);
}
