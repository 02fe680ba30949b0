#!/bin/sh
# run.sh — builds the libFuzzer targets with clang and runs each for SECONDS (default 60).
#
#   sh tests/fuzz/run.sh [SECONDS] [TARGET...]      (from the repository root; make fuzz)
#
# Targets: proto ply pcd las xyz lzf params ws laz copc cache splod frame e57 e57xml e57bits
# dispatch (default: all).
# dispatch links the whole server (its session, dispatch and render-thread code, on the real
# renderer) and tests/common/fuzz_dispatch.c; it needs `make` to have generated
# build/gen/shaders_gen.c and page_gen.c. Each fuzzer is
# build/fuzz/fuzz_<target>, built with -fsanitize=fuzzer,address,undefined from the sources it
# needs and tests/common/fuzz_targets.c (the bodies, shared with tests/test_fuzz_regress.c).
# Each runs niced on a copy of tests/fuzz/corpus/<target>/ (the seeds stay as they are), with
# tests/fuzz/<target>.dict when present. A crash, leak, timeout or out-of-memory input is saved
# to tests/fuzz/crashes/<target>/, where make test replays it from then on.
# Prints one line per target and exits non-zero when any target found something.
# Environment: CLANG (default clang), FUZZ_JOBS (parallel fuzzers, default 1),
# FUZZ_MAX_LEN (default 65536).
set -u
cd "$(dirname "$0")/../.." || exit 2

secs=${1:-60}
[ $# -gt 0 ] && shift
targets=${*:-proto ply pcd las xyz lzf params ws laz copc cache splod frame e57 e57xml e57bits dispatch}
CLANG=${CLANG:-clang}
max_len=${FUZZ_MAX_LEN:-65536}
out=build/fuzz

if ! command -v "$CLANG" >/dev/null 2>&1; then
    echo "fuzz: $CLANG not found; install clang (Debian: apt-get install clang) or set CLANG" >&2
    exit 2
fi

# ---- build: every source once into objects, then one link per target ----
CFLAGS="-std=c11 -D_GNU_SOURCE -g -O1 -fno-omit-frame-pointer -Wall -Wextra -Wno-unused-parameter
        -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined
        -Iprotocol $(for d in util io prep render pipelines enc net daemon cmd; do printf -- "-Iserver/%s " $d; done)-Iclient -Itests -Itests/common -Ibuild/gen -I/usr/include/OpenEXR"
SRCS="$(ls protocol/*.c) $(ls server/io/*.c) server/util/sd_err.c server/util/sd_hash.c server/util/sd_sigbus.c server/util/cachefile.c
      server/net/ws.c server/net/http.c tests/common/fuzz_copc.c
      $(ls server/prep/*.c) client/frame_decode.c tests/common/fuzz_targets.c tests/common/e57test.c"
LIBS="-lflann -lturbojpeg -llz4 -lxxhash -llzf -lcrypto -lexpat -lpthread -lm"
# The dispatch target: the rest of the server (all but its main), the embedded shaders.
# (ws.c and http.c are in SRCS already, for the ws target; server/mpi is the MPI binary's.)
DISPATCH_SRCS="$(ls server/*/*.c | grep -v -e '^server/cmd/main.c$' -e '^server/io/' -e '^server/prep/' \
                 -e '^server/util/' -e '^server/mpi/' -e '^server/net/ws.c$' -e '^server/net/http.c$') \
               build/gen/shaders_gen.c build/gen/page_gen.c tests/common/fuzz_dispatch.c"
DISPATCH_SRCS=$(echo $DISPATCH_SRCS) # one line, single spaces: the case below matches " $s "
DISPATCH_LIBS="$(pkg-config --libs egl opengl osmesa libpng libssl libcrypto) -lOpenEXRCore"
case " $targets " in
    *" dispatch "*)
        { [ -f build/gen/shaders_gen.c ] && [ -f build/gen/page_gen.c ]; } ||
            make build/gen/shaders_gen.c build/gen/page_gen.c >/dev/null ||
            { echo "fuzz: cannot generate build/gen/shaders_gen.c and page_gen.c" >&2; exit 2; }
        SRCS="$SRCS $DISPATCH_SRCS" ;;
