#!/bin/sh
# The paper's Table II on rendered phantoms: both presets at the paper's length, one camera,
# every 2D method of `stillheart warp` fed the ground-truth marker centres, evaluated with
# stillheart-eval (e over the hull, geometric error against the truth, heatmaps).
#   sh tools/eval/table2.sh BUILD OUTDIR
# Writes OUTDIR/table2.md, its figure OUTDIR/table2.png (e per method and preset, from the
# numbers in OUTDIR/table2.csv), OUTDIR/<preset>-<method>.png and the evaluator's JSON per run in
# OUTDIR/json/. The renders stay in OUTDIR/work/<preset>/ (about 2.3 GB) unless KEEP_RENDERS=0;
# stabilized videos are deleted as soon as they are measured. RENDER_ARGS adds renderer options
# for a quick trial (e.g. RENDER_ARGS="--frames 20 --width 640 --height 360").
# Natural landmarks (issue 19, docs/landmarks.md) add rows on the same renders when LANDMARKS > 0
# (`make table2 TABLE2_LANDMARKS=200`; default 0: they more than double the run): that many are
# asked, chosen and judged by stillheart-eval --landmarks, predicted from the truth's tag centres,
# and the accepted ones join the markers in the points file each method that takes them is warped
# with (LM_METHODS); then TPS with only the four tags nearest the corners of the field, without
# and with landmarks.
set -eu
BUILD=${1:?usage: table2.sh BUILD OUTDIR}
OUT=${2:?usage: table2.sh BUILD OUTDIR}
HERE=$(cd "$(dirname "$0")" && pwd)
. "$HERE/common.sh"
METHODS="affine pwlinear bspline rbf-local tps gaussian"
# the methods `stillheart warp` gives landmarks to (sh_landmarks_method_uses): not rbf-local and
# gaussian, which are worse with them (docs/landmarks.md)
LM_METHODS="affine pwlinear bspline tps"
LANDMARKS=${LANDMARKS:-0}
# the landmark rows: key, method, points file (in the render's folder)
LM_RUNS=""
if [ "$LANDMARKS" -gt 0 ]; then
    for m in $LM_METHODS; do LM_RUNS="$LM_RUNS $m-lm:$m:landmarks.csv"; done
    LM_RUNS="$LM_RUNS tps-4tags:tps:points4.csv tps-4tags-lm:tps:landmarks4.csv"
fi
PRESETS="exvivo invivo"
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval WARP=$BUILD/stillheart
PLOT=$BUILD/tools/eval/table2-plot
for b in "$RENDER" "$EVAL" "$WARP" "$PLOT"; do
    [ -x "$b" ] || { echo "table2: $b is not built" >&2; exit 1; }
