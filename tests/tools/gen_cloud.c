/* gen_cloud — a deterministic synthetic scan-like point cloud, as binary little-endian PLY or
 * as LAS.
 *
 *   gen_cloud N out.ply|out.las [--seed S] [--vegetation F]
 *
 * Writes N points (x y z float, red green blue uchar) of a 100 m outdoor scene in metres:
 *   50 %  ground: a disc of radius 50 m with gentle undulation, sampled like a terrestrial
 *         scanner at the origin would (areal density falling as 1 / distance);
 *   20 %  four box buildings (walls and roofs), 7 % three cylinders (poles, a tank),
 *    5 %  a sphere of radius 4 m, 17 % a 'vegetation' blob: points scattered through a ball
 *         (a tree crown);
 *    1 %  noise: points scattered uniformly through the scene's box (mixed pixels, birds);
 * every surface point moved by Gaussian noise of 1 cm per axis. --vegetation F (0 to 1) makes
 * the vegetation share F instead, the other shares scaled down in proportion (the soft
 * transparency bench's "half noisy vegetation" cloud is F = 0.5). Same N and seed, same bytes:
 * the generator is splitmix64 with a fixed default seed. Only standard C; 1M points take well
 * under a second.
 *
 * An output name ending in .las (any case) gives LAS 1.2, point format 2: the same points,
 * quantised to millimetres (scale 0.001, offset 0), colours stored as 16-bit values (v * 257, so
 * readers that scale 16-bit colours down get v back), and an ASPRS class per generator:
 * 2 ground, 6 building, 1 poles and sphere, 5 vegetation, 7 noise. The header's bounds and
 * counts by return are filled in after the points, so the file is written in one pass. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rng.h"

typedef struct pt {
    float x, y, z;
    uint8_t c[3];
    uint8_t cls;   /* ASPRS class (LAS output only) */
} pt;

static const double NOISE = 0.01; /* metres, per axis */

static double ground_z(double x, double y)
{
    return 0.3 * sin(x / 7.0) * cos(y / 9.0) + 0.1 * sin(x / 2.3 + y / 3.1);
}

static void colour(pt *p, rng *r, int R, int G, int B)
{
    int v = (int)(uni(r) * 30) - 15;
    int c[3] = {R + v, G + v, B + v};
    for (int i = 0; i < 3; i++) p->c[i] = (uint8_t)(c[i] < 0 ? 0 : (c[i] > 255 ? 255 : c[i]));
}

static void jitter(pt *p, rng *r, double x, double y, double z)
{
    p->x = (float)(x + NOISE * gauss(r));
    p->y = (float)(y + NOISE * gauss(r));
    p->z = (float)(z + NOISE * gauss(r));
}

static void ground(pt *p, rng *r)
{
    double t = 6.283185307179586 * uni(r), d = 1.0 + 49.0 * uni(r);
    double x = d * cos(t), y = d * sin(t);
    jitter(p, r, x, y, ground_z(x, y));
    colour(p, r, 110, 120, 70);
    p->cls = 2;
}

static void building(pt *p, rng *r)
{
    static const double b[4][5] = { /* centre x, y, size x, y, height */
        {20, 15, 12, 8, 9}, {-25, 10, 10, 14, 14}, {10, -30, 15, 10, 6}, {-15, -25, 8, 8, 11}};
    const double *B = b[next64(r) % 4];
    double aw = B[2] * B[4], ad = B[3] * B[4], ar = B[2] * B[3];
    double u = uni(r) * (2 * aw + 2 * ad + ar), s = uni(r), t = uni(r);
    double x0 = B[0] - B[2] / 2, y0 = B[1] - B[3] / 2, x, y, z;
    if (u < 2 * aw) { x = x0 + s * B[2]; y = u < aw ? y0 : y0 + B[3]; z = t * B[4]; }
    else if (u < 2 * aw + 2 * ad) { y = y0 + s * B[3]; x = u < 2 * aw + ad ? x0 : x0 + B[2]; z = t * B[4]; }
    else { x = x0 + s * B[2]; y = y0 + t * B[3]; z = B[4]; }
    jitter(p, r, x, y, z + ground_z(B[0], B[1]));
    colour(p, r, 160, 155, 150);
    p->cls = 6;
}

