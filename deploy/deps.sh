#!/bin/sh
# Installs the Debian packages splatd needs to build, test and run.
# Idempotent: packages already present are left alone and apt-get is not called.
set -eu

PKGS="make gcc pkg-config
libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri libosmesa6-dev
libflann-dev libturbojpeg0-dev libopenexr-dev libpng-dev liblz4-dev
libssl-dev libcmocka-dev"

missing=""
for p in $PKGS; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing="$missing $p"
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
