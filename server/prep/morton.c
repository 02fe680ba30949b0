/* morton.c — Morton codes and their radix sort; see morton.h. */
#include "morton.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "simd.h"

/* Spreads the low 21 bits of v so that bit i lands on bit 3i. */
static uint64_t spread3(uint64_t v)
{
    v &= 0x1fffffu;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
}

/* The inverse of spread3: gathers bits 0, 3, 6, ... of v into the low 21 bits. */
static uint32_t compact3(uint64_t v)
{
    v &= 0x1249249249249249ull;
    v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
    v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
    v = (v ^ (v >> 8)) & 0x1f0000ff0000ffull;
    v = (v ^ (v >> 16)) & 0x1f00000000ffffull;
    v = (v ^ (v >> 32)) & 0x1fffffull;
    return (uint32_t)v;
}

#if defined(__x86_64__) && defined(__GNUC__)
/* spread3 of each coordinate by one bit deposit each (BMI2): the same bits. */
__attribute__((target("bmi2"))) static uint64_t encode_bmi2(uint32_t x, uint32_t y, uint32_t z)
{
    const uint64_t m = 0x1249249249249249ull; /* bits 0, 3, ..., 60 */
    return _pdep_u64(x, m) | _pdep_u64(y, m << 1) | _pdep_u64(z, m << 2);
}
#endif

uint64_t prep_morton_encode(uint32_t x, uint32_t y, uint32_t z)
{
#if defined(__x86_64__) && defined(__GNUC__)
    /* PDEP is fast on Intel since Haswell and on CPUs with AVX-512 (AMD before Zen 3 has
     * BMI2 with a microcoded PDEP hundreds of cycles long) */
    if (__builtin_cpu_supports("bmi2") &&
        (__builtin_cpu_is("intel") || __builtin_cpu_supports("avx512f")))
        return encode_bmi2(x, y, z);
#endif
    return spread3(x) | spread3(y) << 1 | spread3(z) << 2;
}

void prep_morton_decode(uint64_t code, uint32_t *x, uint32_t *y, uint32_t *z)
{
    *x = compact3(code);
    *y = compact3(code >> 1);
    *z = compact3(code >> 2);
}

void prep_morton_frame_of(const float *pos, size_t n, prep_morton_frame *f)
{
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            double v = pos[3 * i + a];
            if (i == 0 || v < lo[a]) lo[a] = v;
            if (i == 0 || v > hi[a]) hi[a] = v;
        }
    double side = 0;
    for (int a = 0; a < 3; a++) side = fmax(side, hi[a] - lo[a]);
    /* Enlarge a little so the highest point falls strictly inside the last cell; a cloud of
     * one position gets a unit cube. */
    double margin = side > 0 ? side * 1e-6 : 0.5;
    side += 2 * margin;
    for (int a = 0; a < 3; a++) f->origin[a] = lo[a] - margin;
    f->side = side;
    f->inv_cell = (double)(1u << PREP_MORTON_BITS) / side;
}

/* Cell index along one axis at the finest level, clamped into the grid. */
static uint32_t cell_of(const prep_morton_frame *f, int a, float v)
{
    double c = floor(((double)v - f->origin[a]) * f->inv_cell);
    if (!(c >= 0)) return 0; /* also NaN */
    if (c >= (double)((1u << PREP_MORTON_BITS) - 1)) return (1u << PREP_MORTON_BITS) - 1;
    return (uint32_t)c;
}

PREP_CLONES uint64_t prep_morton_code(const prep_morton_frame *f, const float p[3])
{
    return prep_morton_encode(cell_of(f, 0, p[0]), cell_of(f, 1, p[1]), cell_of(f, 2, p[2]));
}

int prep_morton_sort(const float *pos, size_t n, const prep_morton_frame *f, uint64_t *codes,
                     uint32_t *perm, sd_err *err)
{
    for (size_t j = 0; j < n; j++) {
        codes[j] = prep_morton_code(f, pos + 3 * j);
        perm[j] = (uint32_t)j;
    }
    return prep_radix_sort64(codes, perm, n, err);
}

/* One stable counting-sort pass of src / psrc into dst / pdst by the digit (key >> shift) & mask,
 * h its histogram (mask + 1 counts), turned into the buckets' ends. */
static void scatter_digit(const uint64_t *src, const uint32_t *psrc, uint64_t *dst,
                          uint32_t *pdst, size_t n, size_t *h, int shift, uint64_t mask)
{
    size_t sum = 0;
    for (uint64_t v = 0; v <= mask; v++) {
        size_t c = h[v];
        h[v] = sum;
        sum += c;
    }
    for (size_t j = 0; j < n; j++) {
        size_t o = h[(src[j] >> shift) & mask]++;
        dst[o] = src[j];
        pdst[o] = psrc[j];
    }
}

