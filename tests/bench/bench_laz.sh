#!/bin/sh
# bench_laz.sh — LAZ decode throughput: splatd's decoder (laz_bench: one thread, the reader on
# one and two threads, and the uncompressed .las twin read for scale) beside laz-perf's WASM
# decoder under Node (npm package laz-perf, installed into a temporary directory only for this
# bench, never a build or test dependency; skipped with a note when node or npm cannot get it).
# Both print an FNV-1a hash of all decoded records: equal hashes mean byte-equal output.
# Environment: SPLATD_BENCH (laz_bench's directory), SPLATD_TESTDATA, LAZ_BENCH_RUNS (default 9),
# LAZPERF_DIR (an existing directory holding node_modules/laz-perf: skips the install).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
bench=${SPLATD_BENCH:-$root/build/bench}
data=${SPLATD_TESTDATA:-$root/tests/data}
runs=${LAZ_BENCH_RUNS:-9}
lb="$bench/laz_bench"
if [ ! -x "$lb" ]; then echo "bench_laz: $lb is missing (make $lb)" >&2; exit 1; fi
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-laz.XXXXXX")
trap 'rm -rf "$tmp"' EXIT INT TERM

echo "## LAZ decode (median of $runs decodes, file in memory / page cache)"
echo
"$lb" "$data/autzen_trim.laz" --twin "$data/autzen_trim.las" --runs "$runs" --header \
    | tee "$tmp/splatd.md"
"$lb" "$data/ellipsoid-1.4.laz" --runs "$runs" | tee -a "$tmp/splatd.md"
"$lb" "$data/ellipsoid.copc.laz" --runs "$runs" | tee -a "$tmp/splatd.md"
echo
"$lb" "$data/ellipsoid.copc.laz" --levels --runs "$runs"

echo
lp=${LAZPERF_DIR:-}
if [ -z "$lp" ] && command -v npm >/dev/null 2>&1 && command -v node >/dev/null 2>&1; then
    if (cd "$tmp" && npm install --silent --no-audit --no-fund laz-perf@0.0.7 >/dev/null 2>&1)
    then lp=$tmp; fi
fi
if [ -z "$lp" ] || [ ! -d "$lp/node_modules/laz-perf" ]; then
    echo "laz-perf: not available (no node/npm, or the npm registry unreachable): no comparison."
    exit 0
fi
echo "| file | laz-perf $(node -p "require('$lp/node_modules/laz-perf/package.json').version") WASM (Node $(node --version)) Mpts/s | per CPU second | splatd decode 1 thread / laz-perf, wall | same, per CPU second | splatd reader 2 threads / laz-perf | same records (FNV-1a) |"
echo "|---|---|---|---|---|---|---|"
NODE_PATH="$lp/node_modules" node "$here/lazperf_bench.js" "$runs" "$data/autzen_trim.laz" \
    "$data/ellipsoid-1.4.laz" "$data/ellipsoid.copc.laz" |
while read -r f n t c h; do
    base=$(basename "$f")
    row=$(grep "^| $base |" "$tmp/splatd.md")
    dec=$(echo "$row" | awk -F'|' '{gsub(/ /,"",$4); print $4}')
    cpu=$(echo "$row" | awk -F'|' '{gsub(/ /,"",$5); print $5}')
    rd2=$(echo "$row" | awk -F'|' '{gsub(/ /,"",$7); print $7}')
    ours=$(echo "$row" | awk -F'|' '{gsub(/ /,"",$10); print $10}')
    awk -v b="$base" -v n="$n" -v t="$t" -v c="$c" -v d="$dec" -v u="$cpu" -v r="$rd2" -v h="$h" \
        -v o="$ours" 'BEGIN {
        lp = n / t / 1e6; lc = n / c / 1e6
        printf "| %s | %.2f | %.2f | %.2fx | %.2fx | %.2fx | %s |\n", b, lp, lc, d / lp, u / lc,
               r / lp, (h == o ? "yes" : "NO (" h ")")
    }'
done
