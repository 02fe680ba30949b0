#!/bin/sh
# dev_archive.sh — tolerant library build for single-target development builds.
#
# When several people edit the tree at once, one half-written file must not stop everyone else
# from building their own test. For goals other than all/test/asan/bench/run/install, the
# Makefile builds each library through this script: it compiles every out-of-date source,
# prints the errors of those that fail and leaves them out of the archive. The full build
# (make, make test, CI) never uses it and fails on the first error.
#
# usage: dev_archive.sh "CC FLAGS" OBJROOT ARCHIVE SRC...
cc=$1; objroot=$2; archive=$3; shift 3
objs=""
for src in "$@"; do
    obj="$objroot/obj/${src%.c}.o"
    case "$src" in "$objroot"/*|build/*) obj="$objroot/obj/gen/$(basename "${src%.c}").o";; esac
    dep="${obj%.o}.d"
    stale=0
    if [ ! -f "$obj" ] || [ "$src" -nt "$obj" ]; then
        stale=1
    elif [ -f "$dep" ]; then
        for f in $(sed -e 's/^[^:]*://' -e 's/\\$//' "$dep" | tr ' ' '\n' | grep -v ':$' | sort -u); do
            [ -f "$f" ] && [ "$f" -nt "$obj" ] && { stale=1; break; }
        done
    fi
    if [ $stale = 1 ]; then
        mkdir -p "$(dirname "$obj")"
        if ! $cc -c "$src" -o "$obj" 2> "$obj.err"; then
            echo "dev build: $src does not compile, left out of $(basename "$archive"):" >&2
            head -20 "$obj.err" >&2
            rm -f "$obj"
        fi
        rm -f "$obj.err"
    fi
    [ -f "$obj" ] && objs="$objs $obj"
done
rm -f "$archive"
# shellcheck disable=SC2086
ar rcs "$archive" $objs