static void cylinder(pt *p, rng *r)
{
    static const double c[3][4] = {{5, 5, 0.3, 8}, {-5, 30, 3, 6}, {35, -10, 0.5, 10}};
    const double *C = c[next64(r) % 3];
    double t = 6.283185307179586 * uni(r);
    jitter(p, r, C[0] + C[2] * cos(t), C[1] + C[2] * sin(t), uni(r) * C[3]);
    colour(p, r, 60, 90, 170);
    p->cls = 1;
}

static void sphere(pt *p, rng *r)
{
    double z = 2 * uni(r) - 1, t = 6.283185307179586 * uni(r), s = sqrt(1 - z * z);
    jitter(p, r, 0 + 4 * s * cos(t), 25 + 4 * s * sin(t), 6 + 4 * z);
    colour(p, r, 190, 60, 50);
    p->cls = 1;
}

static void vegetation(pt *p, rng *r)
{
    double x, y, z;
    do {
        x = 2 * uni(r) - 1; y = 2 * uni(r) - 1; z = 2 * uni(r) - 1;
    } while (x * x + y * y + z * z > 1);
    jitter(p, r, -30 + 5 * x, -5 + 5 * y, 7 + 4 * z);
    colour(p, r, 50, 130, 40);
    p->cls = 5;
}

static void noise(pt *p, rng *r)
{
    p->x = (float)(100 * uni(r) - 50);
    p->y = (float)(100 * uni(r) - 50);
    p->z = (float)(16 * uni(r) - 1);
    colour(p, r, 128, 128, 128);
    p->cls = 7;
}

/* Which generator makes point i of n: fixed shares of the scene, interleaved so any prefix of
 * the file is a thinned version of the whole scene. */
static void make_point(pt *p, rng *r, double veg)
{
    if (veg >= 0) {
        if (uni(r) < veg) {
            vegetation(p, r);
            return;
        }
        uint64_t v = next64(r) % 830; /* the other shares, without the vegetation's 170 */
        if (v < 500) ground(p, r);
        else if (v < 700) building(p, r);
        else if (v < 770) cylinder(p, r);
        else if (v < 820) sphere(p, r);
        else noise(p, r);
        return;
    }
    uint64_t u = next64(r) % 1000;
    if (u < 500) ground(p, r);
    else if (u < 700) building(p, r);
    else if (u < 770) cylinder(p, r);
    else if (u < 820) sphere(p, r);
    else if (u < 990) vegetation(p, r);
    else noise(p, r);
}

static void put_f32(uint8_t *b, float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    b[0] = (uint8_t)u; b[1] = (uint8_t)(u >> 8); b[2] = (uint8_t)(u >> 16); b[3] = (uint8_t)(u >> 24);
}

