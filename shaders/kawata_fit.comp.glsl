#version 430
// kawata_fit.comp — passes 3 and 4 of the `kawata` pipeline (pipe_kawata.c), compute passes over
// the list of the image buffer's covered pixels that pass 2 made (kawata_raster.comp: each
// buffer pixel with a nearest point, once), so that empty buffer pixels cost nothing: llvmpipe
// runs every instruction of a fragment or an invocation for all its SIMD lanes, masked, so the
// earlier fragment passes over the cloud's whole rectangle paid as much for an empty pixel as
// for a covered one (the 1M scan: 65k covered of 213k). Invocations take list entries u_threads
// apart (adjacent invocations read adjacent entries, 8 SIMD lanes at once on llvmpipe), many a
// work group, since llvmpipe pays per invocation. Every read goes through a buffer texture:
// texelFetch from one gathers all SIMD lanes at once on llvmpipe, where a 2-D texelFetch costs
// several times as much and storage-buffer reads run lane by lane. pipe_kawata.c inserts
// "#define STAGE 1|2".
//   STAGE 1: the nearest point of each listed buffer pixel (near[b]) and the farthest within
//           gamma (far[b]'s index bits), when they belong to this buffer set, to eye space
//           (w = 1) with their colours: pts[4b] = P1, pts[4b + 1] = P2, pts[4b + 2] = colour of
//           P1, pts[4b + 3] = colour of P2; (0, 0, 0, 0) marks "no point". u_all 1 (a cloud in
//           one set): every entry of the pixel written; else per set only its own points (the
//           rows were cleared first).
//   STAGE 2: the average of the two (Omega_a, pass 3), the least-squares plane z = Ax + By + C
//           in eye space over the points of the 3x3 neighbourhood in both buffers that lie
//           within the depth tolerance of the nearest point (eq. 4-5, pass 4; coordinates
//           centred on Omega_a for conditioning, Cramer's rule), normal (A, B, -1) turned
//           towards the eye, Lambert shading, and the splat for pass 5: splats[2b] = (frame x,
//           frame y, eye depth, 1), splats[2b + 1] = (colour, 1). The splats of the rectangle's
//           rows were cleared to 0 ("none"), so a pixel with fewer than u_min_support supporters
//           writes nothing. A neighbour is empty where near[] says so (its pts entries are an
//           earlier frame's). Counts the splats in nsplats. The determinants are written out:
//           the GLSL specification leaves determinant()'s precision undefined, where products
//           and sums are correctly rounded (fused or not, which is the compiler's choice here:
//           nothing else must repeat these values).

layout(local_size_x = 64) in;

#include "lib_bindings.glsl"

uniform ivec2 u_bsize;
uniform ivec2 u_blo, u_bhi; // the buffer pixels [u_blo, u_bhi) this frame uses (the cloud's
                            // screen rectangle); the others hold an earlier frame's data
uniform mat4 u_view;        // local -> eye
uniform int u_color;        // 0 rgb, 1 field, 2 normal, 3 depth, 4 intensity
uniform uint u_threads;     // invocations in the dispatch
uniform uint u_per;         // STAGE 0: rectangle pixels an invocation
layout(binding = T_KAWATA_LIST) uniform usamplerBuffer u_list;   // covered pixels: x | y << 16
layout(binding = T_KAWATA_NEAR) uniform usamplerBuffer u_near;
layout(std430, binding = B_KAWATA_COUNT) restrict buffer Count { uint nsplats, nlist; };

#if STAGE == 0
layout(std430, binding = B_KAWATA_LIST) restrict writeonly buffer List { uint list[]; };
#elif STAGE == 1
layout(binding = T_POS) uniform samplerBuffer u_pos;
layout(binding = T_SRC) uniform usamplerBuffer u_src;
layout(binding = T_KAWATA_FAR) uniform usamplerBuffer u_far;
layout(std430, binding = B_KAWATA_PTS) writeonly restrict buffer Pts { vec4 pts[]; };
#include "lib_fetch.glsl"
#include "lib_colormap.glsl"
uniform uint u_base, u_count, u_index_bits;
uniform int u_all;

