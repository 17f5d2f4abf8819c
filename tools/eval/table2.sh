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
set -eu
BUILD=${1:?usage: table2.sh BUILD OUTDIR}
OUT=${2:?usage: table2.sh BUILD OUTDIR}
METHODS="affine pwlinear bspline rbf-local tps gaussian"
PRESETS="exvivo invivo"
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval WARP=$BUILD/stillheart
PLOT=$BUILD/tools/eval/table2-plot
for b in "$RENDER" "$EVAL" "$WARP" "$PLOT"; do
    [ -x "$b" ] || { echo "table2: $b is not built" >&2; exit 1; }
done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s)
stamp() { echo "table2: [$(( $(date +%s) - start )) s] $*" >&2; }

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
        "$WARP" warp --quiet --threads 2 --method "$m" --points "$dir/points.csv" \
            "$dir/cam0.y4m" "$dir/stabilized.y4m"
        "$EVAL" --quiet --json --points "$dir/points.csv" --truth "$dir" --method "$m" \
            --heatmap "$OUT/$p-$m.png" "$dir/stabilized.y4m" > "$OUT/json/$p-$m.json"
        rm -f "$dir/stabilized.y4m"
    done
    [ "${KEEP_RENDERS:-1}" = 1 ] || rm -f "$dir/cam0.y4m"
done

# A number from the evaluator's one-line JSON: the first "key": value.
num() { sed -n "s/.*\"$2\": \([-0-9.eE+]*\).*/\1/p" "$OUT/json/$1.json" | head -1; }
fmt() { [ -n "$1" ] && printf '%.3f' "$1" || printf 'n/a'; }
fmt2() { [ -n "$1" ] && printf '%.2f' "$1" || printf 'n/a'; }

{
    echo "preset,method,e"
    for p in $PRESETS; do
        for m in unstabilized $METHODS; do echo "$p,$m,$(num "$p-$m" e_stabilized)"; done
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
    for row in "unstabilized:unstabilized:0.186:0.133" "affine:affine:0.054:0.088" \
        "bspline:B-Spline:0.037:0.076" "pwlinear:piecewise linear:0.039:0.076" \
        "rbf-local:RBF (locally supp.):0.040:0.083" "tps:RBF (TPS):0.038:0.077" \
        "gaussian:RBF (Gaussian):0.037:0.079"; do
        m=${row%%:*}; rest=${row#*:}; name=${rest%%:*}; rest=${rest#*:}
        pex=${rest%%:*}; pin=${rest#*:}
        printf '| %s | %s | %s | %s | %s | %s / %s | %s / %s |\n' "$name" \
            "$(fmt "$(num exvivo-$m e_stabilized)")" "$pex" \
            "$(fmt "$(num invivo-$m e_stabilized)")" "$pin" \
            "$(fmt2 "$(num exvivo-$m mean)")" "$(fmt2 "$(num exvivo-$m p95)")" \
            "$(fmt2 "$(num invivo-$m mean)")" "$(fmt2 "$(num invivo-$m p95)")"
    done
    echo
    echo "Hull pixels: ex-vivo $(num exvivo-bspline pixels) over $(num exvivo-bspline frames) frames,"
    echo "in-vivo $(num invivo-bspline pixels) over $(num invivo-bspline frames) frames."
    echo "![e per method and preset](table2.png)"
    echo
    echo "Heatmaps (I_error, viridis up to 0.2, contours every 0.04): <preset>-<method>.png."
    echo "Made by \`make table2\` in ${secs} s."
} > "$md"
stamp "done: $md"
cat "$md"
