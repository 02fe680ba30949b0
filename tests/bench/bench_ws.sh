#!/bin/sh
# bench_ws.sh — the browser listener against plain TCP (part of `make bench`): starts splatd
# with --http on ephemeral loopback ports and tests/data/Guanyin.ply preloaded, runs
# build/bench/ws_bench (the same cameras over TCP and over the WebSocket, interleaved; framing
# cost in process) and prints Markdown rows.
set -eu
bin=${SPLATD_BIN:-build/bin/splatd}
bench=${SPLATD_BENCH:-build/bench}
data=${SPLATD_TESTDATA:-tests/data}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-ws.XXXXXX")
pid=
cleanup() {
    [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM
mkdir -p "$tmp/data" "$tmp/cache"
cp "$data/Guanyin.ply" "$tmp/data/"
"$bin" --listen 127.0.0.1:0 --http 127.0.0.1:0 --port-file "$tmp/port" --data "$tmp/data" \
    --cache "$tmp/cache" --preload Guanyin 2>"$tmp/splatd.log" &
pid=$!
i=0
while ! { [ -s "$tmp/port" ] && [ "$(wc -l < "$tmp/port")" -ge 2 ]; }; do
    i=$((i + 1))
    if [ $i -gt 600 ] || ! kill -0 "$pid" 2>/dev/null; then
        echo "bench_ws: splatd did not start:" >&2; cat "$tmp/splatd.log" >&2; exit 1
    fi
    sleep 0.1
done
port=$(sed -n 1p "$tmp/port")
hport=$(sed -n 2p "$tmp/port")
echo "## browser listener: WebSocket against TCP (loopback, Guanyin.ply, 238k points)"
echo
echo "| measure | value | detail |"
echo "|---|---|---|"
"$bench/ws_bench" --port "$port" --http-port "$hport" --cloud Guanyin --size 1280x720 --pipeline points --frames 40
"$bench/ws_bench" --port "$port" --http-port "$hport" --cloud Guanyin --size 640x360 --pipeline points --frames 40 --framing 0
echo
echo "## browser page: camera sent by the page -> frame received and drawn (headless Chromium, loopback, Guanyin.ply)"
echo
echo "| measure | value | detail |"
echo "|---|---|---|"
"$bench/ws_bench" --port "$port" --http-port "$hport" --cloud Guanyin.ply --size 640x360 --pipeline points --page 15
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
pid=
[ "$rc" -eq 0 ] || { echo "bench_ws: splatd exited with $rc after SIGTERM" >&2; exit 1; }
