#!/bin/sh
# Four tags through the product, without and with carried frames (landmarks.h, "Carried frames";
# docs/landmarks.md): both presets, seeds 1-4, the paper rig's camera (1920x1080), the instrument
# and blood, the four tags nearest the corners of the 16-tag layout rendered alone
# (--only-markers, as `make landmarks-table`'s -4only rows). For each: `stillheart track --ids
# THE_FOUR --landmarks 400 --landmarks-sparse` without and with --landmarks-carry, `stillheart warp
# --method tps` through each, e and the geometric error against the truth; and the daemon in test
# mode on the same file (its marker rows: `stillheart run --points ... --landmarks 400
# --landmarks-sparse 1 --min-markers 3`, its own landmarks) without and with --landmarks-carry 1,
# the same, and its frames carried or refused by the landmarks. About 15 minutes on 2 cores.
#   sh tools/eval/carry.sh BUILD OUTDIR
# Writes OUTDIR/carry.csv and OUTDIR/json/*.json; renders go to OUTDIR/work and are deleted as they
# are measured. FRAMES (default 200) sets the length.
set -eu
BUILD=$(cd "$1" && pwd) OUT=$2 HERE=$(cd "$(dirname "$0")" && pwd)
RENDER=$BUILD/stillheart-render EVAL=$BUILD/stillheart-eval APP=$BUILD/stillheart
FRAMES=${FRAMES:-200}
for b in "$RENDER" "$EVAL" "$APP"; do [ -x "$b" ] || { echo "carry: $b is not built" >&2; exit 1; }; done
mkdir -p "$OUT/work" "$OUT/json"
start=$(date +%s)
stamp() { echo "carry: [$(( $(date +%s) - start )) s] $*" >&2; }
. "$HERE/common.sh"
# geo NAME: e, the geometric error's mean and the raw frames of the evaluator's JSON NAME (one
# line: the geometric object's mean is its only "mean")
geo() { echo "$(num "$1" e_stabilized),$(num "$1" mean),$(num "$1" raw_frames)"; }
# count STATUS REASON_PREFIX TRACE: the trace's frames with that status and reason
count() { awk -F, -v s="$1" -v r="\"$2" 'NR > 1 && $2 == s && index($5, r) == 1 { n++ } END { print n + 0 }' "$3"; }

echo "run,carry,track_carried,warp_e,warp_geo,warp_raw,daemon_e,daemon_geo,daemon_raw,daemon_carried,daemon_carry_refused" > "$OUT/carry.csv"
for p in exvivo invivo; do
    for seed in 1 2 3 4; do
        full=$OUT/work/$p-$seed dir=$OUT/work/$p-$seed-4only
        stamp "render $p seed $seed, the four corner tags alone ($FRAMES frames, 1920x1080, occlusions)"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --seed "$seed" --frames 1 --quiet --out "$full"
        "$EVAL" --truth "$full" --export-points "$full/points.csv"
        ids=$(awk -F, -f "$HERE/corners.awk" "$full/points.csv" | tr '|' ,)
        rm -rf "$full"
        "$RENDER" --preset "$p" --rig paper --cameras 1 --occlusions --seed "$seed" --frames "$FRAMES" \
            --only-markers "$ids" --quiet --out "$dir"
        for c in 0 1; do
            n=$p-$seed-carry$c
            flag=$([ "$c" = 1 ] && echo --landmarks-carry || true)
            (cd "$dir" && "$APP" track --quiet --ids "$ids" --landmarks 400 --landmarks-sparse $flag --stats --json \
                cam0.y4m > "track$c.csv" 2> "track$c.err")
            carried=$(sed -n 's/.*"carried_frames": \([0-9]*\).*/\1/p' "$dir/track$c.err")
            "$APP" warp --quiet --threads 2 --method tps --points "$dir/track$c.csv" "$dir/cam0.y4m" "$dir/stab.y4m"
            "$EVAL" --quiet --json --truth "$dir" --points "$dir/track$c.csv" "$dir/stab.y4m" "$dir/cam0.y4m" > "$OUT/json/$n-warp.json"
            rm -f "$dir/run.y4m"
            "$APP" run --source "y4m:$dir/cam0.y4m" --no-realtime --no-loop --points "$dir/track$c.csv" --method tps \
                --landmarks 400 --landmarks-sparse 1 --min-markers 3 --landmarks-carry "$c" --sink none --group= \
                --threads 2 --quiet --record "$dir/run.y4m" --trace "$dir/trace.csv" --trace-points "$dir/used.csv"
            "$EVAL" --quiet --json --truth "$dir" --points "$dir/used.csv" "$dir/run.y4m" "$dir/cam0.y4m" > "$OUT/json/$n-daemon.json"
            echo "$p-$seed,$c,${carried:-0},$(geo "$n-warp"),$(geo "$n-daemon"),$(count degraded carried "$dir/trace.csv"),$(count raw "too few markers (2); landmarks" "$dir/trace.csv")" >> "$OUT/carry.csv"
        done
        rm -rf "$dir"
    done
done
stamp "done: $OUT/carry.csv"
column -s, -t < "$OUT/carry.csv"
