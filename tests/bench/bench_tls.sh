#!/bin/sh
# bench_tls.sh — the cost of TLS per frame (part of `make bench`): starts two splatd on
# loopback, one plaintext and one with a certificate made by build/bench/tls_bench, both with
# tests/data/bun000.ply, and runs tls_bench against both (alternating rounds). Markdown rows.
set -eu
bin=${SPLATD_BIN:-build/bin/splatd}
bench=${SPLATD_BENCH:-build/bench}
data=${SPLATD_TESTDATA:-tests/data}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-tls.XXXXXX")
p1= p2=
cleanup() {
    for p in $p1 $p2; do kill "$p" 2>/dev/null && wait "$p" 2>/dev/null; done
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM
mkdir -p "$tmp/data" "$tmp/cache"
cp "$data/bun000.ply" "$tmp/data/bunny.ply"
"$bench/tls_bench" --make-cert "$tmp"
"$bin" --listen 127.0.0.1:0 --port-file "$tmp/port1" --data "$tmp/data" --cache "$tmp/cache" \
    --preload bunny 2>"$tmp/plain.log" &
p1=$!
"$bin" --listen 127.0.0.1:0 --port-file "$tmp/port2" --data "$tmp/data" --cache "$tmp/cache" \
    --preload bunny --tls-cert "$tmp/bench.crt" --tls-key "$tmp/bench.key" 2>"$tmp/tls.log" &
p2=$!
i=0
while [ ! -s "$tmp/port1" ] || [ ! -s "$tmp/port2" ]; do
    i=$((i + 1))
    if [ $i -gt 600 ] || ! kill -0 "$p1" 2>/dev/null || ! kill -0 "$p2" 2>/dev/null; then
        echo "bench_tls: splatd did not start:" >&2; cat "$tmp"/*.log >&2; exit 1
    fi
    sleep 0.1
done
echo "## TLS: cost per frame (loopback, bun000.ply, 40k points)"
echo
"$bench/tls_bench" --plain "$(cat "$tmp/port1")" --tls "$(cat "$tmp/port2")" --ca "$tmp/bench.crt" \
    --cloud bunny --rounds "${TLS_BENCH_ROUNDS:-3}" --frames "${TLS_BENCH_FRAMES:-15}" \
    --pids "$p1,$p2"