/* Stable LSD radix sort of the n keys k (and their perm p) on bits [0, bits), w bits a pass
 * (w <= 11, bits <= 64), with tk / tp (n entries) as the other buffer and hist (one row of
 * 1 << w counts a pass) as scratch; the result ends in k / p. The histograms are counted in one
 * read; a pass whose digit is the same for every key is skipped; up to 32 keys take an
 * insertion sort. */
static void lsd_sort(uint64_t *k, uint32_t *p, uint64_t *tk, uint32_t *tp, size_t n, int bits,
                     int w, size_t *hist)
{
    if (n < 2) return;
    if (n <= 32) { /* stable: a key moves left only past greater keys */
        for (size_t i = 1; i < n; i++) {
            uint64_t v = k[i];
            uint32_t q = p[i];
            size_t j = i;
            while (j > 0 && k[j - 1] > v) { k[j] = k[j - 1]; p[j] = p[j - 1]; j--; }
            k[j] = v;
            p[j] = q;
        }
        return;
    }
    size_t nb = (size_t)1 << w;
    uint64_t mask = nb - 1;
    int np = (bits + w - 1) / w;
    memset(hist, 0, (size_t)np * nb * sizeof *hist);
    for (size_t j = 0; j < n; j++) {
        uint64_t c = k[j];
        for (int d = 0; d < np; d++) hist[(size_t)d * nb + ((c >> (w * d)) & mask)]++;
    }
    uint64_t *src = k, *dst = tk;
    uint32_t *psrc = p, *pdst = tp;
    for (int d = 0; d < np; d++) {
        int shift = w * d;
        size_t *h = hist + (size_t)d * nb;
        if (h[(src[0] >> shift) & mask] == n) continue;
        scatter_digit(src, psrc, dst, pdst, n, h, shift, mask);
        uint64_t *t = src; src = dst; dst = t;
        uint32_t *u = psrc; psrc = pdst; pdst = u;
    }
    if (src != k) {
        memcpy(k, src, n * sizeof *k);
        memcpy(p, psrc, n * sizeof *p);
    }
}

/* Arrays of at least this many keys (3 MiB of keys and indices: past a core's L2) are split by
 * a most-significant digit first. */
enum { RADIX_MSD_MIN = 1 << 18 };

int prep_radix_sort64(uint64_t *codes, uint32_t *perm, size_t n, sd_err *err)
{
    size_t i = 1;
    while (i < n && codes[i - 1] <= codes[i]) i++;
    if (i >= n) return 0; /* already in Morton order (a prepared cloud): nothing to sort */
    uint64_t *tk = malloc(n * sizeof *tk);
    uint32_t *tp = malloc(n * sizeof *tp);
    /* small: six rows of 11-bit counts; large: the MSD's row, then eight of 8-bit counts */
    size_t *hist = malloc((n < RADIX_MSD_MIN ? (size_t)6 << 11 : (size_t)4096) * sizeof(size_t));
    if (!tk || !tp || !hist) {
        free(tk); free(tp); free(hist);
        return sd_errf(err, SD_ENOMEM, "out of memory sorting %zu keys", n);
    }
    if (n < RADIX_MSD_MIN) { /* in cache: LSD passes of 11 bits over the whole array */
        lsd_sort(codes, perm, tk, tp, n, 64, 11, hist);
        free(tk); free(tp); free(hist);
        return 0;
    }
    /* One stable counting pass on the 11 highest bits that differ among the keys (MSD) into
     * tk / tp, then each bucket sorted on the bits below by LSD passes of 8 bits, back into
     * codes / perm: buckets are small enough to stay in cache, where LSD passes over the
     * whole array would scatter it six times. Stable throughout: the same order as any
     * stable sort by key. */
    uint64_t diff = 0;
    for (size_t j = 1; j < n; j++) diff |= codes[j] ^ codes[0];
    int hb = 63 - __builtin_clzll(diff); /* diff != 0: the keys are not all in order */
    int lo = hb + 1 > 11 ? hb + 1 - 11 : 0;
    memset(hist, 0, ((size_t)1 << 11) * sizeof *hist);
    for (size_t j = 0; j < n; j++) hist[(codes[j] >> lo) & 0x7ff]++;
    scatter_digit(codes, perm, tk, tp, n, hist, lo, 0x7ff);
    memcpy(codes, tk, n * sizeof *codes); /* the bucket order, sorted below in place */
    memcpy(perm, tp, n * sizeof *perm);
    for (size_t a = 0, d = 0; d < 2048; d++) { /* hist[d] is now the end of bucket d */
        size_t b = hist[d];
        lsd_sort(codes + a, perm + a, tk + a, tp + a, b - a, lo, 8, hist + 2048);
        a = b;
    }
    free(tk); free(tp); free(hist);
    return 0;
}
