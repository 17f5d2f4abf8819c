#!/bin/sh
# Landmarks under blood that spreads slowly (docs/landmarks.md, "Blood that spreads slowly"): the
# renders of `make landmarks-table` (both presets, seeds 1-4, the paper rig's camera at 1920x1080,
# the instrument and blood, the truth's tag centres as the markers), but each blood blob grows to
# its size, and shrinks back, over BLOOD_SPREAD seconds (stillheart-render --blood-spread; 0.4 s on
# the standard renders). The jump test compares a landmark's window with the median of its last 16
# frames, 0.5-0.7 s: blood that creeps over a window more slowly than that never jumps, and only
# the other tests (the fixed bound on the windows, the backward search, the map) stand between it
# and an accepted landmark under the blood. For each render: stillheart-eval --landmarks with the
# 16 (14) tags and the default tests, with the four corner tags and --lm-sparse, and the same seed
# with those four tags alone (--only-markers) with --lm-sparse and 400 landmarks; the landmark-
# frames the truth hides, how many of them were accepted, and the accepted ones partly under blood.
#   sh tools/eval/blood.sh BUILD OUTDIR
# Writes OUTDIR/blood.csv and OUTDIR/json/*.json; renders go to OUTDIR/work and are deleted as they
# are measured. FRAMES (default 200), BLOOD_SPREAD (default 3 seconds). About 4 minutes on 2 cores.
set -eu
BUILD=$(cd "$1" && pwd) OUT=$2 HERE=$(cd "$(dirname "$0")" && pwd)
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval
FRAMES=${FRAMES:-200} SPREAD=${BLOOD_SPREAD:-3}
for b in "$RENDER" "$EVAL"; do [ -x "$b" ] || { echo "blood: $b is not built" >&2; exit 1; }; done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s)
. "$HERE/common.sh"
stamp() { echo "blood: [$(( $(date +%s) - start )) s] $*" >&2; }

run() { # run NAME DIR POINTS [EVAL OPTIONS]
    name=$1 dir=$2 pts=$3
    shift 3
    "$EVAL" --quiet --json --truth "$dir" --points "$pts" --landmarks 200 "$@" "$dir/cam0.y4m" > "$OUT/json/$name.json"
    set -- "$name"
    echo "$1,$SPREAD,$(num "$1" accepted),$(num "$1" mean),$(num "$1" max),$(num "$1" over_1px),$(num "$1" hidden),$(num "$1" accepted_hidden),$(num "$1" accepted_partly_hidden),$(num "$1" over_1px_partly_hidden),$(num "$1" markers_mean),$(num "$1" landmarks_mean)" >> "$OUT/blood.csv"
}

echo "run,blood_spread_s,accepted,mean,max,over_1px,hidden,accepted_hidden,accepted_partly_hidden,over_1px_partly_hidden,geo_markers_mean,geo_landmarks_mean" > "$OUT/blood.csv"
for p in exvivo invivo; do
    for seed in 1 2 3 4; do
        dir=$OUT/work/$p-$seed
        stamp "render $p seed $seed ($FRAMES frames, 1920x1080, occlusions, blood spreading over $SPREAD s)"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --blood-spread "$SPREAD" --seed "$seed" \
            --frames "$FRAMES" --quiet --out "$dir"
        "$EVAL" --truth "$dir" --export-points "$dir/points.csv"
        run "$p-$seed" "$dir" "$dir/points.csv"
        ids=$(four_tags "$dir/points.csv" "$dir/points4.csv")
        run "$p-$seed-4tags-sparse" "$dir" "$dir/points4.csv" --lm-sparse
        rm -rf "$dir"
        d4=$OUT/work/$p-$seed-4only
        stamp "render $p seed $seed, the four corner tags alone"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --blood-spread "$SPREAD" --seed "$seed" \
            --frames "$FRAMES" --only-markers "$(echo "$ids" | tr '|' ,)" --quiet --out "$d4"
        "$EVAL" --truth "$d4" --export-points "$d4/points.csv"
        run "$p-$seed-4only-sparse-400" "$d4" "$d4/points.csv" --lm-sparse --landmarks 400
        rm -rf "$d4"
    done
done
stamp "done: $OUT/blood.csv"
column -s, -t < "$OUT/blood.csv"
