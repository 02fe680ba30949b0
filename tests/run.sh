#!/bin/sh
# run.sh — runs test binaries, one line per binary, then the tests counted over all of them:
#
#   LABEL: N passed, N failed, N skipped
#
# Each binary runs under a time limit ($TEST_TIMEOUT seconds, default 300): a hang fails that
# binary instead of stalling CI. Tests are counted from cmocka's lines ([ OK ], [ FAILED ],
# [ ERROR ], [ SKIPPED ]); a binary that dies, times out, or fails after its tests (a leak
# report at exit) counts as one failed test besides.
# A skipped test must name why the check is impossible on this machine (TU_SKIP in
# tests/common/testutil.h prints "tu-skip-reason: ..." inside the test): a skip with no reason
# is a failure, and the reasons are listed before the closing line. A failing binary's output
# is shown; logs are kept in $TEST_LOGS (default: a temporary directory, removed when all pass).
# Exit status is non-zero when any test or binary fails.
#
# With $TEST_TOTALS set, "passed failed skipped" is appended to that file (make test adds the
# plain and sanitizer runs up into one closing line).
#
# usage: run.sh LABEL BIN...
label=$1; shift
limit=${TEST_TIMEOUT:-300}
pass=0; fail=0; skipped=0; badbins=0
logdir=${TEST_LOGS:-${TMPDIR:-/tmp}/splatd-test-logs.$$}
mkdir -p "$logdir"
reasons="$logdir/skip-reasons"
: > "$reasons"
for t in "$@"; do
    name=$(basename "$t")
    log="$logdir/$name.log"
    start=$(date +%s)
    timeout --kill-after=10 "$limit" "$t" > "$log" 2>&1
    rc=$?
    # Per-test counts, and skips with and without a reason (awk pairs each SKIPPED with the
    # reason lines printed since that test's RUN line).
    # cmocka names a failed or skipped test twice (as it happens and in the closing list), so
    # tests are counted once by name.
    read -r ok bad sk <<COUNTS
$(awk -v reasons="$reasons" -v bin="$name" '
        /^\[ RUN      \] / { why[$NF] = ""; cur = $NF; next }
        /^tu-skip-reason: / { sub(/^tu-skip-reason: /, ""); why[cur] = $0; next }
        /^\[       OK \] / { ok[$NF] = 1; next }
        /^\[  (FAILED  |ERROR   )\] [A-Za-z_][A-Za-z0-9_]*$/ { bad[$NF] = 1; next }
        /^\[  SKIPPED \] [A-Za-z_][A-Za-z0-9_]*$/ { sk[$NF] = 1; next }
        END {
            nok = 0; nbad = 0; nsk = 0
            for (t in ok) nok++
            for (t in bad) nbad++
            for (t in sk) {
                if (why[t] == "") {
                    nbad++
                    printf "%s %s: skipped WITHOUT a reason (a failure: use TU_SKIP)\n", bin, t >> reasons
                } else {
                    nsk++
                    printf "%s %s: %s\n", bin, t, why[t] >> reasons
                }
            }
            printf "%d %d %d\n", nok, nbad, nsk
        }' "$log")
COUNTS
    st=ok
    finished=0
    grep -q '^\[==========\] [0-9]* test(s) run\.' "$log" && finished=1
    if [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ]; then
        st=TIMEOUT; bad=$((bad + 1))
    elif [ "$finished" -eq 0 ]; then
        st=DIED; bad=$((bad + 1))           # crashed or exited before cmocka's summary
    elif [ "$rc" -ne 0 ] && [ "$bad" -eq 0 ]; then
        st=FAIL; bad=1                      # failed after the tests (a leak report at exit)
    elif [ "$bad" -ne 0 ]; then
        st=FAIL
    elif [ "$ok" -eq 0 ] && [ "$sk" -eq 0 ]; then
        st=FAIL; bad=1                      # ran no test at all
    fi
    pass=$((pass + ok)); fail=$((fail + bad)); skipped=$((skipped + sk))
    [ "$st" = ok ] || badbins=$((badbins + 1))
    printf '%-6s %-7s %-28s %4ss  %3d passed' "$label" "$st" "$name" "$(( $(date +%s) - start ))" "$ok"
    [ "$bad" -ne 0 ] && printf ', %d failed' "$bad"
    [ "$sk" -ne 0 ] && printf ', %d skipped' "$sk"
    printf '\n'
    if [ "$st" != ok ]; then
        [ "$st" = TIMEOUT ] && echo "    | (killed after ${limit}s; TEST_TIMEOUT sets the limit)"
        sed 's/^/    | /' "$log" | tail -60
    fi
done
if [ -s "$reasons" ]; then
    echo "$label: skips, with the reason each check is impossible on this machine:"
    sed 's/^/    /' "$reasons"
fi
if [ "$badbins" -eq 0 ] && [ -z "${TEST_LOGS:-}" ]; then rm -rf "$logdir"; else echo "$label: logs in $logdir"; fi
echo "$label: $pass passed, $fail failed, $skipped skipped"
[ -n "${TEST_TOTALS:-}" ] && echo "$pass $fail $skipped" >> "$TEST_TOTALS"
[ "$fail" -eq 0 ]