done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s) lm_secs=0
stamp() { echo "table2: [$(( $(date +%s) - start )) s] $*" >&2; }
# warp_eval PRESET KEY METHOD POINTS: the warp, then e and the geometric error of what it made
warp_eval() {
    "$WARP" warp --quiet --threads 2 --method "$3" --points "$4" "$dir/cam0.y4m" "$dir/stabilized.y4m"
    "$EVAL" --quiet --json --points "$4" --truth "$dir" --method "$3" \
        --heatmap "$OUT/$1-$2.png" "$dir/stabilized.y4m" > "$OUT/json/$1-$2.json"
    rm -f "$dir/stabilized.y4m"
}
# landmark_rows PRESET: the landmarks with all the tags and with the four corner ones, then the rows
landmark_rows() {
    t0=$(date +%s)
    four_tags "$dir/points.csv" "$dir/points4.csv" > /dev/null
    for v in "" 4; do
        stamp "landmarks $1${v:+, 4 tags}"
        "$EVAL" --quiet --json --truth "$dir" --points "$dir/points$v.csv" --landmarks "$LANDMARKS" \
            --landmarks-points "$dir/landmarks$v.csv" "$dir/cam0.y4m" > "$OUT/json/$1-landmarks$v.json"
    done
    for r in $LM_RUNS; do
        key=${r%%:*} rest=${r#*:}
        stamp "warp + evaluate $1 $key"
        warp_eval "$1" "$key" "${rest%%:*}" "$dir/${rest#*:}"
    done
    lm_secs=$(( lm_secs + $(date +%s) - t0 ))
}

for p in $PRESETS; do
    dir=$OUT/work/$p
    stamp "render $p (1 camera, 1920x1080, the preset's length)"
    "$RENDER" --preset "$p" --rig paper --cameras 1 --quiet ${RENDER_ARGS:-} --out "$dir"
    "$EVAL" --truth "$dir" --export-points "$dir/points.csv"
    stamp "evaluate $p unstabilized"
    "$EVAL" --quiet --json --points "$dir/points.csv" --truth "$dir" --method none \
        --heatmap "$OUT/$p-unstabilized.png" "$dir/cam0.y4m" > "$OUT/json/$p-unstabilized.json"
    for m in $METHODS; do
        stamp "warp + evaluate $p $m"
        warp_eval "$p" "$m" "$m" "$dir/points.csv"
    done
    [ -z "$LM_RUNS" ] || landmark_rows "$p"
    [ "${KEEP_RENDERS:-1}" = 1 ] || rm -f "$dir/cam0.y4m"
done

# A number from the evaluator's one-line JSON: the first "key": value. Not common.sh's num: a nan
# is left empty here, which fmt and fmt2 print as n/a in the table.
num() { sed -n "s/.*\"$2\": \([-0-9.eE+]*\).*/\1/p" "$OUT/json/$1.json" | head -1; }
fmt() { [ -n "$1" ] && printf '%.3f' "$1" || printf 'n/a'; }
fmt2() { [ -n "$1" ] && printf '%.2f' "$1" || printf 'n/a'; }

{
    echo "preset,method,e"
    for p in $PRESETS; do
        for m in unstabilized $METHODS $(for r in $LM_RUNS; do echo "${r%%:*}"; done); do
            echo "$p,$m,$(num "$p-$m" e_stabilized)"
        done
    done
} > "$OUT/table2.csv"
"$PLOT" "$OUT/table2.csv" "$OUT/table2.png"

secs=$(( $(date +%s) - start ))
md=$OUT/table2.md
{
    echo "# Table II, reproduced on the rendered phantom"
    echo
    echo "Average error e (paper, section V) in the stabilized images, ours beside the paper's, and"
    echo "the geometric error of the warp's map against the phantom's ground truth (mean / 95th"
    echo "percentile, px, hull pixels every 4 px, all frames). One camera," \
        "$(sed -n 's/^width //p' "$OUT/work/exvivo/phantom.txt")x$(sed -n 's/^height //p' "$OUT/work/exvivo/phantom.txt");"
    echo "correspondences are the ground-truth marker centres (detection is measured on its own)."
    echo
    echo "| method | ex-vivo e | paper | in-vivo e | paper | ex-vivo geometric px (mean / p95) | in-vivo geometric px (mean / p95) |"
    echo "|---|---|---|---|---|---|---|"
    rows="unstabilized:unstabilized:0.186:0.133
affine:affine:0.054:0.088
bspline:B-Spline:0.037:0.076
pwlinear:piecewise linear:0.039:0.076
rbf-local:RBF (locally supp.):0.040:0.083
tps:RBF (TPS):0.038:0.077
gaussian:RBF (Gaussian):0.037:0.079"
    [ -z "$LM_RUNS" ] || rows="$rows
affine-lm:affine + landmarks:-:-
pwlinear-lm:piecewise linear + landmarks:-:-
bspline-lm:B-Spline + landmarks:-:-
tps-lm:RBF (TPS) + landmarks:-:-
tps-4tags:RBF (TPS), 4 corner tags:-:-
tps-4tags-lm:RBF (TPS), 4 corner tags + landmarks:-:-"
    printf '%s\n' "$rows" | while IFS=: read -r m name pex pin; do
        printf '| %s | %s | %s | %s | %s | %s / %s | %s / %s |\n' "$name" \
            "$(fmt "$(num exvivo-$m e_stabilized)")" "$pex" \
            "$(fmt "$(num invivo-$m e_stabilized)")" "$pin" \
            "$(fmt2 "$(num exvivo-$m mean)")" "$(fmt2 "$(num exvivo-$m p95)")" \
            "$(fmt2 "$(num invivo-$m mean)")" "$(fmt2 "$(num invivo-$m p95)")"
    done
    echo
    echo "Hull pixels: ex-vivo $(num exvivo-bspline pixels) over $(num exvivo-bspline frames) frames,"
    echo "in-vivo $(num invivo-bspline pixels) over $(num invivo-bspline frames) frames."
    if [ -n "$LM_RUNS" ]; then
        echo
        echo "Landmarks (issue 19, docs/landmarks.md): up to $LANDMARKS tissue landmarks chosen in frame 0"
        echo "inside the markers' hull, predicted in every later frame by TPS on the truth's tag centres,"
        echo "found and judged by \`stillheart-eval --landmarks\`; the accepted ones are correspondences beside"
        echo "the markers (\`--landmarks-points\`). No landmark rows for rbf-local and the Gaussian:"
        echo "\`stillheart warp\` leaves landmarks out for them, worse with them. The 4-tag rows keep the four"
        echo "tags nearest the corners of the field (their hull: ex-vivo $(num exvivo-tps-4tags pixels),"
        echo "in-vivo $(num invivo-tps-4tags pixels) pixels)."
        echo
        echo "| preset | tags | landmarks chosen | accepted (landmark-frames) | accepted vs truth: mean / max px | over 1 px |"
        echo "|---|---|---|---|---|---|"
        for p in $PRESETS; do
            for v in "" 4; do
                j=$p-landmarks$v
                printf '| %s | %s | %s | %s | %s / %s | %s |\n' "$p" "${v:-all}" "$(num "$j" seeded)" \
                    "$(num "$j" accepted)" "$(fmt "$(num "$j" mean)")" "$(fmt "$(num "$j" max)")" "$(num "$j" over_1px)"
            done
        done
    fi
    echo
    echo "![e per method and preset](table2.png)"
    echo
    echo "Heatmaps (I_error, viridis up to 0.2, contours every 0.04): <preset>-<method>.png."
    echo "Made by \`make table2\` in ${secs} s${LM_RUNS:+ (the landmark rows ${lm_secs} s of it)}."
} > "$md"
stamp "done: $md"
cat "$md"
