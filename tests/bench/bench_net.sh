#!/bin/sh
# bench_net.sh — end-to-end network numbers (part of `make bench`): starts splatd on an
# ephemeral loopback port with a temporary data directory holding tests/data/Guanyin.ply, runs
# build/bench/net_bench (latency vs render+encode time, pipelined camera path) and prints
# Markdown rows.
set -eu
bin=${SPLATD_BIN:-build/bin/splatd}
bench=${SPLATD_BENCH:-build/bench}
data=${SPLATD_TESTDATA:-tests/data}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-net.XXXXXX")
pid=
cleanup() {
    [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM
mkdir -p "$tmp/data" "$tmp/cache"
cp "$data/Guanyin.ply" "$tmp/data/"
"$bin" --listen 127.0.0.1:0 --port-file "$tmp/port" --data "$tmp/data" --cache "$tmp/cache" \
    --preload Guanyin 2>"$tmp/splatd.log" &
pid=$!
i=0
while [ ! -s "$tmp/port" ]; do
    i=$((i + 1))
    if [ $i -gt 600 ] || ! kill -0 "$pid" 2>/dev/null; then
        echo "bench_net: splatd did not start:" >&2; cat "$tmp/splatd.log" >&2; exit 1
    fi
    sleep 0.1
done
port=$(cat "$tmp/port")
echo "## network: end-to-end latency and pipelining (loopback, Guanyin.ply, 238k points)"
echo
echo "| measure | value | detail |"
echo "|---|---|---|"
"$bench/net_bench" --port "$port" --cloud Guanyin --size 1280x720 --pipeline points --latency 20 --path 100
"$bench/net_bench" --port "$port" --cloud Guanyin --size 1280x720 --pipeline splat --latency 10 --path 12
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
pid=
[ "$rc" -eq 0 ] || { echo "bench_net: splatd exited with $rc after SIGTERM" >&2; exit 1; }
