#version 430
#include "lib_bindings.glsl"
// splat_raster.comp — EWA surface splatting, passes 1 (visibility) and 2 (attributes), as a
// compute rasteriser (Schütz et al. 2021) instead of point sprites, which are 10-40x slower on
// llvmpipe. pipe_splat.c compiles this file four times, inserting after the #version line:
//   #define PASS 1      visibility: the nearest ray-disc depth per pixel (atomicMax of ~bits)
//   #define PASS 2      attributes: w*colour, w*normal, w for fragments within eps of it
//   #define MODE 0      one invocation per visible point: splats that deposit (see below) are
//                       done here; in pass 1 the others are appended to the raster list. This
//                       pass holds no pixel loops: llvmpipe runs both sides of a divergent branch
//                       under a mask, so loop code in it slowed every point down (25 %).
//   #define MODE 1      one invocation per listed raster splat, looping over the pixels of its
//                       bounding box; in pass 1 boxes over u_big pixels go to the big list.
//   #define MODE 2      one 8x8 work group per listed big splat, walking its box in 8x8 tiles
//                       (so a close-up does not serialise on one lane of a SIMD group).
//                       Pass 2 replays the lists pass 1 built.
//   #define FLOAT_ATOMICS 1 (with GL_NV_shader_atomic_float) or 0: fixed-point uint atomics.
//
// Footprint (Zwicker et al. 2001, "Surface splatting"; the slides' resampling filter): the splat
// is a disc (centre c, unit normal n, radius r = radius * splat_scale) carrying a Gaussian with
// standard deviation sigma = r / 2 (the disc's rim is the 2-sigma contour). J = d(pixel)/d(u,v)
// is the Jacobian of the projection at c along an orthonormal tangent basis (u, v) of the disc,
// V_k = sigma^2 J J^T the warped reconstruction kernel. The resampling filter is
// V = V_k + lowpass * I. With ewa=exact pipe_splat.c sets u_pre = lowpass and u_subpx = 0: that
// filter per splat, every splat sampled. With ewa=split it splits the low-pass into u_pre =
// lowpass / 4 (added here) and the rest, which splat_resolve.frag applies as a depth-aware 3x3
// Gaussian over the accumulated sums (convolution is linear, so filtering the sums equals
// widening every footprint). Splats whose
// kernel V_k is small (2 sigma < u_subpx = 2 px along x and y) and lowpass > 0 deposit
// their whole weight in the pixel holding their centre (area sampling: a box filter of one
// pixel, so minified splats never vanish and cost one fragment); the others are sampled at pixel
// centres: w = exp(-x^T Q x / 2) with Q = V^-1 and x^T Q x <= CUT^2 (CUT = 2, so with lowpass 0
// the footprint is exactly the disc). Depth per fragment is the eye-space depth of the
// ray-disc-plane intersection, clamped to c's depth +- r (the disc lies inside that slab; the
// clamp catches rays that miss the plane in the fringe or hit it near edge-on); a deposited
// splat uses its centre's depth. Footprints and depths are `precise`: pass 2 is a separate
// compilation and must classify (small, big, deposited) and place every splat exactly as pass 1
// did, or a splat would be accumulated twice or not at all.

#if MODE == 2
layout(local_size_x = 8, local_size_y = 8) in;
#else
layout(local_size_x = 64) in;
#endif

#if FLOAT_ATOMICS
#define ACC float
#define ACCI float
#else
#define ACC uint
#define ACCI int
#endif

#define CUT2 4.0

// The cloud's buffers, read as buffer textures: texelFetch gathers all lanes at once on
// llvmpipe, where storage-buffer reads at varying addresses run lane by lane.
layout(binding = T_POS) uniform samplerBuffer u_pos;   // R32F: x y z per point (lib_fetch.glsl)
layout(binding = T_NRM) uniform samplerBuffer u_nrm;   // R32F: nx ny nz per point
layout(binding = T_RAD) uniform samplerBuffer u_rad;   // R32F
layout(binding = T_SRC) uniform usamplerBuffer u_src;  // R32UI: rgba8 (u_color 0) or float bits of field/intensity
#include "lib_fetch.glsl"


