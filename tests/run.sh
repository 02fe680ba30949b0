#!/usr/bin/env bash
# run.sh — runs the test programs listed in tests/list, several at a time, one line each as it
# ends, then the tests counted over all of them:
#
#   LABEL: N passed, N failed, N skipped (W s wall)
#
# usage: run.sh LABEL BINDIR [PROGRAM[:PATTERN] ...]
#   With no PROGRAM, every program of tests/list runs; PATTERN (cmocka's filter, '*' and '?')
#   picks tests inside a program (make test T='test_lod:test_octree*').
#
# tests/list is the one list of programs: a name, a time limit in seconds for the plain build,
# and flags. `alone` marks a program that measures time or loads every core: it runs with no
# other program beside it. Every built tests/test_* must be listed (and every listed one built):
# a program missing from the list fails the run. Programs start longest limit first.
# Environment: TEST_JOBS (programs at a time, default: cores + 1, since most programs wait on
# sockets and child processes), TEST_TIMEOUT_SCALE (multiplies every limit; make asan sets 3),
# TEST_LIST (another list, for tests of this runner), TEST_LOGS (keep the logs there), TEST_TOTALS (append "passed failed skipped" to that file).
#
# Tests are counted from cmocka's lines ([ OK ], [ FAILED ], [ ERROR ], [ SKIPPED ]); a program
# that dies, runs past its limit, or fails after its tests (a leak report at exit) counts as one
# failed test besides. A skipped test must name why the check is impossible on this machine
# (TU_SKIP in tests/common/testutil.h prints "tu-skip-reason: ..." inside the test): a skip with
# no reason is a failure, and the reasons are listed before the closing line. A failing
# program's output is shown; logs are kept in $TEST_LOGS (default: a temporary directory,
# removed when all pass). Exit status is non-zero when any test or program fails.
set -u
label=$1 bindir=$2; shift 2
here=$(cd "$(dirname "$0")" && pwd)
list=${TEST_LIST:-$here/list}
scale=${TEST_TIMEOUT_SCALE:-1}
jobs=${TEST_JOBS:-$(( $(nproc) + 1 ))}
logdir=${TEST_LOGS:-${TMPDIR:-/tmp}/splatd-test-logs.$$}
mkdir -p "$logdir"
: > "$logdir/skip-reasons"
t0=$(date +%s)

declare -A limit alone
order=()
while read -r name secs flags; do
    case "$name" in ''|'#'*) continue ;; esac
    limit[$name]=$secs; alone[$name]=0
    [ "$flags" = alone ] && alone[$name]=1
    order+=("$name")
done < "$list"

# What to run: the named programs, or the whole list (sorted by limit, longest first).
sel=() pat=()
if [ $# -gt 0 ]; then
    for a in "$@"; do
        n=${a%%:*}; n=$(basename "$n")
        [ -n "${limit[$n]:-}" ] || { echo "$label: $n is not in tests/list" >&2; exit 2; }
        sel+=("$n"); if [ "$a" != "${a#*:}" ]; then pat+=("${a#*:}"); else pat+=(""); fi
    done
else
    missing=0
    for b in "$bindir"/test_*; do
        [ -x "$b" ] || continue
        n=$(basename "$b")
        if [ -z "${limit[$n]:-}" ]; then
            echo "$label: $b is not in tests/list: add it with a time limit" >&2; missing=1
        fi
    done
    [ "$missing" -eq 0 ] || exit 2
    while read -r n; do sel+=("$n"); pat+=(""); done < <(
        for n in "${order[@]}"; do echo "${limit[$n]} $n"; done | sort -rn | cut -d' ' -f2)
fi

# run_one NAME PATTERN: runs one program under its limit and writes NAME.res: the status, the
# seconds, and the passed / failed / skipped counts.
run_one() {
    local name=$1 p=$2 log="$logdir/$1.log" lim start rc st ok bad sk finished
    lim=$(awk -v s="${limit[$1]}" -v k="$scale" 'BEGIN { printf "%d", s * k + 0.5 }')
    start=$(date +%s)
    if [ -n "$p" ]; then timeout --kill-after=10 "$lim" "$bindir/$name" "$p" > "$log" 2>&1
    else timeout --kill-after=10 "$lim" "$bindir/$name" > "$log" 2>&1; fi
    rc=$?
    # cmocka names a failed or skipped test twice (as it happens and in the closing list), so
    # tests are counted once by name; awk pairs each SKIPPED with the reason lines printed since
    # that test's RUN line.
    read -r ok bad sk <<COUNTS
$(awk -v reasons="$logdir/skip-reasons" -v bin="$name" '
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
    st=ok; finished=0
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
        st=FAIL; bad=1                      # ran no test at all (a pattern that matches none)
    fi
    echo "$st $(( $(date +%s) - start )) $ok $bad $sk $lim" > "$logdir/$name.res"
}

# report NAME: prints the line of a finished program (and its log's tail when it failed) and
# adds its counts up.
pass=0 fail=0 skipped=0 badbins=0
report() {
    local name=$1 st secs ok bad sk lim
    read -r st secs ok bad sk lim < "$logdir/$name.res"
    pass=$((pass + ok)); fail=$((fail + bad)); skipped=$((skipped + sk))
    [ "$st" = ok ] || badbins=$((badbins + 1))
    printf '%-6s %-7s %-28s %4ss  %3d passed' "$label" "$st" "$name" "$secs" "$ok"
    [ "$bad" -ne 0 ] && printf ', %d failed' "$bad"
    [ "$sk" -ne 0 ] && printf ', %d skipped' "$sk"
    printf '\n'
    if [ "$st" != ok ]; then
        [ "$st" = TIMEOUT ] && echo "    | (killed after ${lim}s: tests/list sets the limit)"
        sed 's/^/    | /' "$logdir/$name.log" | tail -60
    fi
}

declare -A running=()
# reap: waits for one running program to end and reports every one that has.
reap() {
    local n done=0
    while :; do
        for n in "${!running[@]}"; do
            if [ -f "$logdir/$n.res" ]; then report "$n"; unset "running[$n]"; done=1; fi
        done
        [ "$done" = 1 ] && return
        wait -n 2>/dev/null || sleep 0.2
    done
}
for i in "${!sel[@]}"; do
    n=${sel[$i]}
    rm -f "$logdir/$n.res"
    if [ "${alone[$n]}" = 1 ]; then
        while [ ${#running[@]} -gt 0 ]; do reap; done
        run_one "$n" "${pat[$i]}"; report "$n"
        continue
    fi
    while [ ${#running[@]} -ge "$jobs" ]; do reap; done
    run_one "$n" "${pat[$i]}" &
    running[$n]=$!
done
while [ ${#running[@]} -gt 0 ]; do reap; done

if [ -s "$logdir/skip-reasons" ]; then
    echo "$label: skips, with the reason each check is impossible on this machine:"
    sed 's/^/    /' "$logdir/skip-reasons"
fi
if [ "$badbins" -eq 0 ] && [ -z "${TEST_LOGS:-}" ]; then rm -rf "$logdir"; else echo "$label: logs in $logdir"; fi
wall=$(( $(date +%s) - t0 ))
echo "$label: $pass passed, $fail failed, $skipped skipped (${wall} s wall)"
[ -n "${TEST_TOTALS:-}" ] && echo "$pass $fail $skipped $wall" >> "$TEST_TOTALS"
[ "$fail" -eq 0 ]
