#!/bin/sh
# Natural landmarks in 3D (issue 19; docs/landmarks.md, "In 3D"): both presets, seeds 1-4, the
# paper's trinocular rig (3 x 1920x1080), with the instrument shaft and blood. For each render:
# `stillheart track --cameras` without and with --landmarks; the landmark rows against the truth
# (stillheart-eval --landmark-rows: camera 0's positions, and X,Y,Z projected into every camera
# that sees the point); then `stillheart warp3d`'s reference view with each of METHODS through
# both files, and stillheart-eval --cameras's e and geometric error of both.
#   sh tools/eval/landmarks3d.sh BUILD OUTDIR
# Writes OUTDIR/landmarks3d.csv, OUTDIR/warp3d.csv and OUTDIR/json/*.json; renders go to
# OUTDIR/work and are deleted as they are measured. FRAMES (default 200) sets the length,
# LANDMARKS (200) how many are asked, METHODS (tps bspline) the 3D interpolants, JOBS (2) how
# many renders are measured side by side.
# REFERENCES (default 15 30 ... 165, as tools/eval/landmarks.sh) are the other frames each render's
# landmarks are chosen in (`stillheart track --reference N`: the instrument or blood in view in
# some), their rows judged from there (stillheart-eval --landmark-rows --reference N: the rows
# hidden, the landmarks chosen on what covered the tissue and their rows more than 1 px from the
# tissue behind), into OUTDIR/references.csv; "" skips them.
set -eu
BUILD=$(cd "$1" && pwd) OUT=$2 HERE=$(cd "$(dirname "$0")" && pwd)
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval APP=$BUILD/stillheart
METHODS=${METHODS:-tps bspline} FRAMES=${FRAMES:-200} LANDMARKS=${LANDMARKS:-200} JOBS=${JOBS:-2}
REFERENCES=${REFERENCES-15 30 45 60 75 90 105 120 135 150 165}
for b in "$RENDER" "$EVAL" "$APP"; do [ -x "$b" ] || { echo "landmarks3d: $b is not built" >&2; exit 1; }; done
mkdir -p "$OUT/work" "$OUT/json" "$OUT/rows"
start=$(date +%s)
stamp() { echo "landmarks3d: [$(( $(date +%s) - start )) s] $*" >&2; }
. "$HERE/common.sh"

