#!/bin/sh
# Natural landmarks on rendered phantoms against their truth (issue 19; docs/landmarks.md): both
# presets, seeds 1-4, the paper rig's camera (1920x1080), with the instrument shaft and blood,
# the truth's tag centres as the markers (as make table2 feeds the warp); for each, stillheart-eval
# --landmarks with all the markers, then with the four nearest the corners of the reference's
# markers only, with the default tests and with --lm-sparse (the tests for sparse markers), the
# same seed rendered without the instrument and blood (-clear: how many are more than 1 px off
# without any occluder), and the same seed rendered with those four tags alone (--only-markers:
# no stickers between them) with --lm-sparse, with LANDMARKS and with LANDMARKS_SPARSE of them
# (four tags' map rests on the landmarks alone between them: docs/landmarks.md, "Four tags: how
# many landmarks"); and one
# render with the tissue texture's contrast halved. TPS, the default method.
# Then the product's own path on the same renders: `stillheart track` without and with
# --landmarks, `stillheart warp` with each 2D method that takes them, and stillheart-eval's e and
# geometric error of both; and the daemon (`stillheart run`, [track] landmarks) likewise.
#   sh tools/eval/landmarks.sh BUILD OUTDIR
# Writes OUTDIR/landmarks.csv, OUTDIR/warp.csv, OUTDIR/daemon.csv and OUTDIR/json/*.json;
# renders go to OUTDIR/work and are deleted as they are measured. FRAMES (default 200) sets the
# length; LANDMARKS (200) how many are asked, LANDMARKS_SPARSE (400) for the four tags alone;
# WARP_METHODS (tps pwlinear bspline affine) the warp's methods, DAEMON_METHODS (tps bspline
# pwlinear) the daemon's.
# REFERENCES (default 15 30 ... 165) are the other frames each standard render is evaluated from
# as the reference (the instrument or blood in view in some: a reference is taken at start, after
# the camera moved, or when asked, whatever is over the tissue then), into OUTDIR/references.csv,
# with the landmarks chosen on what covered the tissue there and how many of those were accepted
# and more than 1 px from the tissue behind them; and the product's path from each (`stillheart
# track --landmarks --reference N`, the tracker's markers, the rows judged by stillheart-eval
# --landmark-rows --reference N: track_*); and the four corner tags with the sparse tests from
# each, each pass used at once and from the fourth on (NAME-4tags-sparse-confirm1 and -confirm4,
# the evaluator's alone). "" skips them.
set -eu
BUILD=$(cd "$1" && pwd) OUT=$2 HERE=$(cd "$(dirname "$0")" && pwd)
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval APP=$BUILD/stillheart
WARP_METHODS=${WARP_METHODS:-tps pwlinear bspline affine} DAEMON_METHODS=${DAEMON_METHODS:-tps bspline pwlinear}
FRAMES=${FRAMES:-200} LANDMARKS=${LANDMARKS:-200} LANDMARKS_SPARSE=${LANDMARKS_SPARSE:-400}
REFERENCES=${REFERENCES-15 30 45 60 75 90 105 120 135 150 165}
for b in "$RENDER" "$EVAL" "$APP"; do [ -x "$b" ] || { echo "landmarks: $b is not built" >&2; exit 1; }; done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s)
stamp() { echo "landmarks: [$(( $(date +%s) - start )) s] $*" >&2; }
. "$HERE/common.sh"

run() { # run NAME DIR POINTS [EVAL OPTIONS]
    name=$1 dir=$2 pts=$3
    shift 3
    "$EVAL" --quiet --json --truth "$dir" --points "$pts" --landmarks "$LANDMARKS" "$@" "$dir/cam0.y4m" > "$OUT/json/$name.json"
    set -- "$name"
    echo "$1,$(num "$1" seeded),$(num "$1" accepted),$(num "$1" measured),$(num "$1" mean),$(num "$1" p99),$(num "$1" max),$(num "$1" over_1px),$(num "$1" hidden),$(num "$1" accepted_hidden),$(num "$1" map_mean),$(num "$1" markers_mean),$(num "$1" markers_p95),$(num "$1" landmarks_mean),$(num "$1" landmarks_p95),$(num "$1" ms_median),$(num "$1" unpredicted_frames),$(num "$1" accepted_partly_hidden),$(num "$1" over_1px_partly_hidden)" >> "$OUT/landmarks.csv"
}

# The evaluator's columns of references.csv from OUT/json/J.json (J: a run from a reference).
eval_columns() {
    echo "$(num "$1" seeded),$(num "$1" accepted),$(num "$1" over_1px),$(num "$1" hidden),$(num "$1" accepted_hidden),$(num "$1" chosen_covered),$(num "$1" accepted_covered),$(num "$1" over_1px_covered),$(num "$1" unjudged),$(num "$1" markers_mean),$(num "$1" landmarks_mean)"
}