// One pixel of the stripe: accumulated attributes (32 bytes, one cache-line half), and apart
// from them, in a compact array that pass 1's many reads keep in cache, the visibility key:
// ~floatBitsToUint(depth). Positive floats order like their bits, so the nearest depth has the
// largest key and 0 means empty: a zero fill (glClearBufferData, each frame) clears both.
struct Px { ACC r, g, b, w; ACCI nx, ny, nz; uint pad; };
layout(std430, binding = B_SPLAT_SUMS) restrict buffer Frame { Px px[]; };
layout(std430, binding = B_SPLAT_KEYS) restrict buffer Keys { uint keys[]; };
// The same keys as a buffer texture for the reads, a gather on llvmpipe (storage-buffer reads
// go lane by lane): pass 2 only reads them; pass 1 tests against them before its atomicMax, and
// keys only grow during the pass, so a stale read costs a needless atomic, never a lost one.
// ~5 % of a close-up frame.
layout(binding = T_SPLAT_KEYS) uniform usamplerBuffer u_keys;  // R32UI

// The raster and big lists: dispatch arguments for their passes (groups[0] = min(work groups,
// 65535)), the count and the point indices.
layout(std430, binding = B_SPLAT_BIG) restrict buffer Big { uint big_groups[3]; uint big_count; uint big_list[]; };
layout(std430, binding = B_SPLAT_RAS) restrict buffer Ras { uint ras_groups[3]; uint ras_count; uint ras_list[]; };

// Pass 1: the bounding box (x0, y0, x1, y1 inclusive, frame pixels) of every pixel any splat
// touches in this stripe, reset to (big, big, -1, -1) per stripe; the resolve draws only it.
layout(std430, binding = B_SPLAT_RECT) restrict buffer Rect { ivec4 rect; };

// Visible ranges after culling: (first point, first visible index) per range, RG32UI
// (lib_ranges.glsl).
layout(binding = T_RANGES) uniform usamplerBuffer u_ranges;
#include "lib_ranges.glsl"

uniform mat4 u_view;      // local -> eye
uniform mat4 u_proj;      // eye -> clip
uniform vec4 u_rayo;      // eye ray origin at pixel (sx, sy): (x*sx + y, z*sy + w, 0)
uniform vec4 u_rayd;      // eye ray direction:               (x*sx + y, z*sy + w, -1)
uniform ivec2 u_size;     // frame width, height in pixels
uniform ivec2 u_stripe;   // first row and row count of this stripe (the accumulation buffer)
uniform float u_scale;    // splat_scale
uniform float u_pre;      // part of the low-pass variance added to each footprint (px^2)
uniform float u_subpx;    // 2-sigma size (px) below which a splat is deposited; 0: never
uniform float u_eps;      // depth tolerance of pass 2, in units of the splat's radius
uniform float u_znear;
uniform uint u_total;     // visible points
uniform uint u_nranges;
uniform uint u_big;       // bounding boxes above this many pixels go to the big list
uniform int u_color;      // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity

// The uniforms, read once at the top of main() into a local U that every function takes as its
// first parameter: llvmpipe reloads a uniform at each use inside a loop, and global copies are
// reloaded the same way; only locals stay in registers (measured on 1M points: the projection
// alone cost 6x its arithmetic, and both passes ran ~1.6x slower).
struct Uni {
    mat4 view, proj;
    vec4 rayo, rayd;
    ivec2 size, stripe;
    float scale, pre, subpx, eps, znear;
    uint total, nranges, big;
    int color;
};

Uni load_uniforms()
{
    return Uni(u_view, u_proj, u_rayo, u_rayd, u_size, u_stripe, u_scale, u_pre, u_subpx, u_eps,
               u_znear, u_total, u_nranges, u_big, u_color);
}

