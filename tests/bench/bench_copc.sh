#!/bin/sh
# bench_copc.sh — time from OPEN of a COPC file to its first frame (part of `make bench`):
# for each run, a fresh splatd on an ephemeral loopback port with an empty cache (so the OPEN
# prepares the cloud), and build/bench/copc_first as the client: the first frame (1280x720
# JPEG, the default camera framing) with provisional=1 (COPC's top levels, drawn with points)
# and with provisional=0 (the full prep first, then the default splat pipeline). Medians of
# COPC_RUNS runs (default 5). Files: tests/data's COPC files (ellipsoid.copc.laz, 100k points,
# the only one: there is no COPC writer), a larger hierarchy made from it by copc_dup.py (its
# top levels hold 463,904 points; the full prep still reads the chunk table's 100k), plus
# $COPC_BENCH_FILES.
set -eu
bin=${SPLATD_BIN:-build/bin/splatd}
bench=${SPLATD_BENCH:-build/bench}
data=${SPLATD_TESTDATA:-tests/data}
runs=${COPC_RUNS:-5}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-copc.XXXXXX")
pid=
cleanup() {
    [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

# one FILE PROVISIONAL: prints copc_first's line for a fresh daemon and cache
one() {
    rm -rf "$tmp/cache" "$tmp/port"
    mkdir -p "$tmp/cache"
    "$bin" --listen 127.0.0.1:0 --port-file "$tmp/port" --data "$tmp/data" --cache "$tmp/cache" \
        2>"$tmp/splatd.log" &
    pid=$!
    i=0
    while [ ! -s "$tmp/port" ]; do
        i=$((i + 1))
        if [ $i -gt 600 ] || ! kill -0 "$pid" 2>/dev/null; then
            echo "bench_copc: splatd did not start:" >&2; cat "$tmp/splatd.log" >&2; exit 1
        fi
        sleep 0.1
    done
    "$bench/copc_first" --port "$(cat "$tmp/port")" --cloud "$1" --provisional "$2"
    kill -TERM "$pid"
    wait "$pid" || true
    pid=
}

# median of column $1 of stdin
median() { sort -n -k"$1","$1" | awk -v c="$1" '{v[NR]=$c} END {print v[int((NR+1)/2)]}'; }

mkdir -p "$tmp/data" "$tmp/made"
# A larger COPC without a COPC writer (copc_dup.py): ellipsoid's root chunk referenced by 1 + 6
# level-0/1 nodes (463,904 points under the default 500k budget) and 8 level-2 nodes beyond it.
dup=
if command -v python3 >/dev/null 2>&1; then
    python3 "$(dirname "$0")/copc_dup.py" "$data/ellipsoid.copc.laz" \
        "$tmp/made/ellipsoid-dup464k.copc.laz" 6 8 >/dev/null && dup="$tmp/made/ellipsoid-dup464k.copc.laz"
fi
files=$(ls "$data"/*.copc.laz 2>/dev/null; echo $dup; for f in ${COPC_BENCH_FILES:-}; do echo "$f"; done)
echo "## COPC: OPEN to first frame (fresh daemon and cache each run, median of $runs, 1280x720 JPEG)"
echo
echo "| file | first frame, provisional=1 (min-max) | points drawn | full INFO, provisional=1 | first frame, provisional=0 (min-max) | ratio |"
echo "|---|---:|---:|---:|---:|---:|"
for f in $files; do
    name=$(basename "$f")
    cp "$f" "$tmp/data/$name"
    : >"$tmp/p1"; : >"$tmp/p0"
    r=0
    while [ $r -lt "$runs" ]; do
        one "$name" 1 >>"$tmp/p1"
        one "$name" 0 >>"$tmp/p0"
        r=$((r + 1))
    done
    a=$(median 1 <"$tmp/p1"); full=$(median 2 <"$tmp/p1"); b=$(median 1 <"$tmp/p0")
    pts=$(head -1 "$tmp/p1" | awk '{print $3}')
    ra=$(sort -n "$tmp/p1" | awk 'NR==1{lo=$1} {hi=$1} END{print lo "-" hi}')
    rb=$(sort -n "$tmp/p0" | awk 'NR==1{lo=$1} {hi=$1} END{print lo "-" hi}')
    echo "| $name | $a ms ($ra) | $pts | $full ms | $b ms ($rb) | $(awk -v a="$a" -v b="$b" 'BEGIN{printf "%.1fx", b / a}') |"
    rm -f "$tmp/data/$name"
done
