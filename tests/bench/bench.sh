#!/bin/sh
# make bench: runs every tests/bench/bench_*.sh in order and prints their tables.
# Each part prints Markdown table rows; README.md quotes the latest output.
set -eu
here=$(dirname "$0")
echo "# splatd bench — $(date -u +%Y-%m-%dT%H:%MZ)"
echo "machine: $(nproc) cores, $(awk '/model name/{$1=$2=$3="";print;exit}' /proc/cpuinfo | sed 's/^ *//'), $(free -g | awk '/Mem:/{print $2}') GiB"
for part in "$here"/bench_*.sh; do
    [ -f "$part" ] || continue
    echo
    sh "$part"
done