struct Splat {
    vec2 ctr;       // centre, pixels
    vec3 conic;     // Q = [x y; y z]
    vec2 ext;       // half extent of the cut-off ellipse's bounding box, pixels
    vec3 num, den;  // depth(sx, sy) = dot(num, (1, sx, sy)) / dot(den, (1, sx, sy))
    float dc, r;    // centre depth, radius
    vec3 n;         // eye-space normal, facing the viewer
    ivec4 box;      // x0, y0, x1, y1 inclusive, clipped to the stripe
    bool dep;       // deposited: one fragment at box.xy with weight 1 and depth dc
    vec3 k;         // covariance V_k + U.pre I: xx, xy, yy (px^2)
    float nc;       // n . c
};

// Splat i's centre, normal, covariance and whether it is deposited (then box.xy is its pixel);
// false when it is behind the near plane, degenerate, or deposited off the stripe.
bool setup_core(Uni U, uint i, out Splat s)
{
    vec3 p = fetch3(u_pos, i);
    precise vec3 c = (U.view * vec4(p, 1.0)).xyz;
    s.dc = -c.z;
    if (!(s.dc > U.znear)) return false;
    vec3 n = mat3(U.view) * fetch3(u_nrm, i);
    float nl = dot(n, n);
    n = nl > 0.0 ? n * inversesqrt(nl) : vec3(0.0, 0.0, 1.0);
    // The eye ray towards c (perspective: from the origin; orthographic: along -z).
    vec3 toc = U.proj[3][3] == 0.0 ? c : vec3(0.0, 0.0, -1.0);
    if (dot(n, toc) > 0.0) n = -n;
    s.n = n;
    s.nc = dot(n, c);
    s.r = texelFetch(u_rad, int(i)).x * U.scale;
    float sigma = 0.5 * s.r;
    // Orthonormal tangent basis (Duff et al. 2017); the footprint does not depend on its
    // rotation because the disc's Gaussian is isotropic.
    float sg = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sg + n.z);
    float b = n.x * n.y * a;
    vec3 tu = vec3(1.0 + sg * n.x * n.x * a, sg * b, -sg * n.x);
    vec3 tv = vec3(b, sg + n.y * n.y * a, -n.y);
    // Jacobian of pixel coordinates with respect to the eye position at c.
    vec4 clip = U.proj * vec4(c, 1.0);
    float iw = 1.0 / clip.w;
    vec3 rx = vec3(U.proj[0][0], U.proj[1][0], U.proj[2][0]);
    vec3 ry = vec3(U.proj[0][1], U.proj[1][1], U.proj[2][1]);
    vec3 rw = vec3(U.proj[0][3], U.proj[1][3], U.proj[2][3]);
    vec2 half_size = 0.5 * vec2(U.size);
    vec3 gx = (rx - (clip.x * iw) * rw) * (iw * half_size.x);
    vec3 gy = (ry - (clip.y * iw) * rw) * (iw * half_size.y);
    vec2 ju = vec2(dot(gx, tu), dot(gy, tu)) * sigma;
    vec2 jv = vec2(dot(gx, tv), dot(gy, tv)) * sigma;
    precise float kxx = ju.x * ju.x + jv.x * jv.x;
    precise float kxy = ju.x * ju.y + jv.x * jv.y;
    precise float kyy = ju.y * ju.y + jv.y * jv.y;
    precise vec2 ctr = (clip.xy * iw * 0.5 + 0.5) * vec2(U.size);
    s.ctr = ctr;
    s.dep = 4.0 * max(kxx, kyy) < U.subpx * U.subpx;
    s.k = vec3(kxx + U.pre, kxy, kyy + U.pre);
    if (s.dep) {
        vec2 f = floor(ctr);
        if (!(f.x >= 0.0 && f.x < float(U.size.x) && f.y >= float(U.stripe.x) &&
              f.y < float(U.stripe.x + U.stripe.y))) return false;
        s.box = ivec4(f, f);
    }
    return true;
}

