#!/bin/sh
# ab_render.sh — the same rendering benchmark for two builds, interleaved, so a change is judged
# against the code before it on the same machine in the same minutes (frame times on a shared
# 2-core VM move by +-15 % between runs; interleaving spreads that over both).
#
#   sh tests/bench/ab_render.sh OLD_BENCH NEW_BENCH FILE [ROUNDS] [render_bench options...]
#
# OLD_BENCH and NEW_BENCH are render_bench binaries (e.g. a worktree of the old commit built with
# `make BUILD=/tmp/old build...`). Each round runs OLD then NEW (then NEW then OLD in the next
# round) with --frames 10 on FILE; the table gives, per pipeline, the median over rounds of each
# build's median frame time and of its CPU time per frame (steadier on a shared machine), and
# new / old. Extra arguments go to both (e.g. --zoom 3).
set -eu
old=${1:?usage: ab_render.sh OLD_BENCH NEW_BENCH FILE [ROUNDS] [options]}
new=${2:?usage: ab_render.sh OLD_BENCH NEW_BENCH FILE [ROUNDS] [options]}
file=${3:?usage: ab_render.sh OLD_BENCH NEW_BENCH FILE [ROUNDS] [options]}
rounds=${4:-4}
[ $# -ge 4 ] && shift 4 || shift $#
tmp=$(mktemp -d "${TMPDIR:-/tmp}/splatd-ab.XXXXXX")
trap 'rm -rf "$tmp"' EXIT

# one BIN TAG: appends "pipeline wall-ms cpu-ms" lines (render_bench's median wall time, and the
# process CPU time per frame it prints on stderr) to $tmp/TAG.
one() {
    bin=$1 tag=$2
    shift 2
    "$bin" "$file" --frames 10 --size 1280x720 --pipelines points,splat --label ab "$@" \
        > "$tmp/out" 2> "$tmp/err" || true
    for p in points splat; do
        w=$(awk -v p=$p '$1 == "|" && $6 == p { print $8 }' "$tmp/out")
        c=$(awk -v p=$p '$1 == "cpu:" && $3 == p { print $4 }' "$tmp/err")
        [ -n "$w" ] && echo "$p $w ${c:-0}" >> "$tmp/$tag"
    done
}
i=0
while [ $i -lt "$rounds" ]; do
    if [ $((i % 2)) -eq 0 ]; then
        one "$old" old "$@"; one "$new" new "$@"
    else
        one "$new" new "$@"; one "$old" old "$@"
    fi
    i=$((i + 1))
done
med() { sort -n | awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }'; }
echo "| pipeline | old wall ms | new wall ms | new / old | old CPU ms | new CPU ms | new / old |"
echo "|---|---|---|---|---|---|---|"
for p in points splat; do
    ow=$(awk -v p=$p '$1 == p { print $2 }' "$tmp/old" | med)
    nw=$(awk -v p=$p '$1 == p { print $2 }' "$tmp/new" | med)
    oc=$(awk -v p=$p '$1 == p { print $3 }' "$tmp/old" | med)
    nc=$(awk -v p=$p '$1 == p { print $3 }' "$tmp/new" | med)
    echo "| $p | $ow | $nw | $(awk -v a="$nw" -v b="$ow" 'BEGIN { printf "%.3f", a / b }') | $oc | $nc | $(awk -v a="$nc" -v b="$oc" 'BEGIN { printf "%.3f", a / b }') |"
done
