#!/bin/sh
# What the daemon allocates per frame, by the shared object that asks (DESIGN.md: the hot loop
# allocates nothing): `stillheart run ARGS --max-frames N`, then 2N, under tools/alloc/count.c
# (LD_PRELOAD), and the difference divided by N. ARGS must give a source at least 2N frames long
# whose marker set and models settle in the first N (a model built later is a reference's cost,
# not a frame's), e.g. test mode on a render without occlusions:
#   sh tools/alloc/per-frame.sh build 30 --source y4m:cam0.y4m --points markers.csv \
#       --no-realtime --no-loop --sink none --landmarks 100 --method pwlinear
# glibc hosts only; not under ASan (it replaces malloc itself).
set -eu
BUILD=$(cd "$1" && pwd) N=$2
shift 2
T=$(mktemp -d /tmp/sh-alloc.XXXXXX)
trap 'rm -rf "$T"' EXIT
cc -O1 -shared -fPIC -o "$T/count.so" "$(dirname "$0")/count.c" -ldl -lpthread
for f in "$N" $((2 * N)); do
    ALLOC_COUNT_OUT="$T/$f.txt" LD_PRELOAD="$T/count.so" "$BUILD/stillheart" run --quiet --group= "$@" --max-frames "$f" \
        > /dev/null 2> "$T/err.txt" || { cat "$T/err.txt" >&2; exit 1; }
done
echo "allocations per frame (frames $N to $((2 * N)) against the first $N), by the object asking:"
awk -v n="$N" 'FNR == NR { a[$2] = $1; next } { d = $1 - a[$2]; t += d; if (d) printf "  %-28s %10.1f\n", $2, d / n }
    END { printf "  %-28s %10.1f\n", "all", t / n }' \
    "$T/$N.txt" "$T/$((2 * N)).txt"
