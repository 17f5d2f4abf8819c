#!/bin/sh
# Installs the Debian 12 packages that stillheart's build, tests and benchmarks need.
# Idempotent: packages already present are skipped without touching apt at all.
#   scripts/install-deps.sh          build + tests
#   scripts/install-deps.sh --bench  also OpenCV (benchmark peer)
set -eu

pkgs="build-essential pkg-config libcmocka-dev libqhull-dev libeigen3-dev libpng-dev
      libopencv-core-dev libopencv-imgproc-dev clang llvm libclang-rt-14-dev
      libosmesa6-dev libapriltag-dev libopencv-calib3d-dev libturbojpeg0-dev"
for arg in "$@"; do
    case "$arg" in
        --bench) ;;   # the bench peer (cv::remap) lives in opencv-imgproc, already listed
        *) echo "install-deps: unknown option '$arg'" >&2; exit 2 ;;
    esac
done

missing=""
for p in $pkgs; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing="$missing $p"
    fi
done
[ -z "$missing" ] && exit 0

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 || { echo "install-deps: need root or sudo to install:$missing" >&2; exit 1; }
    SUDO="sudo"
fi
echo "install-deps: installing$missing" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# shellcheck disable=SC2086
$SUDO apt-get install -y -qq --no-install-recommends $missing >&2