// The rest of a sampled (not deposited) splat's footprint after setup_core: conic, bounding box
// and depth plane; false when degenerate or off the stripe.
bool setup_raster(Uni U, inout Splat s)
{
    precise float kxx = s.k.x, kxy = s.k.y, kyy = s.k.z;
    float det = kxx * kyy - kxy * kxy;
    if (!(det > 1e-12)) return false;
    s.conic = vec3(kyy, -kxy, kxx) / det;
    precise vec2 ext = 2.0 * sqrt(vec2(kxx, kyy)); // CUT * standard deviation along x and y
    s.ext = ext;
    // Pixel centres k + 0.5 within [ctr - ext, ctr + ext].
    precise vec2 lo = ceil(s.ctr - ext - 0.5), hi = floor(s.ctr + ext - 0.5);
    if (!(lo.x < 1e9 && hi.x > -1e9 && lo.y < 1e9 && hi.y > -1e9)) return false;
    s.box = ivec4(max(lo.x, 0.0), max(lo.y, float(U.stripe.x)),
                  min(hi.x, float(U.size.x - 1)), min(hi.y, float(U.stripe.x + U.stripe.y - 1)));
    if (s.box.x > s.box.z || s.box.y > s.box.w) return false;
    // Ray-plane depth: t = n.(c - o) / n.d with o, d affine in the pixel position; depth = t.
    vec3 n = s.n;
    s.num = vec3(s.nc - n.x * U.rayo.y - n.y * U.rayo.w, -n.x * U.rayo.x, -n.y * U.rayo.z);
    s.den = vec3(n.x * U.rayd.y + n.y * U.rayd.w - n.z, n.x * U.rayd.x, n.y * U.rayd.z);
    return true;
}

// Depth of splat s along the ray through pixel centre (sx, sy).
float frag_depth(Uni U, Splat s, float sx, float sy)
{
    precise float den = s.den.x + s.den.y * sx + s.den.z * sy;
    precise float d = abs(den) > 1e-30 ? (s.num.x + s.num.y * sx + s.num.z * sy) / den : s.dc;
    float lo = max(s.dc - s.r, 0.5 * U.znear), hi = s.dc + s.r;
    return d >= lo ? (d <= hi ? d : hi) : lo; // NaN -> lo
}

#if PASS == 2
// The splat's base colour (RGB in [0,1], the points pipeline's rules): rgba8, the field and the
// scan index through viridis, intensity as grey; normal and depth colours are made by the resolve.
#include "lib_colormap.glsl"

vec3 base_colour(Uni U, uint i)
{
    if (U.color == 0) return unpackUnorm4x8(texelFetch(u_src, int(i)).x).rgb;
    if (U.color == 1 || U.color == 5) return colormap(uintBitsToFloat(texelFetch(u_src, int(i)).x));
    if (U.color == 4) return vec3(clamp(uintBitsToFloat(texelFetch(u_src, int(i)).x), 0.0, 1.0));
    return vec3(1.0);
}
#endif

