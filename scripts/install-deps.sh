#!/bin/sh
# Installs the Debian 12 packages that stillheart's build, tests and benchmarks need.
# Idempotent: packages already present are skipped without touching apt at all.
#   scripts/install-deps.sh          build + tests
#   scripts/install-deps.sh --bench  also OpenCV (benchmark peer) and its Python binding (the
#                                    whole-process peer of `stillheart warp`, bench_warp_process)
#   scripts/install-deps.sh --profile  also perf (linux-perf), for the before/after profiles the
#                                    issues ask for (docs/warp.md)
#   scripts/install-deps.sh --vm     also what make vmtest's host side uses (tests/vm/run.sh installs
#                                    them itself when missing): QEMU, busybox, and GStreamer's
#                                    gst-launch-1.0 with v4l2src, which the guest runs on the
#                                    daemon's v4l2loopback output
#   scripts/install-deps.sh --arm64  also the aarch64 cross build and its tests under emulation:
#                                    arm64 multiarch, crossbuild-essential-arm64, qemu-user, the
#                                    arm64 -dev packages, and libapriltag-dev:arm64 unpacked into
#                                    $ARM64_CACHE (it cannot co-install with the amd64 one)
set -eu
arm64=0
bench=0
profile=0
vm=0
ARM64_CACHE="${ARM64_CACHE:-/var/cache/stillheart/arm64}"

pkgs="build-essential pkg-config libcmocka-dev libqhull-dev libeigen3-dev libkissfft-dev libpng-dev
      libopencv-core-dev libopencv-imgproc-dev clang llvm libclang-rt-14-dev
      libosmesa6-dev libapriltag-dev libopencv-calib3d-dev libturbojpeg0-dev libgpiod-dev libcamera-dev
      libinih-dev libsystemd-dev python3 strace groff-base ffmpeg libdrm-dev libopencv-video-dev"
# ffmpeg: the README's "Stabilize your own video" runs through it, and test_readme_video runs that
# section as written (37 packages, about 27 MB to download on Debian 12: the price of a README
# that is known to work)
# libopencv-video-dev: cv::calcOpticalFlowPyrLK, the oracle of src/flow's tracker (test_flow_opencv)
for arg in "$@"; do
    case "$arg" in
        # cv::remap lives in opencv-imgproc, already listed; the Python script that is
        # `stillheart warp`'s whole-process peer needs the binding (it brings NumPy)
        --bench) bench=1 ;;
        --profile) profile=1 ;;
        --arm64) arm64=1 ;;
        --vm) vm=1 ;;
        *) echo "install-deps: unknown option '$arg'" >&2; exit 2 ;;
    esac
done

# arm64: what the cross build links (libopencv-dev:arm64 cannot co-install: the daemon, its tests
# and the tools built on arm64 need no OpenCV), the runtime of libapriltag (its -dev is unpacked
# below), and the emulator that runs the tests.
arm64_pkgs="crossbuild-essential-arm64 qemu-user libcmocka-dev:arm64 libqhull-dev:arm64 libkissfft-dev:arm64
      libpng-dev:arm64 libturbojpeg0-dev:arm64 libapriltag3:arm64 libosmesa6-dev:arm64
      libinih-dev:arm64 libgpiod-dev:arm64 libcamera-dev:arm64 libdrm-dev:arm64
      dpkg-dev debhelper fakeroot lintian"
if [ "$arm64" = 1 ]; then
    pkgs="$pkgs $arm64_pkgs"
fi
if [ "$bench" = 1 ]; then
    pkgs="$pkgs python3-opencv"
fi
if [ "$profile" = 1 ]; then
    pkgs="$pkgs linux-perf"
fi
if [ "$vm" = 1 ]; then
    pkgs="$pkgs qemu-system-x86 busybox-static kmod cpio xz-utils gstreamer1.0-tools gstreamer1.0-plugins-good"
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

if [ "$arm64" = 1 ] && ! dpkg --print-foreign-architectures | grep -qx arm64; then
    echo "install-deps: adding the arm64 architecture" >&2
    $SUDO dpkg --add-architecture arm64
    $SUDO apt-get update -qq
fi

# libapriltag-dev:arm64, unpacked beside the system (headers, .so links to the arm64 runtime) with
# a .pc of its own: Debian's omits -lapriltag-utils, and the package conflicts with the amd64 one.
apriltag_cache() {
    [ -f "$ARM64_CACHE/pkgconfig/apriltag.pc" ] && return 0
    ver=$(dpkg-query -W -f='${Version}' libapriltag3:arm64)
    tmp=$(mktemp -d); chmod 777 "$tmp"   # apt downloads as _apt
    (cd "$tmp" && apt-get download -qq "libapriltag-dev:arm64=$ver" >&2)
    $SUDO mkdir -p "$ARM64_CACHE/pkgconfig" "$ARM64_CACHE/lib"
    $SUDO dpkg-deb -x "$tmp"/libapriltag-dev_*_arm64.deb "$ARM64_CACHE/root"
    rm -rf "$tmp"
    for l in apriltag apriltag-utils; do
        $SUDO ln -sf "/usr/lib/aarch64-linux-gnu/lib$l.so.3" "$ARM64_CACHE/lib/lib$l.so"
    done
    printf '%s\n' "prefix=$ARM64_CACHE" "" "Name: apriltag" "Description: AprilTag detector library (arm64, unpacked)" \
        "Version: ${ver%%-*}" "Cflags: -I\${prefix}/root/usr/include" \
        "Libs: -L\${prefix}/lib -lapriltag -lapriltag-utils" | $SUDO tee "$ARM64_CACHE/pkgconfig/apriltag.pc" >/dev/null
    echo "install-deps: libapriltag-dev:arm64 unpacked into $ARM64_CACHE" >&2
}

# A name without :ARCH means the native (or arch-independent) package: with arm64 multiarch, an
# installed libdrm-dev:arm64 alone must not count as libdrm-dev.
native=$(dpkg --print-architecture)
missing=""
for p in $pkgs; do
    case "$p" in *:*) want="$p" ;; *) want="$p:$native" ;; esac
    if ! dpkg-query -W -f='${Status} ${Architecture}\n' "${want%%:*}" 2>/dev/null |
            grep -qE "^install ok installed (${want#*:}|all)\$"; then
        missing="$missing $want"
    fi
done
if [ -z "$missing" ]; then
    [ "$arm64" = 1 ] && apriltag_cache
    exit 0
fi

if [ -n "$SUDO" ]; then
    command -v sudo >/dev/null 2>&1 || { echo "install-deps: need root or sudo to install:$missing" >&2; exit 1; }
fi
echo "install-deps: installing$missing" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# shellcheck disable=SC2086
$SUDO apt-get install -y -qq --no-install-recommends $missing >&2
[ "$arm64" = 1 ] && apriltag_cache
exit 0
