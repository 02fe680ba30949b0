/* cmd_prep_lod.c — `splatd prep FILE --lod ...`: builds (or maps) the LOD form of one cloud and
 * prints its summary: points, nodes, levels, chunks, the build's rate. */
#include <stdio.h>
#include <string.h>

#include "commands.h"
#include "lod.h"
#include "srv.h"

void cmd_lod_status(void *user, const char *line)
{
    (void)user;
    fprintf(stderr, "%s\n", line);
}

int cmd_prep_lod(const char *file, const lod_desc *d)
{
    lod_cloud c;
    lod_result r;
    sd_err err = {0};
    if (lod_open_cloud(file, d, &c, &r, &err) < 0) {
        char clean[sizeof err.msg * 4];
        srv_clean_text(err.msg, clean, sizeof clean);
        fprintf(stderr, "splatd prep: %s\n", clean);
        return 1;
    }
    uint64_t inner = 0, leaves = 0, maxn = 0, minn = UINT64_MAX;
    for (uint64_t i = 0; i < c.nnodes; i++) {
        const lod_node *n = &c.nodes[i];
        if (n->nchildren) inner++;
        else leaves++;
        if (n->count > maxn) maxn = n->count;
        if (n->count < minn) minn = n->count;
    }
    printf("file        %s\n", file);
    printf("format      %s (level of detail)\n", c.format);
    printf("points      %llu kept, %llu dropped (non-finite)\n", (unsigned long long)c.n,
           (unsigned long long)c.n_dropped);
    printf("bounds      x [%.6f, %.6f]  y [%.6f, %.6f]  z [%.6f, %.6f]\n", c.bmin[0], c.bmax[0],
           c.bmin[1], c.bmax[1], c.bmin[2], c.bmax[2]);
    printf("octree      %llu nodes (%llu inner, %llu leaves), %u levels, %llu to %llu points a "
           "node, sampling grid %u^3, leaves up to %u points\n", (unsigned long long)c.nnodes,
           (unsigned long long)inner, (unsigned long long)leaves, c.depth,
           (unsigned long long)minn, (unsigned long long)maxn, 1u << c.grid_bits, c.leaf_max);
    printf("sigma       %.6g (median nearest-neighbour distance)\n", c.sigma);
    printf("radius      %.6g (median splat radius)\n", c.radius_median);
    printf("F           p1 %.3f  p25 %.3f  p50 %.3f  p75 %.3f  p99 %.3f  (raw p99 %.4g)\n",
           c.F_pct[0], c.F_pct[1], c.F_pct[2], c.F_pct[3], c.F_pct[4], c.F_raw_p99);
    printf("cache       %s (%s)\n", r.path, r.hit ? "hit" : r.why);
    if (r.hit)
        printf("time        mapped in %.1f ms\n", r.t_total * 1e3);
    else
        printf("time        %.2f s, %.2f M points/s end to end; %llu chunks of at most %u "
               "points, %.0f %% of them grew their halo\n", r.t_total,
               r.t_total > 0 ? c.n / r.t_total / 1e6 : 0.0, (unsigned long long)r.chunks,
               r.chunk_max, r.halo_retries * 100);
    lod_cloud_free(&c);
    return 0;
}
