#!/bin/sh
# run-demo.sh — `make run`: starts splatd on 127.0.0.1 (an ephemeral port) serving a temporary
# data directory with a copy of tests/data/Guanyin.ply, renders a 36-frame orbit of it with
# `splat path`, prints where the frames are, and stops the daemon with SIGTERM (exit 0 expected).
#
# usage: sh deploy/run-demo.sh SPLATD SPLAT [OUTDIR]   (OUTDIR default ./out)
# $RUN_ARGS (make run RUN_ARGS=...) are passed to `splat path`, e.g. --force to render again the
# frames a previous run left in OUTDIR (without it they are skipped).
set -eu
splatd=${1:?usage: run-demo.sh SPLATD SPLAT [OUTDIR]}
splat=${2:?usage: run-demo.sh SPLATD SPLAT [OUTDIR]}
out=${3:-out}
here=$(cd "$(dirname "$0")/.." && pwd)
src="$here/tests/data/Guanyin.ply"

tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-demo.XXXXXX")
pid=
cleanup() {
    if [ -n "$pid" ]; then kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; fi
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

# A copy, not a symlink: splatd refuses links that point outside its data directory.
mkdir -p "$tmp/data" "$out"
cp "$src" "$tmp/data/Guanyin.ply"
# The prepared-cloud cache persists between runs, so a second `make run` skips preprocessing.
cache=${SPLATD_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/splatd}

echo "run-demo: starting splatd (data $tmp/data, cache $cache)"
"$splatd" --listen 127.0.0.1:0 --port-file "$tmp/port" --data "$tmp/data" --cache "$cache" \
    --preload Guanyin 2>"$tmp/splatd.log" &
pid=$!
i=0
while [ ! -s "$tmp/port" ]; do
    i=$((i + 1))
    if [ $i -gt 300 ] || ! kill -0 "$pid" 2>/dev/null; then
        echo "run-demo: splatd did not start; its log:" >&2
        cat "$tmp/splatd.log" >&2
        exit 1
    fi
    sleep 0.1
done
port=$(cat "$tmp/port")
echo "run-demo: splatd is listening on 127.0.0.1:$port"

# shellcheck disable=SC2086
if ! "$splat" --port "$port" path Guanyin --orbit 36 --size 960x720 -o "$out/%05d.jpg" ${RUN_ARGS:-}; then
    echo "run-demo: splat path failed; the daemon's log:" >&2
    cat "$tmp/splatd.log" >&2
    exit 1
fi
n=$(ls "$out"/*.jpg 2>/dev/null | wc -l)
echo "run-demo: $n frames in $(cd "$out" && pwd)/ (00000.jpg ... 00035.jpg)"

kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
pid=
if [ "$rc" -ne 0 ]; then
    echo "run-demo: splatd exited with status $rc after SIGTERM (expected 0); its log:" >&2
    cat "$tmp/splatd.log" >&2
    exit 1
fi
echo "run-demo: splatd stopped cleanly (SIGTERM, exit 0)"