// Writes point i (cloud-wide) at entries e (position) and e + 2 (colour) when it is a point of
// this set; else, when all, "no point".
void put(uint i, int e, bool all)
{
    uint l = i - u_base; // wraps for points of earlier sets
    if (i == 0xFFFFFFFFu || l >= u_count) {
        if (all) pts[e] = vec4(0.0), pts[e + 2] = vec4(0.0);
        return;
    }
    pts[e] = vec4((u_view * vec4(fetch3(u_pos, l), 1.0)).xyz, 1.0);
    uint v = texelFetch(u_src, int(l)).x;
    int color = u_color;
    vec3 c = color == 1 || color == 5 ? colormap(uintBitsToFloat(v))
             : color == 4 ? vec3(clamp(uintBitsToFloat(v), 0.0, 1.0))
                          : unpackUnorm4x8(v).rgb;
    pts[e + 2] = vec4(c, 1.0);
}

void pixel(int b, bool all)
{
    uint k = texelFetch(u_far, b).x;
    put(texelFetch(u_near, b).x, 4 * b, all);
    put(k == 0u ? 0xFFFFFFFFu : k & ((1u << u_index_bits) - 1u), 4 * b + 1, all);
}
#else
layout(binding = T_KAWATA_PTS) uniform samplerBuffer u_pts;
layout(std430, binding = B_KAWATA_SPLATS) writeonly restrict buffer Splats { vec4 splats[]; };
layout(std430, binding = B_KAWATA_TILES) writeonly restrict buffer Tiles { uint tiles[]; };
uniform mat4 u_proj;
uniform ivec2 u_fsize;
uniform float u_gamma;   // depth tolerance: u_gamma + u_slope * depth
uniform float u_slope;
uniform int u_min_support;
uniform vec3 u_light;    // unit, eye space
uniform float u_znear, u_zfar;

// The normal-equation sums of the plane fit, the number of supporting points, and the plane
// of the first round (g: A, B, C; g.w: the residual bound of the second round, 0 in the first).
struct Fit {
    float sxx, sxy, syy, sx, sy, n, sxz, syz, sz, szz;
    int support;
    vec4 g;
};

void add_point(vec4 t, vec3 pa, float z0, float tol, bool self, inout Fit f)
{
    if (t.w == 0.0 || abs(t.z - z0) > tol) return;
    vec3 e = t.xyz - pa;
    float r = e.z - (f.g.x * e.x + f.g.y * e.y + f.g.z);
    if (f.g.w > 0.0 && abs(r) > f.g.w) return;
    if (!self) f.support++;
    f.sxx += e.x * e.x, f.sxy += e.x * e.y, f.syy += e.y * e.y;
    f.sx += e.x, f.sy += e.y, f.n += 1.0;
    f.sxz += e.x * e.z, f.syz += e.y * e.z, f.sz += e.z, f.szz += e.z * e.z;
}

// Point j (0: nearest, 1: farthest) of neighbour q + (dx, dy); "no point" outside this
// frame's rectangle or where the neighbour has none.
vec4 point_at(ivec2 q, int dx, int dy, int j, ivec2 blo, ivec2 bhi, int w)
{
    ivec2 r = q + ivec2(dx, dy);
    if (r.x < blo.x || r.y < blo.y || r.x >= bhi.x || r.y >= bhi.y) return vec4(0.0);
    int b = r.y * w + r.x;
    if (texelFetch(u_near, b).x == 0xFFFFFFFFu) return vec4(0.0);
    return texelFetch(u_pts, 4 * b + j);
}

// The determinant of the 3x3 matrix of columns a, b, c, expanded along the first row.
float det3(vec3 a, vec3 b, vec3 c)
{
    return a.x * (b.y * c.z - c.y * b.z) - b.x * (a.y * c.z - c.y * a.z) +
           c.x * (a.y * b.z - b.y * a.z);
}

