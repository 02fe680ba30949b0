#!/bin/sh
# bench_farm.sh — beyond one machine (part of `make bench`; issue 17), on loopback with
# tests/data/Guanyin.ply at 1280x720:
#   farm       frames/s of one daemon rendering a camera path, against 2 shards on 2 daemons
#              (each shard a `splat path --shard I/2` of its own);
#   sort-last  `splatd --mpi` under mpirun -np 1..4 (skipped without mpirun/splatd-mpi):
#              frames/s of a camera path (one frame in flight), the compositing time per
#              frame (rank 0's median), the bytes each rank sends per frame, and each rank's
#              resident memory after loading (points, splat, soft; SPLATD_BENCH_MPI_PIPES
#              picks some).
# All processes share this machine's cores: the numbers measure overheads, not speed-ups.
# Also the ranks' parts (partition.h), no MPI needed: Guanyin.ply and bun000.ply into N = 2, 3,
# 4, 7 parts by the earlier median cuts and by the octree-cell kd tree splatd --mpi uses, each
# part's share of the points and of the footprint proxy (sum of pi r^2 over its splats) and
# the imbalance max/mean of both; for Guanyin at N = 2..4 also each part rendered alone
# (points, splat; 1280x720): its covered pixels and render time, max/mean (part_bench.c).
set -eu
bin=${SPLATD_BIN:-build/bin/splatd}
splat=${SPLAT_BIN:-build/bin/splat}
data=${SPLATD_TESTDATA:-tests/data}
frames=${SPLATD_BENCH_FARM_FRAMES:-36}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-bench-farm.XXXXXX")
pids=""
cleanup() {
    for p in $pids; do kill "$p" 2>/dev/null || true; done
    for p in $pids; do wait "$p" 2>/dev/null || true; done
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM
mkdir -p "$tmp/data"
cp "$data/Guanyin.ply" "$data/bun000.ply" "$tmp/data/"
"$bin" prep "$tmp/data/Guanyin.ply" --cache "$tmp/cache" --quiet

# wait_port FILE PID: waits for the port file of a starting daemon.
wait_port() {
    i=0
    while [ ! -s "$1" ]; do
        i=$((i + 1))
        if [ $i -gt 600 ] || ! kill -0 "$2" 2>/dev/null; then
            echo "bench_farm: a daemon did not start" >&2; cat "$tmp"/*.log >&2; exit 1
        fi
        sleep 0.1
    done
    cat "$1"
}
# fps LOG: frames/s and server render/encode ms from a `splat path` summary line.
fps() {
    sed -n 's/.* frames in \([0-9.]*\) s (\([0-9.]*\) frames\/s.*server render \([0-9.]*\) ms, encode \([0-9.]*\) ms.*/\1 \2 \3 \4/p' "$1" | tail -1
}

echo "## farm: one daemon vs 2 shards on 2 daemons (loopback, Guanyin.ply, 1280x720 JPEG, $frames frames, $(nproc) cores shared)"
echo
echo "| pipeline | 1 daemon frames/s | 2 shards on 2 daemons, frames/s | ratio | server render + encode ms/frame (1 daemon) |"
echo "|---|---:|---:|---:|---:|"
for k in a b; do
    "$bin" --listen 127.0.0.1:0 --port-file "$tmp/port-$k" --data "$tmp/data" --cache "$tmp/cache" \
        --preload Guanyin 2>"$tmp/farm-$k.log" &
    pids="$pids $!"
    eval "port_$k=\$(wait_port \"$tmp/port-$k\" $!)"
done
for pipe in points splat; do
    rm -rf "$tmp/one" "$tmp/two"
    for p in "$port_a" "$port_b"; do # warm-up: each daemon compiles the pipeline's programs
        "$splat" -q --port "$p" path Guanyin --orbit 2 --size 1280x720 --set pipeline=$pipe \
            -o "$tmp/warm-$p-$pipe/%04d.jpg"
    done
    "$splat" --port "$port_a" path Guanyin --orbit "$frames" --size 1280x720 --set pipeline=$pipe \
        -o "$tmp/one/%04d.jpg" 2>"$tmp/one.txt"
    t0=$(date +%s.%N)
    "$splat" --port "$port_a" path Guanyin --orbit "$frames" --size 1280x720 --set pipeline=$pipe \
        --shard 0/2 -o "$tmp/two/%04d.jpg" 2>"$tmp/s0.txt" &
    s0=$!
    "$splat" --port "$port_b" path Guanyin --orbit "$frames" --size 1280x720 --set pipeline=$pipe \
        --shard 1/2 -o "$tmp/two/%04d.jpg" 2>"$tmp/s1.txt"
    wait $s0
    t1=$(date +%s.%N)
    set -- $(fps "$tmp/one.txt")
    one=$2; ren=$3; enc=$4
    two=$(echo "$frames $t0 $t1" | awk '{printf "%.1f", $1 / ($3 - $2)}')
    echo "| $pipe | $one | $two | $(echo "$two $one" | awk '{printf "%.2f", $1 / $2}') | $ren + $enc |"
done
for p in $pids; do kill -TERM "$p"; wait "$p" || true; done
pids=""
echo
echo "Cost model: a frame costs t = render + read-back + encode on its daemon plus transfer and"
echo "decode on the client; N daemons on N machines give N / t frames/s until the clients' network"
echo "or the shared file system limits, after each daemon's one-time load (prep from the shared"
echo "cache: mmap). Here both daemons share $(nproc) cores, so 2 shards cannot beat one daemon."

# ---- the ranks' parts (no MPI needed) ----
part_bench=${SPLATD_BENCH:-$(dirname "$bin")/../bench}/part_bench
if [ -x "$part_bench" ]; then
    for cloud in Guanyin bun000; do
        echo
        echo "## partition: $cloud.ply into N parts, median cuts (before) vs octree cells (splatd --mpi); footprint = sum of pi r^2"
        echo
        render=""
        [ "$cloud" = Guanyin ] && render="--render 2,3,4"
        "$part_bench" "$tmp/data/$cloud.ply" --cache "$tmp/cache" --parts 2,3,4,7 $render
    done
else
    echo
    echo "(partition: skipped, $part_bench not built)"
fi

# ---- sort-last over MPI ----
mpi_bin=$(dirname "$bin")/splatd-mpi
if ! command -v mpirun >/dev/null 2>&1 || [ ! -x "$mpi_bin" ]; then
    echo
    echo "(sort-last: skipped, mpirun or $mpi_bin missing)"
    exit 0
fi
root=""
[ "$(id -u)" = 0 ] && root="--allow-run-as-root"
mframes=${SPLATD_BENCH_MPI_FRAMES:-10}
echo
echo "## sort-last: splatd --mpi, mpirun -np N (loopback, Guanyin.ply, 1280x720 JPEG, $mframes frames, one in flight; all ranks share $(nproc) cores)"
echo
echo "| pipeline | np | frames/s | compositing ms/frame (median) | MiB sent per frame, per rank | resident MiB per rank after load |"
echo "|---|---:|---:|---:|---|---|"
# the frame counts in the ranks' logs include the 2 warm-up frames; soft (model=express, its
# defaults) composites the ranks' RGBA with "over" in their boxes' order (server/mpi/over.h)
for pipe in ${SPLATD_BENCH_MPI_PIPES:-points splat soft}; do
    for np in 1 2 3 4; do
        log="$tmp/mpi-$pipe-$np.log"
        rm -f "$tmp/port-mpi"
        mpirun --oversubscribe $root -np "$np" "$bin" --mpi --listen 127.0.0.1:0 \
            --port-file "$tmp/port-mpi" --data "$tmp/data" --cache "$tmp/cache" \
            --preload Guanyin >"$log" 2>&1 &
        mp=$!
        pids="$mp"
        port=$(wait_port "$tmp/port-mpi" "$mp")
        rm -rf "$tmp/mpi"
        # warm-up (the pipelines' programs are compiled on each rank's first frame)
        "$splat" -q --port "$port" path Guanyin --orbit 2 --size 1280x720 \
            --set pipeline=$pipe -o "$tmp/warm/%04d.jpg"
        "$splat" --port "$port" path Guanyin --orbit "$mframes" --size 1280x720 \
            --set pipeline=$pipe --inflight 1 -o "$tmp/mpi/%04d.jpg" 2>"$tmp/mpi.txt"
        # rank 0 (OMPI_COMM_WORLD_RANK=0 among mpirun's children) stops, then the workers
        r0=""
        for c in $(pgrep -P "$mp"); do
            tr '\0' '\n' < "/proc/$c/environ" 2>/dev/null | grep -qx OMPI_COMM_WORLD_RANK=0 && r0=$c
        done
        kill -TERM "${r0:-$mp}"
        wait "$mp" || true
        pids=""
        set -- $(fps "$tmp/mpi.txt")
        f=$2
        comp=$(sed -n 's/.*rank 0 of .*compositing median \([0-9.]*\) ms.*/\1/p' "$log")
        sent=$(awk '/frames, .*MiB sent compositing/ {
                        for (i = 1; i <= NF; i++) {
                            if ($i == "rank") r = $(i + 1)
                            if ($i == "frames,") n = $(i - 1)
                            if ($i == "MiB" && $(i + 1) == "sent") m = $(i - 1)
                        }
                        out[r] = sprintf("%.1f", n ? m / n : 0) }
                    END { s = ""; for (r = 0; r < 64; r++) if (r in out) s = s (s ? " / " : "") out[r]; print s }' "$log")
        mem=$(awk '/points, resident/ { for (i = 1; i <= NF; i++) { if ($i == "rank") r = $(i+1); if ($i == "resident") m = $(i+1) } out[r] = m }
                   END { s = ""; for (r = 0; r < 64; r++) if (r in out) s = s (s ? " / " : "") out[r]; print s }' "$log")
        echo "| $pipe | $np | $f | $comp | $sent | $mem |"
    done
done