# The same render from other references: every reference in REFERENCES before the render's end,
# through the evaluator (the truth's markers) and through `stillheart track --reference`.
from_references() { # from_references NAME DIR IDS
    for n in $REFERENCES; do
        [ "$n" -lt "$FRAMES" ] || continue
        j=$1-ref$n k=$1-ref$n-track
        "$EVAL" --quiet --json --truth "$2" --points "$2/points.csv" --landmarks "$LANDMARKS" --reference "$n" \
            "$2/cam0.y4m" > "$OUT/json/$j.json"
        "$APP" track --quiet --ids "$3" --landmarks "$LANDMARKS" --reference "$n" "$2/cam0.y4m" > "$2/ref.csv"
        "$EVAL" --json --truth "$2" --points "$2/ref.csv" --landmark-rows --reference "$n" > "$OUT/json/$k.json"
        echo "$1,$n,$(eval_columns "$j"),$(num_first "$k" landmarks),$(num_first "$k" rows),$(num_first "$k" hidden),$(num_first "$k" over_1px image),$(num_first "$k" rows covered),$(num_first "$k" image_over_1px covered)" >> "$OUT/references.csv"
        # the four corner tags with the sparse tests, each pass used at once (their default) and
        # from the fourth on (--landmarks-confirm 4, the integrator's choice): the evaluator's alone
        for c in 1 4; do
            j=$1-4tags-sparse-confirm$c-ref$n
            "$EVAL" --quiet --json --truth "$2" --points "$2/points4.csv" --landmarks "$LANDMARKS" --lm-sparse \
                --lm-confirm "$c" --reference "$n" "$2/cam0.y4m" > "$OUT/json/$j.json"
            echo "$1-4tags-sparse-confirm$c,$n,$(eval_columns "$j"),,,,,," >> "$OUT/references.csv"
        done
    done
    rm -f "$2/ref.csv"
}

# The product's path: track (the markers' ids 0-15 / 0-13 of the presets, no first pass) without
# and with landmarks, warp, e and the geometric error.
through_warp() { # through_warp NAME DIR IDS
    (cd "$2" && "$APP" track --quiet --ids "$3" cam0.y4m > track.csv &&
        "$APP" track --quiet --ids "$3" --landmarks "$LANDMARKS" cam0.y4m > track_lm.csv)
    for m in $WARP_METHODS; do
        for v in track track_lm; do
            "$APP" warp --quiet --threads 2 --method "$m" --points "$2/$v.csv" "$2/cam0.y4m" "$2/stab.y4m"
            "$EVAL" --quiet --json --truth "$2" --points "$2/$v.csv" "$2/stab.y4m" "$2/cam0.y4m" > "$OUT/json/$1-$m-$v.json"
        done
        a=$1-$m-track b=$1-$m-track_lm
        echo "$1,$m,$(num "$a" e_stabilized),$(num "$b" e_stabilized),$(num "$a" mean),$(num "$b" mean),$(num "$a" p95),$(num "$b" p95)" >> "$OUT/warp.csv"
    done
    rm -f "$2/stab.y4m"
}

# The daemon's path: `stillheart run` without and with [track] landmarks, each of DAEMON_METHODS
# (tps bspline pwlinear: the methods it takes landmarks with, but affine, which is worse), as fast as it goes,
# its markers those of `stillheart track` above (test mode: its reference is frame 0 and is
# warped, so its --trace-points, the markers and landmarks each frame's map went through, is a
# points file the evaluator takes); e and the geometric error of what it showed, the landmark
# stage's and the model update's CPU ms per frame (medians, --trace), and its RSS.
through_daemon() { # through_daemon NAME DIR (after through_warp: its track.csv)
    for m in $DAEMON_METHODS; do
        for v in 0 "$LANDMARKS"; do
            j=$1-daemon-$m-$v
            rm -f "$2/run.y4m"
            "$APP" run --source "y4m:$2/cam0.y4m" --no-realtime --no-loop --points "$2/track.csv" --method "$m" \
                --landmarks "$v" --sink none --group= --threads 2 --quiet --stats --record "$2/run.y4m" \
                --trace "$2/trace.csv" --trace-points "$2/used.csv" > "$2/stats.txt"
            "$EVAL" --quiet --json --truth "$2" --points "$2/used.csv" "$2/run.y4m" "$2/cam0.y4m" > "$OUT/json/$j.json"
            ms=$(python3 -c 'import csv,sys,statistics as s; r=list(csv.DictReader(open(sys.argv[1]))); print("%.2f,%.2f" % (s.median(float(x["landmarks_ms"]) for x in r), s.median(float(x["model_ms"]) for x in r)))' "$2/trace.csv")
            rss=$(sed -n 's/.*RSS kB.* max \([0-9]*\) end .*/\1/p' "$2/stats.txt")
            echo "$1,$m,$v,$(num "$j" e_stabilized),$(num "$j" mean),$(num "$j" p95),$ms,$rss" >> "$OUT/daemon.csv"
        done
    done
    rm -f "$2/run.y4m"
}

