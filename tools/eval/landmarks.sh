#!/bin/sh
# Natural landmarks on rendered phantoms against their truth (issue 19; docs/landmarks.md): both
# presets, seeds 1-4, the paper rig's camera (1920x1080), with the instrument shaft and blood,
# the truth's tag centres as the markers (as make table2 feeds the warp); for each, stillheart-eval
# --landmarks with all the markers, then with the four nearest the corners of the reference's
# markers only; and one render with the tissue texture's contrast halved. TPS, the default method.
#   sh tools/eval/landmarks.sh BUILD OUTDIR
# Writes OUTDIR/landmarks.csv and OUTDIR/json/*.json; renders go to OUTDIR/work and are deleted
# as they are measured. FRAMES (default 200) sets the length; LANDMARKS (200) how many are asked.
set -eu
BUILD=$1 OUT=$2
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval
FRAMES=${FRAMES:-200} LANDMARKS=${LANDMARKS:-200}
for b in "$RENDER" "$EVAL"; do [ -x "$b" ] || { echo "landmarks: $b is not built" >&2; exit 1; }; done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s)
stamp() { echo "landmarks: [$(( $(date +%s) - start )) s] $*" >&2; }
num() { sed -n "s/.*\"$2\": \([-0-9.eEnaif+]*\).*/\1/p" "$OUT/json/$1.json" | head -1; }

# The four markers nearest the corners of frame 0's markers (least x+y, x-y, -x+y, -x-y).
corners() {
    awk -F, 'NR > 1 && $1 == 0 { id[++n] = $2; x[n] = $3; y[n] = $4 }
        END {
            split("1 1,1 -1,-1 1,-1 -1", s, ",")
            for (k = 1; k <= 4; k++) {
                split(s[k], d, " "); best = ""
                for (i = 1; i <= n; i++) { v = d[1] * x[i] + d[2] * y[i]; if (best == "" || v < best) { best = v; pick = id[i] } }
                printf "%s%s", (k > 1 ? "|" : ""), pick
            }
            print ""
        }' "$1"
}

run() { # run NAME DIR POINTS
    "$EVAL" --quiet --json --truth "$2" --points "$3" --landmarks "$LANDMARKS" "$2/cam0.y4m" > "$OUT/json/$1.json"
    echo "$1,$(num "$1" seeded),$(num "$1" accepted),$(num "$1" measured),$(num "$1" mean),$(num "$1" p99),$(num "$1" max),$(num "$1" over_1px),$(num "$1" hidden),$(num "$1" accepted_hidden),$(num "$1" map_mean),$(num "$1" markers_mean),$(num "$1" markers_p95),$(num "$1" landmarks_mean),$(num "$1" landmarks_p95),$(num "$1" ms_median)" >> "$OUT/landmarks.csv"
}

echo "run,seeded,accepted,measured,mean,p99,max,over_1px,hidden,accepted_hidden,map_at_landmarks,geo_markers_mean,geo_markers_p95,geo_landmarks_mean,geo_landmarks_p95,ms" > "$OUT/landmarks.csv"
for p in exvivo invivo; do
    for seed in 1 2 3 4; do
        dir=$OUT/work/$p-$seed
        stamp "render $p seed $seed ($FRAMES frames, 1920x1080, occlusions)"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --seed "$seed" --frames "$FRAMES" --quiet --out "$dir"
        "$EVAL" --truth "$dir" --export-points "$dir/points.csv"
        run "$p-$seed" "$dir" "$dir/points.csv"
        ids=$(corners "$dir/points.csv")
        awk -F, -v ids="$ids" 'NR == 1 || $2 ~ "^(" ids ")$"' "$dir/points.csv" > "$dir/points4.csv"
        run "$p-$seed-4tags" "$dir" "$dir/points4.csv"
        rm -rf "$dir"
    done
done
dir=$OUT/work/exvivo-1-half-contrast
stamp "render exvivo seed 1, texture contrast halved"
"$RENDER" --preset exvivo --rig paper --cameras 1 --occlusions --seed 1 --frames "$FRAMES" --texture-contrast 0.5 --quiet --out "$dir"
"$EVAL" --truth "$dir" --export-points "$dir/points.csv"
run exvivo-1-half-contrast "$dir" "$dir/points.csv"
rm -rf "$dir"
stamp "done: $OUT/landmarks.csv"
column -s, -t < "$OUT/landmarks.csv"