esac
mkdir -p "$out/obj"
objs="" dobjs=""
for s in $SRCS; do
    o="$out/obj/$(echo "$s" | tr / _ | sed 's/\.c$/.o/')"
    # shellcheck disable=SC2046
    if [ ! -f "$o" ] || [ -n "$(find "$s" tests/fuzz/run.sh $(ls server/*/*.h protocol/*.h client/*.h \
            tests/common/*.h) -newer "$o" 2>/dev/null | head -n 1)" ]; then
        # shellcheck disable=SC2086
        $CLANG $CFLAGS -c "$s" -o "$o" || { echo "fuzz: compiling $s failed" >&2; exit 2; }
    fi
    case " $DISPATCH_SRCS " in *" $s "*) dobjs="$dobjs $o" ;; *) objs="$objs $o" ;; esac
done
for t in $targets; do
    src=tests/fuzz/fuzz_$t.c
    [ -f "$src" ] || { echo "fuzz: no target '$t' ($src)" >&2; exit 2; }
    # shellcheck disable=SC2086
    extra=""
    [ "$t" = dispatch ] && extra="$dobjs $DISPATCH_LIBS"
    $CLANG $CFLAGS -fsanitize=fuzzer "$src" $objs $extra $LIBS -o "$out/fuzz_$t" ||
        { echo "fuzz: linking fuzz_$t failed" >&2; exit 2; }
done

# ---- run ----
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
run_one() {
    t=$1
    work=$out/work/$t
    crashes=tests/fuzz/crashes/$t
    rm -rf "$work"
    mkdir -p "$work/corpus" "$crashes"
    [ -d "tests/fuzz/corpus/$t" ] && cp tests/fuzz/corpus/"$t"/* "$work/corpus/" 2>/dev/null
    seeds=$(ls "$work/corpus" | wc -l)
    dict=""
    [ -f "tests/fuzz/$t.dict" ] && dict="-dict=tests/fuzz/$t.dict"
    before=$(ls "$crashes" | wc -l)
    # shellcheck disable=SC2086
    nice -n 19 "$out/fuzz_$t" -max_len="$max_len" -max_total_time="$secs" -timeout=30 \
        -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$crashes/" $dict \
        "$work/corpus" > "$work/log" 2>&1
    rc=$?
    after=$(ls "$crashes" | wc -l)
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$work/log" | tail -n 1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$work/log" | tail -n 1)
    found=$((after - before))
    printf 'fuzz %-7s %10s execs %7s/s  corpus %3s -> %5s  crashes %s\n' "$t" "${execs:-?}" \
        "${rate:-?}" "$seeds" "$(ls "$work/corpus" | wc -l)" "$found"
    if [ "$rc" -ne 0 ] || [ "$found" -ne 0 ]; then
        echo "    fuzz_$t exited $rc; new files in $crashes/:"
        ls -t "$crashes" | head -n "$((found > 0 ? found : 1))" | sed 's/^/      /'
        if [ -n "$execs" ]; then
            grep -E 'ERROR|SUMMARY|fuzz oracle|runtime error|^    #[0-9]' "$work/log" |
                head -n 25 | sed 's/^/    | /'
        else
            tail -n 5 "$work/log" | sed 's/^/    | /'
        fi
        echo "    full log: $work/log"
        return 1
    fi
    [ "$after" -eq 0 ] && rmdir "$crashes" 2>/dev/null
    return 0
}

status=0
jobs=${FUZZ_JOBS:-1}
if [ "$jobs" -le 1 ]; then
    for t in $targets; do run_one "$t" || status=1; done
else
    # Parallel: each target in the background, at most $jobs at a time; results on disk.
    mkdir -p "$out/status"
    running=0
    for t in $targets; do
        (run_one "$t" > "$out/status/$t.txt"; echo $? > "$out/status/$t.rc") &
        running=$((running + 1))
        if [ "$running" -ge "$jobs" ]; then wait; running=0; fi
    done
    wait
    for t in $targets; do
        cat "$out/status/$t.txt"
        [ "$(cat "$out/status/$t.rc")" = 0 ] || status=1
    done
fi
rmdir tests/fuzz/crashes 2>/dev/null
[ "$status" -eq 0 ] && echo "fuzz: no crashes" || echo "fuzz: crashes found (see above)"
exit "$status"
