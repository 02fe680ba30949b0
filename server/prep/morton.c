/* morton.c — Morton codes and their radix sort; see morton.h. */
#include "morton.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

uint64_t prep_morton_encode(uint32_t x, uint32_t y, uint32_t z)
{
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

uint64_t prep_morton_code(const prep_morton_frame *f, const float p[3])
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

int prep_radix_sort64(uint64_t *codes, uint32_t *perm, size_t n, sd_err *err)
{
    size_t i = 1;
    while (i < n && codes[i - 1] <= codes[i]) i++;
    if (i >= n) return 0; /* already in Morton order (a prepared cloud): nothing to sort */
    uint64_t *tk = malloc(n * sizeof *tk);
    uint32_t *tp = malloc(n * sizeof *tp);
    size_t *hist = malloc(sizeof(size_t) << 11);
    if (!tk || !tp || !hist) {
        free(tk); free(tp); free(hist);
        return sd_errf(err, SD_ENOMEM, "out of memory sorting %zu keys", n);
    }
    /* Six passes of 11 bits cover 64-bit keys; a pass whose digit is the same for every key
     * (common for the top bits) is skipped. */
    uint64_t *src = codes, *dst = tk;
    uint32_t *psrc = perm, *pdst = tp;
    for (int shift = 0; shift < 64; shift += 11) {
        memset(hist, 0, sizeof(size_t) << 11);
        for (size_t j = 0; j < n; j++) hist[(src[j] >> shift) & 0x7ff]++;
        if (hist[(src[0] >> shift) & 0x7ff] == n) continue;
        size_t sum = 0;
        for (int d = 0; d < 2048; d++) {
            size_t c = hist[d];
            hist[d] = sum;
            sum += c;
        }
        for (size_t j = 0; j < n; j++) {
            size_t o = hist[(src[j] >> shift) & 0x7ff]++;
            dst[o] = src[j];
            pdst[o] = psrc[j];
        }
        uint64_t *t = src; src = dst; dst = t;
        uint32_t *u = psrc; psrc = pdst; pdst = u;
    }
    if (src != codes) {
        memcpy(codes, src, n * sizeof *codes);
        memcpy(perm, psrc, n * sizeof *perm);
    }
    free(tk); free(tp); free(hist);
    return 0;
}