static void put_u16(uint8_t *b, unsigned v)
{
    b[0] = (uint8_t)v; b[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *b, uint32_t v)
{
    for (int k = 0; k < 4; k++) b[k] = (uint8_t)(v >> (8 * k));
}

static void put_f64(uint8_t *b, double v)
{
    uint64_t u;
    memcpy(&u, &v, 8);
    for (int k = 0; k < 8; k++) b[k] = (uint8_t)(u >> (8 * k));
}

static int ends_with_las(const char *s)
{
    size_t n = strlen(s);
    if (n < 4) return 0;
    const char *e = s + n - 4;
    return e[0] == '.' && (e[1] | 32) == 'l' && (e[2] | 32) == 'a' && (e[3] | 32) == 's';
}

enum { LAS_HDR = 227, LAS_REC = 26 };
static const double LAS_SCALE = 0.001;

/* las_header: the LAS 1.2 public header of n format-2 points with the given bounds (the
 * quantised coordinates' extremes, in metres). */
static void las_header(uint8_t *h, long long n, const double lo[3], const double hi[3],
                       uint64_t seed)
{
    memset(h, 0, LAS_HDR);
    memcpy(h, "LASF", 4);
    h[24] = 1;
    h[25] = 2;
    snprintf((char *)h + 26, 32, "gen_cloud seed %llu", (unsigned long long)seed);
    snprintf((char *)h + 58, 32, "splatd gen_cloud");
    put_u16(h + 94, LAS_HDR);
    put_u32(h + 96, LAS_HDR);
    h[104] = 2;
    put_u16(h + 105, LAS_REC);
    put_u32(h + 107, (uint32_t)n);
    put_u32(h + 111, (uint32_t)n); /* every point a first (and only) return */
    for (int k = 0; k < 3; k++) {
        put_f64(h + 131 + 8 * k, LAS_SCALE);
        put_f64(h + 155 + 8 * k, 0.0);
        put_f64(h + 179 + 16 * k, hi[k]);
        put_f64(h + 187 + 16 * k, lo[k]);
    }
}

/* las_record: point p as a format-2 record; widens lo/hi by its quantised position. */
static void las_record(uint8_t *b, const pt *p, double lo[3], double hi[3])
{
    memset(b, 0, LAS_REC);
    const float xyz[3] = {p->x, p->y, p->z};
    for (int k = 0; k < 3; k++) {
        int32_t q = (int32_t)lround(xyz[k] / LAS_SCALE);
        put_u32(b + 4 * k, (uint32_t)q);
        double v = q * LAS_SCALE;
        if (v < lo[k]) lo[k] = v;
        if (v > hi[k]) hi[k] = v;
    }
    b[14] = 1 | 1 << 3; /* return 1 of 1 */
    b[15] = p->cls;
    for (int k = 0; k < 3; k++) put_u16(b + 20 + 2 * k, p->c[k] * 257u);
}

int main(int argc, char **argv)
{
    const char *out = NULL;
    long long n = -1;
    uint64_t seed = 0x5eed5eedull;
    double veg = -1.0; /* the fixed shares */
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--seed") && i + 1 < argc) {
            seed = strtoull(argv[++i], NULL, 0);
        } else if (!strcmp(argv[i], "--vegetation") && i + 1 < argc) {
            char *e;
            veg = strtod(argv[++i], &e);
            if (*e || !(veg >= 0 && veg <= 1)) {
                fprintf(stderr, "gen_cloud: --vegetation must be in [0, 1], got '%s'\n", argv[i]);
                return 2;
            }
        } else if (n < 0) {
            char *e;
            n = strtoll(argv[i], &e, 10);
            if (*e || n < 1 || n > 2000000000LL) {
                fprintf(stderr, "gen_cloud: N must be an integer in [1, 2e9], got '%s'\n", argv[i]);
                return 2;
            }
        } else if (!out) {
            out = argv[i];
        } else {
            fprintf(stderr, "usage: gen_cloud N out.ply|out.las [--seed S] [--vegetation F]\n");
            return 2;
        }
    }
    if (n < 0 || !out) {
        fprintf(stderr, "usage: gen_cloud N out.ply|out.las [--seed S] [--vegetation F]\n");
        return 2;
    }
    FILE *f = fopen(out, "wb");
    if (!f) {
        perror(out);
        return 1;
    }
    int las = ends_with_las(out);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    uint8_t hdr[LAS_HDR];
    if (las) {
        if (n > 4294967295LL) {
            fprintf(stderr, "gen_cloud: LAS 1.2 holds at most 4294967295 points\n");
            fclose(f);
            return 2;
        }
        las_header(hdr, n, lo, hi, seed); /* bounds written again at the end */
        if (fwrite(hdr, LAS_HDR, 1, f) != 1) {
            perror(out);
            fclose(f);
            return 1;
        }
    } else {
        fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment gen_cloud seed %llu\n"
                   "element vertex %lld\nproperty float x\nproperty float y\nproperty float z\n"
                   "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
                (unsigned long long)seed, n);
    }
    enum { BLOCK = 65536 };
    const size_t REC = las ? LAS_REC : 15;
    uint8_t *buf = malloc((size_t)BLOCK * REC);
    if (!buf) {
        fprintf(stderr, "gen_cloud: out of memory\n");
        fclose(f);
        return 1;
    }
    rng r = {seed};
    for (long long done = 0; done < n;) {
        long long m = n - done < BLOCK ? n - done : BLOCK;
        for (long long i = 0; i < m; i++) {
            pt p;
            make_point(&p, &r, veg);
            uint8_t *b = buf + i * REC;
            if (las) {
                las_record(b, &p, lo, hi);
                continue;
            }
            put_f32(b, p.x);
            put_f32(b + 4, p.y);
            put_f32(b + 8, p.z);
            memcpy(b + 12, p.c, 3);
        }
        if (fwrite(buf, REC, (size_t)m, f) != (size_t)m) {
            perror(out);
            free(buf);
            fclose(f);
            return 1;
        }
        done += m;
    }
    free(buf);
    if (las) {
        las_header(hdr, n, lo, hi, seed);
        if (fseek(f, 0, SEEK_SET) != 0 || fwrite(hdr, LAS_HDR, 1, f) != 1) {
            perror(out);
            fclose(f);
            return 1;
        }
    }
    if (fclose(f) != 0) {
        perror(out);
        return 1;
    }
    return 0;
}
