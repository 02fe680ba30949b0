/* hash_lzf_bench.c — the content hash of the cache key (sd_hash64) and the PCD LZF decoder
 * (pc_lzf_decompress), as the daemon calls them.
 *
 *   hash_lzf_bench PCD_FILE [REPS]
 *
 * PCD_FILE must be DATA binary_compressed (tests/data/table_scene_mug_stereo_textured.pcd).
 * Rows (Markdown): sd_hash64 over a 256 MiB buffer in one call and in 1 MiB pieces (as the
 * cache hashes a source file), GB/s; the file's LZF block decoded alone, MB/s of output; the
 * whole file read by pc_read_pcd, ms. Medians of REPS (default 7). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cloud.h"
#include "lzf.h"
#include "sd_hash.h"
#include "testutil.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: hash_lzf_bench PCD_FILE [REPS]\n");
        return 2;
    }
    int reps = argc > 2 ? atoi(argv[2]) : 7;
    if (reps < 1 || reps > 100) reps = 7;
    double t[100];
    volatile uint64_t sink = 0;

    size_t big = (size_t)256 << 20;
    uint8_t *buf = malloc(big);
    if (!buf) return 1;
    uint64_t x = 0x9E3779B97F4A7C15ull;
    for (size_t i = 0; i < big; i += 8) {
        x ^= x << 13; x ^= x >> 7; x ^= x << 17;
        memcpy(buf + i, &x, 8);
    }
    for (int r = 0; r < reps; r++) {
        double t0 = now_s();
        sink += sd_hash64(buf, big, 0);
        t[r] = now_s() - t0;
    }
    double one = (double)big / tu_median(t, reps) / 1e9;
    for (int r = 0; r < reps; r++) {
        double t0 = now_s();
        sd_hash_state hs;
        sd_hash64_init(&hs, 0);
        for (size_t off = 0; off < big; off += (size_t)1 << 20) sd_hash64_update(&hs, buf + off, (size_t)1 << 20);
        sink += sd_hash64_final(&hs);
        t[r] = now_s() - t0;
    }
    double pieces = (double)big / tu_median(t, reps) / 1e9;
    printf("| sd_hash64, 256 MiB in one call | %.2f GB/s | in 1 MiB pieces (the cache's source hash) %.2f GB/s |\n",
           one, pieces);
    free(buf);

    size_t len = 0;
    uint8_t *f = tu_read_file(argv[1], &len);
    const char *tag = "DATA binary_compressed\n";
    const uint8_t *d = f ? memmem(f, len, tag, strlen(tag)) : NULL;
    if (!d) {
        fprintf(stderr, "hash_lzf_bench: %s is not a binary_compressed PCD\n", argv[1]);
        return 1;
    }
    d += strlen(tag);
    uint32_t csize, usize;
    memcpy(&csize, d, 4);
    memcpy(&usize, d + 4, 4);
    if ((size_t)(d + 8 - f) + csize > len) return 1;
    uint8_t *out = malloc(usize);
    if (!out) return 1;
    for (int r = 0; r < reps; r++) {
        sd_err e = {0};
        double t0 = now_s();
        for (int k = 0; k < 10; k++)
            if (pc_lzf_decompress(d + 8, csize, out, usize, argv[1], 0, &e) != 0) {
                fprintf(stderr, "hash_lzf_bench: %s\n", e.msg);
                return 1;
            }
        t[r] = (now_s() - t0) / 10;
        sink += out[usize / 2];
    }
    double mbs = usize / tu_median(t, reps) / 1e6;
    for (int r = 0; r < reps; r++) {
        pc_raw raw;
        memset(&raw, 0, sizeof raw);
        sd_err e = {0};
        double t0 = now_s();
        if (pc_read_pcd(argv[1], &raw, &e) != 0) {
            fprintf(stderr, "hash_lzf_bench: %s\n", e.msg);
            return 1;
        }
        t[r] = now_s() - t0;
        pc_raw_free(&raw);
    }
    printf("| LZF block of %s (%u -> %u bytes) | %.0f MB/s of output | pc_read_pcd of the whole "
           "file %.2f ms |\n", strrchr(argv[1], '/') ? strrchr(argv[1], '/') + 1 : argv[1], csize,
           usize, mbs, tu_median(t, reps) * 1000);
    free(out);
    free(f);
    (void)sink;
    return 0;
}
