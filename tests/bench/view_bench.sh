#!/bin/sh
# view_bench.sh — interaction latency and frames/s of `splat view` on loopback, under Xvfb.
#
#   sh tests/bench/view_bench.sh BUILD_DIR CLOUD.ply [PIPELINE ...]
#
# Starts Xvfb and splatd on a copy of CLOUD, then for each pipeline (default: points splat)
# runs two scripts at 1280x720: "latency" (ten single drags 600 ms apart: input event -> the
# first frame that shows it, no queueing) and "drag" (a drag event every 20 ms for 3 s, then
# rest: frames/s while dragging, progressive quality on). Prints the viewer's stats lines
# (moving_fps, latency percentiles) and the size and server times of the full frame at rest.
set -eu
build=$1; cloud=$2; shift 2
pipes=${*:-points splat}
dir=$(mktemp -d); trap 'kill $xpid $dpid 2>/dev/null; rm -rf "$dir"' EXIT
mkdir "$dir/data" "$dir/cache"
cp "$cloud" "$dir/data/"
name=$(basename "$cloud" .ply)
n=$((200 + $$ % 50))
while [ -e /tmp/.X11-unix/X$n ] || [ -e /tmp/.X$n-lock ]; do n=$((n + 1)); done
Xvfb :$n -screen 0 1920x1080x24 -nolisten tcp >/dev/null 2>&1 & xpid=$!
"$build/bin/splatd" --listen 127.0.0.1:0 --data "$dir/data" --cache "$dir/cache" \
    --port-file "$dir/port" --preload "$name" 2>"$dir/splatd.log" & dpid=$!
i=0; while [ ! -s "$dir/port" ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done
while [ ! -e /tmp/.X11-unix/X$n ]; do sleep 0.1; done
port=$(cat "$dir/port")
{ echo "wait 1500"; for k in 1 2 3 4 5 6 7 8 9 10; do echo "drag 8 0"; echo "wait 600"; done
  echo "quit"; } > "$dir/latency"
{ echo "wait 1500"; k=0
  while [ $k -lt 150 ]; do echo "drag 3 0"; echo "wait 20"; k=$((k + 1)); done
  echo "wait 1500"; echo "quit"; } > "$dir/drag"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "cloud: $name"
# median: the median of the latency_ms of the frame lines on stdin.
median() {
    grep -v 'latency_ms=-' | sed -n 's/.*latency_ms=\([0-9.]*\).*/\1/p' | sort -n |
        awk '{v[NR] = $1} END {if (NR) printf "%.1f ms (n=%d)", v[int((NR + 1) / 2)], NR}'
}
for p in $pipes; do
    for s in latency drag drag-full; do
        extra=""; script=$s
        [ $s = drag-full ] && { extra=--no-progressive; script=drag; }
        DISPLAY=:$n "$build/bin/splat" --port "$port" view "$name" --size 1280x720 $extra \
            --set pipeline=$p --script "$dir/$script" --verbose > "$dir/out" 2>"$dir/err" ||
            { cat "$dir/err"; exit 1; }
        case $s in
        latency)
            echo "$p latency: input -> first (reduced) frame" \
                 "$(grep 'moving=1' "$dir/out" | median);" \
                 "settle -> full frame $(grep '^frame 1280x720.*moving=0' "$dir/out" | median)" ;;
        drag)
            echo "$p drag: $(grep '^stats' "$dir/out" | sed 's/ latency.*//')"
            echo "$p   last moving frame: $(grep 'moving=1' "$dir/out" | tail -1)"
            echo "$p   rest frame:        $(grep '^frame 1280x720' "$dir/out" | tail -1)" ;;
        drag-full)
            echo "$p drag without progressive quality:" \
                 "$(grep '^stats' "$dir/out" | sed 's/ latency.*//')" ;;
        esac
    done
done