// One fragment at pixel (x, y) with depth z, weight w, colour col, normal n: pass 1 keeps the
// nearest depth, pass 2 accumulates when z lies within eps * r of it.
void put(Uni U, int x, int y, float z, float w, vec3 col, vec3 n, float r)
{
    uint idx = uint(y - U.stripe.x) * uint(U.size.x) + uint(x);
#if PASS == 1
    uint key = ~floatBitsToUint(z);
    if (key > texelFetch(u_keys, int(idx)).x) atomicMax(keys[idx], key);
#else
    float zv = uintBitsToFloat(~texelFetch(u_keys, int(idx)).x);
    if (z > zv + U.eps * r) return;
#if FLOAT_ATOMICS
    atomicAdd(px[idx].r, w * col.r);
    atomicAdd(px[idx].g, w * col.g);
    atomicAdd(px[idx].b, w * col.b);
    atomicAdd(px[idx].w, w);
    atomicAdd(px[idx].nx, w * n.x);
    atomicAdd(px[idx].ny, w * n.y);
    atomicAdd(px[idx].nz, w * n.z);
#else
    // Fixed point: w in 1/255 (>= 34 since w >= exp(-2)), colour in 1/255, normal in 1/511;
    // a pixel overflows only past 66000 (colour) or 16000 (normal) fragments. A constant
    // colour still normalises exactly: sum(wq * c) / sum(wq) = c.
    uint wq = uint(w * 255.0 + 0.5);
    uvec3 cq = uvec3(col * 255.0 + 0.5);
    ivec3 nq = ivec3(round(n * 511.0));
    atomicAdd(px[idx].r, wq * cq.r);
    atomicAdd(px[idx].g, wq * cq.g);
    atomicAdd(px[idx].b, wq * cq.b);
    atomicAdd(px[idx].w, wq);
    atomicAdd(px[idx].nx, int(wq) * nq.x);
    atomicAdd(px[idx].ny, int(wq) * nq.y);
    atomicAdd(px[idx].nz, int(wq) * nq.z);
#endif
#endif
}

// A sampled (not deposited) fragment of splat s at pixel (x, y), if inside the cut-off.
void frag(Uni U, Splat s, int x, int y, vec3 col)
{
    float sx = float(x) + 0.5, sy = float(y) + 0.5;
    vec2 d = vec2(sx, sy) - s.ctr;
    precise float q = s.conic.x * d.x * d.x + 2.0 * s.conic.y * d.x * d.y + s.conic.z * d.y * d.y;
    if (q > CUT2) return;
    precise float z = frag_depth(U, s, sx, sy);
    put(U, x, y, z, exp(-0.5 * q), col, s.n, s.r);
}

#if PASS == 1
// Merges an invocation's box bb into the stripe's rect: an atomic only where it grows the rect
// (a stale read costs one needless atomic, never a wrong rect).
void grow_rect(ivec4 bb)
{
    if (bb.x > bb.z) return;
    if (bb.x < rect.x) atomicMin(rect.x, bb.x);
    if (bb.y < rect.y) atomicMin(rect.y, bb.y);
    if (bb.z > rect.z) atomicMax(rect.z, bb.z);
    if (bb.w > rect.w) atomicMax(rect.w, bb.w);
}
#define BOX_INIT ivec4 bb = ivec4(0x7fffffff, 0x7fffffff, -1, -1)
#define BOX_ADD(b) bb = ivec4(min(bb.xy, (b).xy), max(bb.zw, (b).zw))
#define BOX_DONE grow_rect(bb)
#else
#define BOX_INIT
#define BOX_ADD(b)
#define BOX_DONE
#endif

#if PASS == 2
#define COLOUR(i) base_colour(U, i)
#else
#define COLOUR(i) vec3(0.0)
#endif

