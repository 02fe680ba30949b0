#!/bin/sh
# bench_lod.sh — huge scans in the level-of-detail form (README "Huge scans"):
#   1. the out-of-core build (`splatd prep --lod always`, kNN normals included): wall time,
#      points/s end to end, user CPU seconds and peak RSS (/usr/bin/time), for gen_cloud's
#      synthetic scene at 1M and 10M points, and the in-memory prep of the same files for the
#      ratio (one run each: these take minutes on the 2-core machine);
#   2. frame time at fixed budgets (lod_bench: 1280x720, median of 7 cameras turned 0.5
#      degrees apart, each timed once complete) for the 1M and 10M clouds, points and splat;
#   3. a daemon with the prepared 10M cloud: time from OPEN to the first frame (splat render
#      with lod_first=1, connection included) and to the complete frame, and the daemon's RSS
#      with the cloud open and drawn;
#   4. a fly-through (`splat path`, 32 cameras low over the scene, 640x360, points, budget 1M) against
#      a fresh daemon each run, with --prefetch 0 and 4 alternating: wall time of the job.
# Environment: SPLATD_BIN, SPLAT_BIN, SPLATD_BENCH, SPLATD_TOOLS; LOD_BENCH_100M=1 adds the
# 100M cloud (1.5 GB of PLY, ~12 GB of scratch and cache, ~20 minutes here);
# LOD_BENCH_DIR=DIR keeps the clouds and caches there (default: a temporary directory).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
bench=${SPLATD_BENCH:-$root/build/bench}
tools=${SPLATD_TOOLS:-$root/build/tools}
splatd=${SPLATD_BIN:-$root/build/bin/splatd}
splat=${SPLAT_BIN:-$root/build/bin/splat}
for b in "$bench/lod_bench" "$tools/gen_cloud" "$splatd" "$splat" /usr/bin/time; do
    if [ ! -x "$b" ]; then echo "bench_lod: $b is missing" >&2; exit 1; fi
done
if [ -n "${LOD_BENCH_DIR:-}" ]; then
    tmp=$LOD_BENCH_DIR
    mkdir -p "$tmp"
else
    tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-lod.XXXXXX")
    trap 'rm -rf "$tmp"' EXIT INT TERM
fi
sizes="1000000 10000000"
[ "${LOD_BENCH_100M:-0}" = 1 ] && sizes="$sizes 100000000"
label() { awk -v n="$1" 'BEGIN{ if (n >= 1e6) printf "%gM", n / 1e6; else printf "%gk", n / 1e3 }'; }

echo "## Level of detail: build (k = 24, --memory 2G, 2 threads, one run each)"
echo
echo "| cloud | form | wall s | points/s | user CPU s | peak RSS MiB |"
echo "|---|---|---:|---:|---:|---:|"
for n in $sizes; do
    l=$(label "$n")
    mkdir -p "$tmp/data"
    f="$tmp/data/g$l.ply" # where the daemon below finds it (the cache is keyed by the path)
    [ -f "$f" ] || "$tools/gen_cloud" "$n" "$f" > /dev/null
    for form in lod flat; do
        [ "$form" = flat ] && [ "$n" -gt 10000000 ] && continue # in-memory prep at 100M: ~14 GB
        mode=always; [ "$form" = flat ] && mode=never
        /usr/bin/time -f "%e %U %M" -o "$tmp/time" "$splatd" prep "$f" --lod $mode \
            --cache "$tmp/cache" --memory 2G --force --quiet > /dev/null
        awk -v l="$l" -v form="$form" -v n="$n" '{printf "| %s | %s | %.1f | %.0f | %.1f | %.0f |\n",
            l, form, $1, n / $1, $2, $3 / 1024}' "$tmp/time"
    done
done

