#!/bin/sh
# Runs each test binary given, prints one line per binary and a closing summary line
# "N passed, N failed". Exit status is non-zero when any binary fails.
# usage: run.sh LABEL BIN...
label=$1; shift
pass=0; fail=0; failed=""
logdir=${TMPDIR:-/tmp}/splatd-test-logs.$$
mkdir -p "$logdir"
for t in "$@"; do
    name=$(basename "$t")
    start=$(date +%s)
    if "$t" > "$logdir/$name.log" 2>&1; then
        pass=$((pass + 1)); st=ok
    else
        fail=$((fail + 1)); st=FAIL; failed="$failed $name"
    fi
    printf '%-6s %-5s %-28s %4ss\n' "$label" "$st" "$name" "$(( $(date +%s) - start ))"
    if [ "$st" = FAIL ]; then sed 's/^/    | /' "$logdir/$name.log" | tail -60; fi
done
rm -rf "$logdir"
echo "$label: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
