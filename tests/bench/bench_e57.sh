#!/bin/sh
# bench_e57.sh — E57 read throughput (e57_bench): a generated 4M-point E57 file in two scans
# (double and scaled-integer coordinates, RGB, intensity) read whole and as the LOD build's
# stream, against the LAS reader on the same points in the same run. Environment:
# SPLATD_BENCH (e57_bench's directory), E57_BENCH_POINTS (default 4000000), E57_BENCH_RUNS
# (default 3).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
bench=${SPLATD_BENCH:-$root/build/bench}
eb="$bench/e57_bench"
if [ ! -x "$eb" ]; then echo "bench_e57: $eb is missing (make $eb)" >&2; exit 1; fi
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-e57.XXXXXX")
trap 'rm -rf "$tmp"' EXIT INT TERM
pts=${E57_BENCH_POINTS:-4000000}
runs=${E57_BENCH_RUNS:-3}
echo "## E57 read ($pts points in 2 scans, median of $runs, files in the page cache, 1 thread)"
echo
"$eb" "$tmp" --points "$pts" --runs "$runs" --header