echo
echo "## Level of detail: frame time at a fixed budget (1280x720, median of 7 cameras)"
echo
echo "| cloud | points | pipeline | budget | points drawn | ms/frame | frames to complete |"
echo "|---|---:|---|---:|---:|---:|---:|"
for n in $sizes; do
    l=$(label "$n")
    for p in points splat; do
        for b in 300000 1000000; do
            "$bench/lod_bench" "$tmp/data/g$l.ply" --cache "$tmp/cache" --budget $b --pipeline $p \
                --frames 7 --label "$l" | grep '^|' || true
        done
    done
done

echo
echo "## Level of detail: a daemon with the prepared cloud"
echo
echo "| cloud | OPEN to first frame ms (lod_first=1) | then a complete 1M-point frame ms | daemon RSS MiB (cloud open, frames drawn) |"
echo "|---|---:|---:|---:|"
for n in $sizes; do
    [ "$n" -lt 10000000 ] && continue
    l=$(label "$n")
    rm -f "$tmp/port"
    "$splatd" --data "$tmp/data" --cache "$tmp/cache" --listen 127.0.0.1:0 --port-file "$tmp/port" \
        --lod always 2> "$tmp/splatd.log" &
    pid=$!
    i=0
    while [ ! -s "$tmp/port" ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done
    port=$(cat "$tmp/port")
    t0=$(date +%s.%N)
    "$splat" --port "$port" -q render "g$l" -o "$tmp/first.jpg" --set lod_first=1
    t1=$(date +%s.%N)
    "$splat" --port "$port" -q render "g$l" -o "$tmp/full.jpg" --set point_budget=1000000
    t2=$(date +%s.%N)
    rss=$(awk '/VmRSS/{print $2}' "/proc/$pid/status")
    kill "$pid"
    wait "$pid" || true
    awk -v l="$l" -v a="$t0" -v b="$t1" -v c="$t2" -v r="$rss" \
        'BEGIN{printf "| %s | %.0f | %.0f | %.0f |\n", l, (b - a) * 1e3, (c - b) * 1e3, r / 1024}'
done

echo
echo "## Level of detail: a fly-through with and without PREFETCH (fresh daemon each run)"
echo
awk 'BEGIN{ for (i = 0; i < 32; i++) { t = i / 31; x = -35 + 70 * t; y = -30 + 60 * t;
    printf "%g %g 3  %g %g 2.5  0 0 1  60\n", x, y, x + 10, y + 8.6 } }' > "$tmp/fly.txt"
echo "| cloud | --prefetch 0 s (runs) | --prefetch 4 s (runs) | ratio of medians |"
echo "|---|---|---|---:|"
for n in $sizes; do
    l=$(label "$n")
    r0=""; r4=""
    for run in 1 2 3; do
        for k in 0 4; do
            rm -f "$tmp/port" "$tmp"/fly_*.jpg
            "$splatd" --data "$tmp/data" --cache "$tmp/cache" --listen 127.0.0.1:0 \
                --port-file "$tmp/port" --lod always 2> "$tmp/splatd.log" &
            pid=$!
            i=0
            while [ ! -s "$tmp/port" ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done
            port=$(cat "$tmp/port")
            t0=$(date +%s.%N)
            "$splat" --port "$port" -q path "g$l" --path "$tmp/fly.txt" -o "$tmp/fly_%03d.jpg" \
                --size 640x360 --set point_budget=1000000 --set pipeline=points --prefetch $k
            t1=$(date +%s.%N)
            kill "$pid"
            wait "$pid" || true
            s=$(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.2f", b - a}')
            if [ $k = 0 ]; then r0="$r0 $s"; else r4="$r4 $s"; fi
        done
    done
    med() { echo "$1" | tr ' ' '\n' | grep . | sort -n | sed -n 2p; }
    m0=$(med "$r0"); m4=$(med "$r4")
    awk -v l="$l" -v a="$r0" -v b="$r4" -v x="$m0" -v y="$m4" \
        'BEGIN{printf "| %s |%s |%s | %.2f |\n", l, a, b, x / y}'
done