// Solves the round's normal equations by Cramer's rule on [sxx sxy sx; sxy syy sy; sx sy n]
// (A B C)^T = (sxz syz sz)^T (mat3 takes columns; the matrix is symmetric). Returns false
// when they are singular (fewer than 3 points, or all on a line).
bool solve(Fit f, out vec3 abc)
{
    abc = vec3(0.0);
    vec3 cx = vec3(f.sxx, f.sxy, f.sx), cy = vec3(f.sxy, f.syy, f.sy), cn = vec3(f.sx, f.sy, f.n);
    vec3 cz = vec3(f.sxz, f.syz, f.sz);
    float det = det3(cx, cy, cn);
    float lim = 1e-6 * f.sxx * f.syy * f.n;
    if (!(abs(det) > lim)) return false;
    float ax = det3(cz, cy, cn) / det, ay = det3(cx, cz, cn) / det;
    float az = det3(cx, cy, cz) / det;
    abc = vec3(ax, ay, az);
    return true;
}

void pixel(ivec2 q, ivec2 blo, ivec2 bhi, int w)
{
    int b = q.y * w + q.x;
    vec4 a1 = texelFetch(u_pts, 4 * b);
    if (a1.w == 0.0) return;
    vec4 a2 = texelFetch(u_pts, 4 * b + 1);
    vec3 pa = a2.w > 0.0 ? 0.5 * (a1.xyz + a2.xyz) : a1.xyz; // pass 3
    float tol = u_gamma + u_slope * (-a1.z);
    // The up to 18 points of the 3x3 neighbourhood in both buffers, fetched once for both
    // rounds and named (llvmpipe keeps named values in registers; arrays and loops measured
    // ~10x slower in splat_resolve.frag.glsl).
    vec4 v00 = point_at(q, -1, -1, 0, blo, bhi, w);
    vec4 v01 = point_at(q, -1, -1, 1, blo, bhi, w);
    vec4 v10 = point_at(q, 0, -1, 0, blo, bhi, w);
    vec4 v11 = point_at(q, 0, -1, 1, blo, bhi, w);
    vec4 v20 = point_at(q, 1, -1, 0, blo, bhi, w);
    vec4 v21 = point_at(q, 1, -1, 1, blo, bhi, w);
    vec4 v30 = point_at(q, -1, 0, 0, blo, bhi, w);
    vec4 v31 = point_at(q, -1, 0, 1, blo, bhi, w);
    vec4 v40 = point_at(q, 0, 0, 0, blo, bhi, w);
    vec4 v41 = point_at(q, 0, 0, 1, blo, bhi, w);
    vec4 v50 = point_at(q, 1, 0, 0, blo, bhi, w);
    vec4 v51 = point_at(q, 1, 0, 1, blo, bhi, w);
    vec4 v60 = point_at(q, -1, 1, 0, blo, bhi, w);
    vec4 v61 = point_at(q, -1, 1, 1, blo, bhi, w);
    vec4 v70 = point_at(q, 0, 1, 0, blo, bhi, w);
    vec4 v71 = point_at(q, 0, 1, 1, blo, bhi, w);
    vec4 v80 = point_at(q, 1, 1, 0, blo, bhi, w);
    vec4 v81 = point_at(q, 1, 1, 1, blo, bhi, w);
    Fit f;
    f.g = vec4(0.0);
    f.sxx = f.sxy = f.syy = f.sx = f.sy = f.n = f.sxz = f.syz = f.sz = f.szz = 0.0;
    f.support = 0;
    add_point(v00, pa, a1.z, tol, false, f);
    add_point(v01, pa, a1.z, tol, false, f);
    add_point(v10, pa, a1.z, tol, false, f);
    add_point(v11, pa, a1.z, tol, false, f);
    add_point(v20, pa, a1.z, tol, false, f);
    add_point(v21, pa, a1.z, tol, false, f);
    add_point(v30, pa, a1.z, tol, false, f);
    add_point(v31, pa, a1.z, tol, false, f);
    add_point(v40, pa, a1.z, tol, true, f);
    add_point(v41, pa, a1.z, tol, false, f);
    add_point(v50, pa, a1.z, tol, false, f);
    add_point(v51, pa, a1.z, tol, false, f);
    add_point(v60, pa, a1.z, tol, false, f);
    add_point(v61, pa, a1.z, tol, false, f);
    add_point(v70, pa, a1.z, tol, false, f);
    add_point(v71, pa, a1.z, tol, false, f);
    add_point(v80, pa, a1.z, tol, false, f);
    add_point(v81, pa, a1.z, tol, false, f);
    if (f.support < u_min_support) return;
    vec3 nrm = vec3(0.0, 0.0, 1.0);
    vec3 abc;
    if (solve(f, abc)) {
        // A second round without the points farther from the first plane than 2.5 times the
        // residuals' RMS (at least a quarter of a buffer pixel, so exact planes lose nothing to
        // rounding): gamma is a fraction of the whole cloud's size, so in a large scene stray
        // points well off a surface still lie within it, and one of them tilts a fit of 18
        // points enough to darken its pixel. When the nearest point itself is such a stray,
        // the pixel is dropped (pass 5 fills it from its neighbours), as the paper drops
        // outliers. The residual sum of squares from the sums: sum (z - Ax - By - C)^2.
        float rss = f.szz - 2.0 * (abc.x * f.sxz + abc.y * f.syz + abc.z * f.sz) +
                    abc.x * abc.x * f.sxx + 2.0 * abc.x * abc.y * f.sxy +
                    abc.y * abc.y * f.syy + 2.0 * abc.x * abc.z * f.sx +
                    2.0 * abc.y * abc.z * f.sy + abc.z * abc.z * f.n;
        float bound = max(2.5 * sqrt(max(rss, 0.0) / f.n), 0.0625 * u_slope * (-a1.z));
        vec3 e1 = a1.xyz - pa;
        float r1 = e1.z - (abc.x * e1.x + abc.y * e1.y + abc.z);
        if (abs(r1) > bound) return;
        f.g = vec4(abc, bound);
        f.sxx = f.sxy = f.syy = f.sx = f.sy = f.n = f.sxz = f.syz = f.sz = f.szz = 0.0;
        f.support = 0;
        add_point(v00, pa, a1.z, tol, false, f);
        add_point(v01, pa, a1.z, tol, false, f);
        add_point(v10, pa, a1.z, tol, false, f);
        add_point(v11, pa, a1.z, tol, false, f);
        add_point(v20, pa, a1.z, tol, false, f);
        add_point(v21, pa, a1.z, tol, false, f);
        add_point(v30, pa, a1.z, tol, false, f);
        add_point(v31, pa, a1.z, tol, false, f);
        add_point(v40, pa, a1.z, tol, true, f);
        add_point(v41, pa, a1.z, tol, false, f);
        add_point(v50, pa, a1.z, tol, false, f);
        add_point(v51, pa, a1.z, tol, false, f);
        add_point(v60, pa, a1.z, tol, false, f);
        add_point(v61, pa, a1.z, tol, false, f);
        add_point(v70, pa, a1.z, tol, false, f);
        add_point(v71, pa, a1.z, tol, false, f);
        add_point(v80, pa, a1.z, tol, false, f);
        add_point(v81, pa, a1.z, tol, false, f);
        if (f.support < u_min_support) return;
        if (solve(f, abc)) { // (A, B, -1) towards +z, divided by its length
            float len = sqrt(abc.x * abc.x + abc.y * abc.y + 1.0);
            nrm = vec3(-abc.x, -abc.y, 1.0) / len;
        }
    }
    vec3 c1 = texelFetch(u_pts, 4 * b + 2).rgb;
    vec3 col = a2.w > 0.0 ? 0.5 * (c1 + texelFetch(u_pts, 4 * b + 3).rgb) : c1;
    int color = u_color;
    mat4 v = u_view;
    vec3 l = u_light;
    if (color == 2) { // local normals (transpose(mat3(u_view)) * nrm), as `points`
        vec3 ln = vec3(v[0].x * nrm.x + v[0].y * nrm.y + v[0].z * nrm.z,
                               v[1].x * nrm.x + v[1].y * nrm.y + v[1].z * nrm.z,
                               v[2].x * nrm.x + v[2].y * nrm.y + v[2].z * nrm.z);
        col = ln * 0.5 + 0.5;
    } else if (color == 3) {
        float t = (-pa.z - u_znear) / (u_zfar - u_znear);
        col = vec3(1.0 - clamp(t, 0.0, 1.0));
    } else {
        float ndl = nrm.x * l.x + nrm.y * l.y + nrm.z * l.z;
        col *= 0.2 + 0.8 * max(ndl, 0.0); // ambient + Lambert
    }
    vec4 clip = u_proj * vec4(pa, 1.0);
    vec2 sxy = (clip.xy / clip.w * 0.5 + 0.5) * vec2(u_fsize);
    splats[2 * b] = vec4(sxy, -pa.z, 1.0);
    splats[2 * b + 1] = vec4(col, 1.0);
    // The 8x8 tiles of buffer pixels whose frame pixels this splat may reach (pass 5 reads
    // the 5x5 buffer pixels from floor(u) - 2, u a frame pixel's centre in buffer pixels: so
    // those of buffer pixels q - 3 .. q + 3, at most 2x2 tiles) are marked for pass 5.
    int tw = (u_bsize.x + 7) >> 3;
    ivec2 t0 = max(q - 3, ivec2(0)) >> 3, t1 = min(q + 3, u_bsize - 1) >> 3;
    tiles[t0.y * tw + t0.x] = 1u;
    tiles[t0.y * tw + t1.x] = 1u;
    tiles[t1.y * tw + t0.x] = 1u;
    tiles[t1.y * tw + t1.x] = 1u;
    atomicAdd(nsplats, 1u);
}
#endif

