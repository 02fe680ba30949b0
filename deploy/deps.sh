#!/bin/sh
# deps.sh — the Debian packages splatd needs to build, test and run (`make`, `make test`,
# `make fuzz-smoke`, `make run`), and nothing else.
#
#   sh deploy/deps.sh           install what is missing (idempotent: apt-get is called only
#                               when a package is absent)
#   sh deploy/deps.sh --check   print "WHAT (Debian package PKG)" for each pkg-config module or
#                               file the build needs that this machine lacks; exit 1 if any
#
# The Makefile runs --check before building, runs this script when something is missing, and
# stops naming the module and its package when it is still missing afterwards.
set -eu

# Each entry: how the build finds it (pc:MODULE for pkg-config, file:PATH, or tool:NAME) and the
# package that provides it.
arch=$(${CC:-cc} -print-multiarch 2>/dev/null || dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || echo x86_64-linux-gnu)
NEEDS="
tool:make=make
tool:cc=gcc
tool:pkg-config=pkg-config
pc:egl=libegl-dev
pc:opengl=libopengl-dev
file:/usr/include/GL/glcorearb.h=libgl-dev
file:/usr/share/glvnd/egl_vendor.d/50_mesa.json=libegl-mesa0
file:/usr/lib/$arch/dri/swrast_dri.so=libgl1-mesa-dri
pc:osmesa=libosmesa6-dev
file:/usr/include/flann/flann.h=libflann-dev
pc:libturbojpeg=libturbojpeg0-dev
file:/usr/include/OpenEXR/openexr.h=libopenexr-dev
pc:libpng=libpng-dev
pc:liblz4=liblz4-dev
pc:libcrypto=libssl-dev
pc:libssl=libssl-dev
pc:libxxhash=libxxhash-dev
pc:liblzf=liblzf-dev
pc:expat=libexpat1-dev
pc:cmocka=libcmocka-dev
pc:sdl2=libsdl2-dev
file:/usr/bin/Xvfb=xvfb
file:/usr/bin/xwd=x11-apps
file:/usr/lib/python3/dist-packages/yaml/__init__.py=python3-yaml
tool:mpicc=libopenmpi-dev
tool:mpirun=openmpi-bin
file:/usr/bin/time=time
"
# CI's fuzz smoke run (make fuzz-smoke, tests/fuzz/run.sh): clang 14 and its libFuzzer and
# sanitizer runtimes.
NEEDS="$NEEDS
tool:clang-14=clang-14
file:/usr/lib/llvm-14/lib/clang/14.0.6/lib/linux/libclang_rt.fuzzer-${arch%%-*}.a=libclang-rt-14-dev
"
# Tests only: the browser viewer's end-to-end test (tests/test_browser.c) drives headless
# Chromium through chromedriver; it skips, naming the package, where they are absent.
NEEDS="$NEEDS
file:/usr/bin/chromium=chromium
file:/usr/bin/chromedriver=chromium-driver
"

# present ENTRY: 0 when the thing the entry names is on this machine.
present() {
    k=${1%%=*}
    w=${k#*:}
    case $k in
        pc:*) command -v pkg-config >/dev/null 2>&1 && pkg-config --exists "$w" ;;
        file:*) test -e "$w" ;;
        tool:*) command -v "$w" >/dev/null 2>&1 ;;
    esac
}

if [ "${1:-}" = "--check" ]; then
    rc=0
    for e in $NEEDS; do
        if ! present "$e"; then
            k=${e%%=*}
            echo "${k#*:} (Debian package ${e#*=})"
            rc=1
        fi
    done
    exit $rc
fi

missing=""
for e in $NEEDS; do
    p=${e#*=}
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
       ! present "$e"; then
        case " $missing " in *" $p "*) ;; *) missing="$missing $p" ;; esac
    fi
done

if [ -z "$missing" ]; then
    echo "deps.sh: all packages present" >&2
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
        echo "deps.sh: need root (or sudo) to install:$missing" >&2
        exit 1
    fi
fi

echo "deps.sh: installing:$missing" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq >&2
# shellcheck disable=SC2086
$SUDO apt-get install -y -qq --no-install-recommends $missing >&2