#ifdef SOFT_FILTER
// The `soft` and `olt` pipelines' splat programs (splat__create_filtered) draw part of the
// points, chosen by F (float bits on T_SOFT_F, soft_field.c) against u_st and u_smode
// (splat_passes.h SPLAT_*): 0 skips soft points (F > u_st), 1 skips solid ones, 2 skips the
// soft points of the first soft layer: those whose centre depth lies within the pass-2 depth
// tolerance of the nearest soft depth at their centre pixel (the keys of an earlier soft-only
// pass, T_OLT_KEYS, same layout as the stripe's keys). The test is made at the start of both
// passes (the raster and big lists are made of points that passed). Mode 3 skips nothing: the
// visible ranges index the list of solid points on T_SOFT_SOLID, which gives the point. The
// `splat` pipeline's own programs do not have this.
layout(binding = T_SOFT_F) uniform usamplerBuffer u_sf;
layout(binding = T_SOFT_SOLID) uniform usamplerBuffer u_solid;
layout(binding = T_OLT_KEYS) uniform usamplerBuffer u_oltkeys;
uniform int u_smode;
uniform float u_st;
bool is_soft(uint i)
{
    return uintBitsToFloat(texelFetch(u_sf, int(i)).x) > u_st;
}
bool skip_point(uint i)
{
    return u_smode == 0 ? is_soft(i) : u_smode == 1 ? !is_soft(i) : false;
}
bool peeled(Uni U, uint i, Splat s)
{
    if (u_smode != 2 || !is_soft(i)) return false;
    vec2 f = floor(s.ctr);
    if (!(f.x >= 0.0 && f.x < float(U.size.x) && f.y >= float(U.stripe.x) &&
          f.y < float(U.stripe.x + U.stripe.y))) return false;
    uint key = texelFetch(u_oltkeys, int((uint(f.y) - uint(U.stripe.x)) * uint(U.size.x) + uint(f.x))).x;
    return key != 0u && s.dc <= uintBitsToFloat(~key) + U.eps * s.r;
}
#endif

void main()
{
    Uni U = load_uniforms();
#if MODE == 0
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    BOX_INIT;
    uint first = texelFetch(u_ranges, 0).x; // read once, as the uniforms
    for (uint g = gl_GlobalInvocationID.x; g < U.total; g += stride) {
        uint i = U.nranges == 1u ? first + g : point_of(u_ranges, U.nranges, g);
#ifdef SOFT_FILTER
        if (u_smode == 3) i = texelFetch(u_solid, int(i)).x;
        else if (skip_point(i)) continue;
#endif
        Splat s;
        if (!setup_core(U, i, s)) continue;
#ifdef SOFT_FILTER
        if (peeled(U, i, s)) continue;
#endif
        if (s.dep) {
            BOX_ADD(s.box);
            put(U, s.box.x, s.box.y, s.dc, 1.0, COLOUR(i), s.n, s.r);
            continue;
        }
#if PASS == 1
        uint k = atomicAdd(ras_count, 1u);
        ras_list[k] = i;
        atomicMax(ras_groups[0], min(k / gl_WorkGroupSize.x + 1u, 65535u));
#endif
    }
    BOX_DONE;
#elif MODE == 1
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    BOX_INIT;
    uint count = ras_count; // read once, as the uniforms
    for (uint j = gl_GlobalInvocationID.x; j < count; j += stride) {
        uint i = ras_list[j];
        Splat s;
        if (!setup_core(U, i, s) || !setup_raster(U, s)) continue;
        BOX_ADD(s.box);
        uint area = uint(s.box.z - s.box.x + 1) * uint(s.box.w - s.box.y + 1);
        if (area > U.big) {
#if PASS == 1
            uint k = atomicAdd(big_count, 1u);
            big_list[k] = i;
            atomicMax(big_groups[0], min(k + 1u, 65535u));
#endif
            continue;
        }
        vec3 col = COLOUR(i);
        for (int y = s.box.y; y <= s.box.w; y++)
            for (int x = s.box.x; x <= s.box.z; x++)
                frag(U, s, x, y, col);
    }
    BOX_DONE;
#else
    // One work group per big splat; each invocation takes one pixel of every 8x8 tile.
    uint count = big_count; // read once, as the uniforms
    for (uint j = gl_WorkGroupID.x; j < count; j += gl_NumWorkGroups.x) {
        uint i = big_list[j];
        Splat s;
        if (!setup_core(U, i, s) || !setup_raster(U, s)) continue;
        vec3 col = COLOUR(i);
        for (int y = s.box.y + int(gl_LocalInvocationID.y); y <= s.box.w; y += 8)
            for (int x = s.box.x + int(gl_LocalInvocationID.x); x <= s.box.z; x += 8)
                frag(U, s, x, y, col);
    }
#endif
}