#if STAGE == 0
// STAGE 0: invocation g lists the covered pixels among the rectangle's pixels [g u_per, (g + 1) u_per)
// (row by row), in their order: it counts them, reserves that many entries with one atomic,
// and writes them. Neighbouring pixels stay neighbours in the list, which the later stages
// read in order (a list in the order pass 2 met the points cost ~2x as much a pixel).
void main()
{
    ivec2 blo = u_blo, bhi = u_bhi;
    int w = u_bsize.x, rw = bhi.x - blo.x;
    uint per = u_per, area = uint(rw * (bhi.y - blo.y));
    uint k0 = gl_GlobalInvocationID.x * per, k1 = min(k0 + per, area);
    ivec2 q0 = blo + ivec2(int(k0) % rw, int(k0) / rw);
    uint count = 0u;
    ivec2 q = q0;
    for (uint k = k0; k < k1; k++) {
        if (texelFetch(u_near, q.y * w + q.x).x != 0xFFFFFFFFu) count++;
        q = q.x + 1 < bhi.x ? ivec2(q.x + 1, q.y) : ivec2(blo.x, q.y + 1);
    }
    if (count == 0u) return;
    uint at = atomicAdd(nlist, count);
    q = q0;
    for (uint k = k0; k < k1; k++) {
        if (texelFetch(u_near, q.y * w + q.x).x != 0xFFFFFFFFu) list[at++] = uint(q.x) | uint(q.y) << 16;
        q = q.x + 1 < bhi.x ? ivec2(q.x + 1, q.y) : ivec2(blo.x, q.y + 1);
    }
}
#else
void main()
{
    uint n = nlist, threads = u_threads;
#if STAGE == 1
    bool all = u_all != 0;
#else
    ivec2 blo = u_blo, bhi = u_bhi;
#endif
    int w = u_bsize.x;
    for (uint k = gl_GlobalInvocationID.x; k < n; k += threads) {
        uint e = texelFetch(u_list, int(k)).x; // x | y << 16
        ivec2 q = ivec2(e & 0xFFFFu, e >> 16);
#if STAGE == 1
        pixel(q.y * w + q.x, all);
#else
        pixel(q, blo, bhi, w);
#endif
    }
}
#endif