one() { # one PRESET SEED: its rows into $OUT/rows/NAME.*
    p=$1 seed=$2 name=$1-$2 dir=$OUT/work/$1-$2
    ids=$( [ "$p" = exvivo ] && echo 0-15 || echo 0-13 )
    stamp "render $name ($FRAMES frames, 3 cameras, 1920x1080, occlusions)"
    "$RENDER" --preset "$p" --rig paper --cameras 3 --occlusions --seed "$seed" --frames "$FRAMES" --quiet --out "$dir"
    (cd "$dir" && T="$APP track --ids $ids --cameras calibration.yaml" &&
        $T --quiet cam0.y4m cam1.y4m cam2.y4m > markers.csv &&
        $T --landmarks "$LANDMARKS" --stats --json cam0.y4m cam1.y4m cam2.y4m 2> stats > landmarks.csv)
    tail -n 1 "$dir/stats" | sed 's/.*"landmarks": //' > "$OUT/json/$name-track.json"
    "$EVAL" --json --truth "$dir" --cameras "$dir/calibration.yaml" --points "$dir/landmarks.csv" --landmark-rows \
        > "$OUT/json/$name-rows.json"
    t=$name-track r=$name-rows
    echo "$name,$(num_first "$t" chosen),$(num_first "$t" in_3d),$(num_first "$t" accepted),$(num_first "$t" unmatched_3d),$(num_first "$t" inconsistent_3d),$(num_first "$r" hidden),$(num_first "$r" mean image),$(num_first "$r" max image),$(num_first "$r" over_1px image),$(num_first "$r" rows reprojected),$(num_first "$r" mean reprojected),$(num_first "$r" p99 reprojected),$(num_first "$r" max reprojected),$(num_first "$r" over_1px reprojected)" \
        > "$OUT/rows/$name.lm"
    : > "$OUT/rows/$name.warp"
    : > "$OUT/rows/$name.ref"
    for n in $REFERENCES; do
        [ "$n" -lt "$FRAMES" ] || continue
        t=$name-ref$n-track r=$name-ref$n-rows
        (cd "$dir" && $APP track --ids "$ids" --cameras calibration.yaml --landmarks "$LANDMARKS" --reference "$n" \
            --stats --json cam0.y4m cam1.y4m cam2.y4m 2> stats > ref.csv)
        tail -n 1 "$dir/stats" | sed 's/.*"landmarks": //' > "$OUT/json/$t.json"
        "$EVAL" --json --truth "$dir" --cameras "$dir/calibration.yaml" --points "$dir/ref.csv" --landmark-rows \
            --reference "$n" > "$OUT/json/$r.json"
        echo "$name,$n,$(num_first "$t" chosen),$(num_first "$r" landmarks),$(num_first "$r" rows),$(num_first "$r" hidden),$(num_first "$r" over_1px image),$(num_first "$r" landmarks covered),$(num_first "$r" rows covered),$(num_first "$r" image_over_1px covered),$(num_first "$r" reprojected_over_1px covered),$(num_first "$r" rows reprojected),$(num_first "$r" mean reprojected),$(num_first "$r" over_1px reprojected)" \
            >> "$OUT/rows/$name.ref"
    done
    for m in $METHODS; do
        for v in markers landmarks; do
            "$APP" warp3d --quiet --threads 1 --cameras "$dir/calibration.yaml" --method "$m" --points "$dir/$v.csv" \
                "$dir/cam0.y4m" "$dir/s.y4m"
            "$EVAL" --quiet --json --truth "$dir" --cameras "$dir/calibration.yaml" --points "$dir/$v.csv" "$dir/s.y4m" \
                "$dir/cam0.y4m" > "$OUT/json/$name-$m-$v.json"
        done
        a=$name-$m-markers b=$name-$m-landmarks
        echo "$name,$m,$(num_first "$a" e_stabilized),$(num_first "$b" e_stabilized),$(num_first "$a" mean geometric),$(num_first "$b" mean geometric),$(num_first "$a" p95),$(num_first "$b" p95)" \
            >> "$OUT/rows/$name.warp"
    done
    rm -rf "$dir"
    stamp "$name done"
}

n=0
for p in exvivo invivo; do
    for seed in 1 2 3 4; do
        one "$p" "$seed" &
        n=$((n + 1))
        if [ $((n % JOBS)) -eq 0 ]; then wait; fi
    done
done
wait
echo "run,chosen,in_3d,accepted_cam0,unmatched,inconsistent,hidden,image_mean,image_max,image_over_1px,rows_3d,reproj_mean,reproj_p99,reproj_max,reproj_over_1px" > "$OUT/landmarks3d.csv"
echo "run,method,e_markers,e_landmarks,geo_mean_markers,geo_mean_landmarks,geo_p95_markers,geo_p95_landmarks" > "$OUT/warp3d.csv"
echo "run,reference,chosen,in_3d,rows,hidden,image_over_1px,covered,covered_rows,covered_image_over_1px,covered_reproj_over_1px,rows_3d,reproj_mean,reproj_over_1px" > "$OUT/references.csv"
for p in exvivo invivo; do
    for seed in 1 2 3 4; do
        cat "$OUT/rows/$p-$seed.lm" >> "$OUT/landmarks3d.csv"
        cat "$OUT/rows/$p-$seed.warp" >> "$OUT/warp3d.csv"
        cat "$OUT/rows/$p-$seed.ref" >> "$OUT/references.csv"
    done
done
stamp "done: $OUT/landmarks3d.csv, $OUT/warp3d.csv, $OUT/references.csv"
column -s, -t < "$OUT/landmarks3d.csv"
column -s, -t < "$OUT/warp3d.csv"
if [ -n "$REFERENCES" ]; then
    column -s, -t < "$OUT/references.csv"
    awk -F, 'NR > 1 { h += $6; r += $5; c += $9; o += $10; o3 += $11; a += $7 }
        END { printf "other references: %d of %d rows hidden, %d over 1 px in x, y; rows of landmarks chosen on a cover %d, over 1 px from the tissue behind %d in x, y and %d in X, Y, Z\n", h, r, a, c, o, o3 }' \
        "$OUT/references.csv"
fi
