#!/bin/sh
# bench_hash.sh — the cache key's hash (sd_hash64: XXH3-64 from libxxhash) and the PCD LZF
# decoder (liblzf) as splatd calls them (part of `make bench`). Markdown rows.
set -eu
bench=${SPLATD_BENCH:-build/bench}
data=${SPLATD_TESTDATA:-tests/data}
echo "## hash and LZF (sd_hash64 = XXH3-64, pc_lzf_decompress = liblzf; medians of 7)"
echo
echo "| measure | value | detail |"
echo "|---|---|---|"
"$bench/hash_lzf_bench" "$data/table_scene_mug_stereo_textured.pcd" 7
