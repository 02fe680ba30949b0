// lib_shade.glsl — the shading factor of splat's resolve, shared through #include by the soft
// discs and spheres (the paper: Lambertian shading for all points): ambient + Lambert +
// Blinn-Phong with an infinite viewer (v = +z), weights summing to 1, for unit normal n and unit
// light direction l in eye space. A surface facing a light along the view axis gets exactly 1.
float shade(vec3 n, vec3 l)
{
    vec3 hv = l + vec3(0.0, 0.0, 1.0);
    float hl = dot(hv, hv);
    float ndl = max(dot(n, l), 0.0);
    float ndh = hl > 0.0 ? max(dot(n, hv * inversesqrt(hl)), 0.0) : 0.0;
    return 0.2 + 0.7 * ndl + 0.1 * pow(ndh, 32.0);
}
