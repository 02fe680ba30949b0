/* cache_seeds — remakes the fuzz seeds of the cache and splod targets (tests/fuzz/corpus/cache/
 * and splod/): caches of small clouds written by this splatd, and damaged copies named bad_*.
 * Run it whenever a cache format's version or layout changes (the seeds must be of the version
 * the loader reads, or every one of them is merely "old" and the fuzzer learns nothing):
 *
 *   build/tools/cache_seeds tests/fuzz/corpus
 *
 * cache/: flat caches (cache_open_cloud, k 24, one thread) of 30 and 64 points on a sphere
 * (xyz) and 40 with colours (PLY); bad_magic (byte 0), bad_count (the point count + 1),
 * bad_truncated (100 bytes cut). splod/: LOD caches (lod_open_cloud with fuzz_one_splod's
 * options, grid_bits 2 and leaf_max 64, one thread) of 200 points on a sphere and 400 on a plane
 * (xyz) and 600 on a sphere with colours (PLY); bad_magic, bad_truncated (200 bytes cut) and
 * bad_table (node 1's parent made 5). The fuzz targets re-seal every seed for their own source
 * file (its key and the checksums), so only the layout and the values matter. */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cache.h"
#include "cachefile.h"
#include "lod.h"
#include "prep.h"

static void die(const char *what, const char *why)
{
    fprintf(stderr, "cache_seeds: %s: %s\n", what, why);
    exit(1);
}

/* Writes n points: on a unit sphere (a Fibonacci spiral), or on a plane when plane, as xyz
 * text, or as ASCII PLY with colours when rgb. */
static void source(const char *path, int n, int plane, int rgb)
{
    FILE *f = fopen(path, "w");
    if (!f) die(path, "cannot write");
    if (rgb)
        fprintf(f, "ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                   "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar "
                   "blue\nend_header\n", n);
    for (int i = 0; i < n; i++) {
        double x, y, z;
        if (plane) {
            x = (i % 20) * 0.05, y = (i / 20) * 0.05, z = 0.001 * ((i * 7) % 5);
        } else {
            z = 1 - (2 * i + 1.0) / n;
            double r = sqrt(1 - z * z), a = i * M_PI * (3 - sqrt(5));
            x = r * cos(a), y = r * sin(a);
        }
        if (rgb) fprintf(f, "%.6f %.6f %.6f %d %d %d\n", x, y, z, i % 256, (3 * i) % 256, 200);
        else fprintf(f, "%.6f %.6f %.6f\n", x, y, z);
    }
    fclose(f);
}

static uint8_t *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f) die(path, "cannot read");
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *b = malloc((size_t)n);
    if (!b || fread(b, 1, (size_t)n, f) != (size_t)n) die(path, "short read");
    fclose(f);
    *len = (size_t)n;
    return b;
}

static void put(const char *dir, const char *name, const uint8_t *b, size_t len)
{
    char p[4096];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    FILE *f = fopen(p, "wb");
    if (!f || fwrite(b, 1, len, f) != len || fclose(f) != 0) die(p, "cannot write");
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: cache_seeds CORPUS_DIR   (tests/fuzz/corpus)\n");
        return 2;
    }
    char tmp[] = "/tmp/cache_seeds.XXXXXX", cdir[4200], ldir[4200];
    if (!mkdtemp(tmp)) die("mkdtemp", "failed");
    snprintf(cdir, sizeof cdir, "%s/cache", argv[1]);
    snprintf(ldir, sizeof ldir, "%s/splod", argv[1]);
    mkdir(cdir, 0755);
    mkdir(ldir, 0755);
    static const struct { const char *name; int n, plane, rgb, lod; } seeds[] = {
        {"sphere30", 30, 0, 0, 0}, {"sphere64", 64, 0, 0, 0},   {"rgb40", 40, 0, 1, 0},
        {"sphere200", 200, 0, 0, 1}, {"plane400", 400, 1, 0, 1}, {"rgb600", 600, 0, 1, 1},
    };
    for (size_t i = 0; i < sizeof seeds / sizeof seeds[0]; i++) {
        char src[4200];
        snprintf(src, sizeof src, "%s/%s.%s", tmp, seeds[i].name, seeds[i].rgb ? "ply" : "xyz");
        source(src, seeds[i].n, seeds[i].plane, seeds[i].rgb);
        sd_err err = {0};
        char path[4096];
        if (!seeds[i].lod) {
            cache_desc d = {.dir = tmp, .threads = 1};
            cache_result r;
            pc_prepared p;
            if (cache_open_cloud(src, &d, &p, &r, &err) != 0) die(src, err.msg);
            snprintf(path, sizeof path, "%s", r.path);
            pc_prepared_free(&p);
        } else {
            lod_desc d = {.dir = tmp, .threads = 1, .grid_bits = 2, .leaf_max = 64};
            lod_result r;
            lod_cloud c;
            if (lod_open_cloud(src, &d, &c, &r, &err) != 0) die(src, err.msg);
            snprintf(path, sizeof path, "%s", r.path);
            lod_cloud_free(&c);
        }
        size_t len;
        uint8_t *b = slurp(path, &len);
        const char *dir = seeds[i].lod ? ldir : cdir;
        put(dir, seeds[i].name, b, len);
        if (i == 0 || i == 3) { /* the damaged copies, of the smallest of each kind */
            cf_head h;
            memcpy(&h, b, sizeof h);
            uint8_t *c = malloc(len);
            memcpy(c, b, len);
            c[0] ^= 0x20;
            put(dir, "bad_magic", c, len);
            put(dir, "bad_truncated", b, len - (seeds[i].lod ? 200 : 100));
            memcpy(c, b, len);
            if (!seeds[i].lod) { /* n, the first u64 after k and attrs in the meta */
                uint64_t n;
                memcpy(&n, c + sizeof h + 8, 8);
                n++;
                memcpy(c + sizeof h + 8, &n, 8);
                put(dir, "bad_count", c, len);
            } else { /* node 1's parent: the table is the body */
                uint32_t five = 5;
                memcpy(c + h.body_off + sizeof(lod_node) + offsetof(lod_node, parent), &five, 4);
                put(dir, "bad_table", c, len);
            }
            free(c);
        }
        free(b);
        unlink(path);
        unlink(src);
    }
    char rm[4200];
    snprintf(rm, sizeof rm, "rm -rf '%s'", tmp);
    if (system(rm) != 0) die(tmp, "cannot remove");
    printf("cache_seeds: cache and splod seeds written under %s\n", argv[1]);
    return 0;
}
