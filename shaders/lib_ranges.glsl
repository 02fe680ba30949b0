// lib_ranges.glsl — the point index of visible index k when culling left several ranges of
// points: a binary search over the ranges' first visible index. Each texel of `ranges` (RG32UI
// buffer texture) is (first point, position of that point in the sequence of visible points).
// Read through a texture, not a storage buffer: texelFetch gathers all SIMD lanes at once on
// llvmpipe, where storage-buffer reads at varying addresses go lane by lane (the close-up of
// `make bench`, 1M points culled to many ranges: `points` 58.5 -> 52.2 ms).
uint point_of(usamplerBuffer ranges, uint nranges, uint k)
{
    uint lo = 0u, hi = nranges - 1u;
    while (lo < hi) {
        uint mid = (lo + hi + 1u) >> 1;
        if (texelFetch(ranges, int(mid)).y <= k) lo = mid;
        else hi = mid - 1u;
    }
    uvec2 r = texelFetch(ranges, int(lo)).xy;
    return r.x + (k - r.y);
}