echo "run,method,landmarks,e,geo_mean,geo_p95,landmarks_ms,model_ms,rss_kb_max" > "$OUT/daemon.csv"
echo "run,method,e_markers,e_landmarks,geo_mean_markers,geo_mean_landmarks,geo_p95_markers,geo_p95_landmarks" > "$OUT/warp.csv"
echo "run,reference,seeded,accepted,over_1px,hidden,accepted_hidden,chosen_covered,accepted_covered,over_1px_covered,unjudged,geo_markers_mean,geo_landmarks_mean,track_landmarks,track_rows,track_hidden,track_over_1px,track_covered_rows,track_covered_over_1px" > "$OUT/references.csv"
echo "run,seeded,accepted,measured,mean,p99,max,over_1px,hidden,accepted_hidden,map_at_landmarks,geo_markers_mean,geo_markers_p95,geo_landmarks_mean,geo_landmarks_p95,ms,unpredicted,partly_hidden,over_1px_partly_hidden" > "$OUT/landmarks.csv"
for p in exvivo invivo; do
    preset_ids=$( [ "$p" = exvivo ] && echo 0-15 || echo 0-13 ) # the presets' markers, for track
    for seed in 1 2 3 4; do
        dir=$OUT/work/$p-$seed
        stamp "render $p seed $seed ($FRAMES frames, 1920x1080, occlusions)"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --seed "$seed" --frames "$FRAMES" --quiet --out "$dir"
        "$EVAL" --truth "$dir" --export-points "$dir/points.csv"
        run "$p-$seed" "$dir" "$dir/points.csv"
        ids=$(four_tags "$dir/points.csv" "$dir/points4.csv")
        run "$p-$seed-4tags" "$dir" "$dir/points4.csv"
        run "$p-$seed-4tags-sparse" "$dir" "$dir/points4.csv" --lm-sparse
        stamp "$p seed $seed from the other references"
        from_references "$p-$seed" "$dir" "$preset_ids"
        stamp "track, warp and evaluate $p seed $seed"
        through_warp "$p-$seed" "$dir" "$preset_ids"
        stamp "the daemon on $p seed $seed"
        through_daemon "$p-$seed" "$dir"
        rm -rf "$dir"
        # the same seed without the instrument and blood: the tail over 1 px without occluders
        dc=$OUT/work/$p-$seed-clear
        "$RENDER" --preset "$p" --rig paper --cameras 1 --seed "$seed" --frames "$FRAMES" --quiet --out "$dc"
        "$EVAL" --truth "$dc" --export-points "$dc/points.csv"
        run "$p-$seed-clear" "$dc" "$dc/points.csv"
        rm -rf "$dc"
        # the four corner tags alone (run sets dir)
        d4=$OUT/work/$p-$seed-4only
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --seed "$seed" --frames "$FRAMES" \
            --only-markers "$(echo "$ids" | tr '|' ,)" --quiet --out "$d4"
        "$EVAL" --truth "$d4" --export-points "$d4/points.csv"
        run "$p-$seed-4only-sparse" "$d4" "$d4/points.csv" --lm-sparse
        run "$p-$seed-4only-sparse-$LANDMARKS_SPARSE" "$d4" "$d4/points.csv" --lm-sparse --landmarks "$LANDMARKS_SPARSE"
        rm -rf "$d4"
    done
done
dir=$OUT/work/exvivo-1-half-contrast
stamp "render exvivo seed 1, texture contrast halved"
"$RENDER" --preset exvivo --rig paper --cameras 1 --occlusions --seed 1 --frames "$FRAMES" --texture-contrast 0.5 --quiet --out "$dir"
"$EVAL" --truth "$dir" --export-points "$dir/points.csv"
run exvivo-1-half-contrast "$dir" "$dir/points.csv"
rm -rf "$dir"
stamp "done: $OUT/landmarks.csv, $OUT/references.csv, $OUT/warp.csv, $OUT/daemon.csv"
column -s, -t < "$OUT/landmarks.csv"
column -s, -t < "$OUT/references.csv"
column -s, -t < "$OUT/warp.csv"
column -s, -t < "$OUT/daemon.csv"
