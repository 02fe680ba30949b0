#!/bin/sh
# bench_prep.sh — preprocessing speed: pc_load + prep_run phases (median of 3) on a synthetic
# 1M-point scan-like cloud (tests/tools/gen_cloud) and on the largest real scan in tests/data,
# the kNN alone (grid, FLANN with pthreads, FLANN with its own OpenMP cores), and, when PCL's
# headers are installed, PCL's NormalEstimationOMP (k = 24, 2 threads) on the same files.
# Prints Markdown tables. Environment: SPLATD_BENCH (prep_bench's directory), SPLATD_TOOLS
# (gen_cloud's), SPLATD_TESTDATA, PREP_BENCH_THREADS (default 2), PREP_BENCH_10M=1 to add a
# 10M-point cloud (slow), PCL_NORMALS_BIN (a pcl_normals built earlier: skips the build).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
bench=${SPLATD_BENCH:-$root/build/bench}
tools=${SPLATD_TOOLS:-$root/build/tools}
data=${SPLATD_TESTDATA:-$root/tests/data}
threads=${PREP_BENCH_THREADS:-2}
pb="$bench/prep_bench"
gen="$tools/gen_cloud"
for b in "$pb" "$gen"; do
    if [ ! -x "$b" ]; then echo "bench_prep: $b is missing (make $(basename "$b"))" >&2; exit 1; fi
done
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-prep.XXXXXX")
trap 'rm -rf "$tmp"' EXIT INT TERM

echo "## Preprocessing (k = 24, $threads threads, median of 3)"
echo
t0=$(date +%s.%N)
"$gen" 1000000 "$tmp/synth1m.ply"
t1=$(date +%s.%N)
echo "gen_cloud 1M points: $(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.3f", b - a}') s"
files="$tmp/synth1m.ply $data/Guanyin.ply"
if [ "${PREP_BENCH_10M:-0}" = 1 ]; then
    "$gen" 10000000 "$tmp/synth10m.ply"
    files="$files $tmp/synth10m.ply"
fi
echo
first=1
for f in $files; do
    if [ $first = 1 ]; then "$pb" "$f" --knn both --threads "$threads" --header; first=0
    else "$pb" "$f" --knn both --threads "$threads"; fi
done | tee "$tmp/prep.md"

echo
echo "## kNN alone (every point, Morton order unless noted)"
echo
first=1
for f in "$tmp/synth1m.ply" "$data/Guanyin.ply"; do
    if [ $first = 1 ]; then "$pb" "$f" --knn-only --knn both --threads "$threads" --header; first=0
    else "$pb" "$f" --knn-only --knn both --threads "$threads"; fi
done
"$pb" "$tmp/synth1m.ply" --knn-only --knn both --threads "$threads" --file-order --runs 1

echo
echo "## Cached reload (splatd prep, first load vs the mmapped cache, median of 3 reloads)"
echo
splatd=${SPLATD_BIN:-$root/build/bin/splatd}
if [ -x "$splatd" ]; then
    echo "| file | first load s (read + prep + cache write) | cached reload ms | reload / first |"
    echo "|---|---|---|---|"
    for f in $files; do
        first=$("$splatd" prep "$f" --cache "$tmp/cache" --quiet | sed -n \
            's/^time *read \([0-9.]*\) s, prep \([0-9.]*\) s.*cache write \([0-9.]*\) s.*/\1 \2 \3/p' |
            awk '{print $1 + $2 + $3}')
        reload=$(for r in 1 2 3; do "$splatd" prep "$f" --cache "$tmp/cache" --quiet |
            awk '/cached load/ {print $4}'; done | sort -n | sed -n 2p)
        awk -v b="$(basename "$f")" -v a="$first" -v r="$reload" \
            'BEGIN{printf "| %s | %.3f | %.1f | %.2f %% |\n", b, a, r, 100 * r / 1000 / a}'
    done
else
    echo "cached reload skipped: $splatd is not built"
fi

echo
pcl_bin=${PCL_NORMALS_BIN:-}
pcl_ver=""
if [ -z "$pcl_bin" ]; then
    pcl_pkg=""
    for p in pcl_features pcl_features-1.13 pcl_features-1.12; do
        if pkg-config --exists "$p" 2>/dev/null; then pcl_pkg=$p; break; fi
    done
    if [ -z "$pcl_pkg" ] || ! command -v g++ >/dev/null 2>&1; then
        echo "PCL comparison skipped: PCL's development files (pkg-config pcl_features) or g++ are not installed."
        exit 0
    fi
    v=${pcl_pkg#pcl_features}
    pcl_ver=" $(pkg-config --modversion "$pcl_pkg")"
    pcl_bin="$tmp/pcl_normals"
    # the pkg-config output is a list of flags: word splitting is intended
    # shellcheck disable=SC2046
    if ! g++ -O2 -std=c++17 -fopenmp $(pkg-config --cflags "$pcl_pkg" "pcl_search$v" "pcl_kdtree$v" "pcl_common$v") \
            -o "$pcl_bin" "$here/pcl_normals.cpp" $(pkg-config --libs-only-L "$pcl_pkg") \
            -lpcl_features -lpcl_search -lpcl_kdtree -lpcl_common -lflann_cpp -llz4 \
            > "$tmp/pcl_build.log" 2>&1; then
        echo "PCL comparison skipped: pcl_normals.cpp did not build:"
        tail -5 "$tmp/pcl_build.log"
        exit 0
    fi
fi
echo "## Against PCL$pcl_ver NormalEstimationOMP (k = 24, $threads threads, median of 3)"
echo
echo "| file | points | PCL normals s | splatd prep (grid) s | splatd prep (flann) s | PCL / grid | PCL / flann |"
echo "|---|---|---|---|---|---|---|"
for f in $files; do
    line=$("$pcl_bin" "$f" 24 "$threads" 3)
    pcl=$(echo "$line" | awk '{print $2}')
    n=$(echo "$line" | awk '{print $4}')
    b=$(basename "$f")
    grid=$(awk -F'|' -v b="$b" '$2 ~ " "b" " && $4 ~ /grid/ {gsub(/ /,"",$13); print $13}' "$tmp/prep.md")
    fl=$(awk -F'|' -v b="$b" '$2 ~ " "b" " && $4 ~ /flann/ {gsub(/ /,"",$13); print $13}' "$tmp/prep.md")
    awk -v b="$b" -v n="$n" -v p="$pcl" -v g="$grid" -v f="$fl" \
        'BEGIN{printf "| %s | %s | %s | %s | %s | %.1fx | %.1fx |\n", b, n, p, g, f, p / g, p / f}'
done
echo
echo "(PCL's time is its kd-tree build + kNN + PCA normals; splatd's prep adds Morton reorder,"
echo " batches, radius, F and percentiles. Both read the same PLY; file parsing is excluded.)"
