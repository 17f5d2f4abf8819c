#!/bin/sh
# The daemon replaying a 1080p phantom (exvivo: 16 tags) as fast as it can, 2 threads, into the
# shared-memory buffer: fps, latency from frame available to published (median, p99, max), RSS.
# BENCH_DAEMON_FRAMES (default 1200) frames published, looping over a 200-frame recording that is
# periodic (stillheart-render --periodic: its end joins its start, so the tracker runs on as it
# would on a live camera instead of starting afresh at every loop).
# Once with detection (the product), once from a points file (detection left out), then
# BENCH_DAEMON_RT_FRAMES (default 400) in real time with detection; then at 4K (below).
B=$(dirname "$0")/..
DIR=${BENCH_DAEMON_DIR:-out/bench-daemon}
N=${BENCH_DAEMON_FRAMES:-1200}
if ! head -c 256 "$DIR/cam0.y4m" 2>/dev/null | head -n 1 | grep -q XLOOP=SEAMLESS; then
    rm -f "$DIR/points.csv"
    "$B/stillheart-render" --preset exvivo --frames 200 --rig paper --cameras 1 --periodic --out "$DIR" >/dev/null || exit 1
fi
[ -s "$DIR/points.csv" ] || "$B/stillheart" track --ids 0-15 "$DIR/cam0.y4m" > "$DIR/points.csv" 2>/dev/null || exit 1
echo "cores: $(nproc)"
T=$(mktemp -d /tmp/sh-bench-daemon.XXXXXX)
# The per-frame stages from --trace: the processing thread's CPU time (medians, p99).
stages() {
    python3 - "$1" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
def q(k, p):
    v = sorted(float(r[k]) for r in rows)
    return v[int((len(v) - 1) * p)]
print("stage CPU ms median / p99: markers %.2f / %.2f, model %.2f / %.2f, warp (this thread) %.2f / %.2f"
      % tuple(q(k, p) for k in ("markers_ms", "model_ms", "warp_ms") for p in (.5, .99)))
PY
}
for mode in detect points; do
    extra=""; [ $mode = points ] && extra="--points $DIR/points.csv"
    t0=$(date +%s.%N)
    line=$("$B/stillheart" run --source "y4m:$DIR/cam0.y4m" --no-realtime --loop --threads 2 --method tps \
        --sink shm:/stillheart-bench --group= --quiet --stats --max-frames "$N" --trace "$T/$mode.csv" $extra) || exit 1
    t1=$(date +%s.%N)
    fps=$(echo "$N $t0 $t1" | awk '{printf "%.1f", $1 / ($3 - $2)}')
    echo "daemon 1920x1080 tps 2 threads, markers $mode: $fps frames/s over $N frames (process start included); $line"
    echo "  $(stages "$T/$mode.csv")"
done
# In real time (the recording's 23 frames/s, as in the operating room) a frame waits for no other:
# the latency is the processing alone.
RT=${BENCH_DAEMON_RT_FRAMES:-400}
line=$("$B/stillheart" run --source "y4m:$DIR/cam0.y4m" --realtime --loop --threads 2 --method tps \
    --sink shm:/stillheart-bench --group= --quiet --stats --max-frames "$RT" --trace "$T/rt.csv" 2>/dev/null) || exit 1
echo "daemon 1920x1080 tps 2 threads, markers detect, real time: $line"
echo "  $(stages "$T/rt.csv")"

# Issue 20's 4K tower: 3840x2160 I420, as fast as possible, 2 threads, into the segment, tps and
# bspline, 16 tags (the preset's 10 mm) and 32 (8 mm: 32 of 10 mm do not fit its patch). Each
# recording is 66 periodic frames (two whole beats: it loops without a jump), 820 MB, made once
# and kept: BENCH_DAEMON_4K_DIR (16 tags, default out/bench-daemon-4k) and BENCH_DETECT_TRACK_4K_DIR
# (32 tags, bench_detect_track's, default out/bench-detect-track-4k); .complete marks one made
# whole. BENCH_DAEMON_4K_FRAMES (default 600) frames a run; 0 leaves the 4K runs out.
N4=${BENCH_DAEMON_4K_FRAMES:-600}
render_4k() { # DIR, extra renderer options
    [ -f "$1/.complete" ] && return 0
    echo "rendering 66 phantom frames (3840x2160, exvivo, periodic) into $1, once..."
    mkdir -p "$1" && "$B/stillheart-render" --preset exvivo --rig paper --cameras 1 --width 3840 --height 2160 \
        --periodic --seed 3 --frames 66 $2 --out "$1" >/dev/null && : > "$1/.complete"
}
load() { cut -d' ' -f1 /proc/loadavg; }
if [ "$N4" -gt 0 ]; then
    D16=${BENCH_DAEMON_4K_DIR:-out/bench-daemon-4k}
    D32=${BENCH_DETECT_TRACK_4K_DIR:-out/bench-detect-track-4k}
    render_4k "$D16" "" || exit 1
    render_4k "$D32" "--markers 32 --tag-size 8" || exit 1
    for tags in 16 32; do
        dir=$D16; [ $tags = 32 ] && dir=$D32
        for method in tps bspline; do
            l0=$(load)
            t0=$(date +%s.%N)
            line=$("$B/stillheart" run --source "y4m:$dir/cam0.y4m" --no-realtime --loop --threads 2 --method $method \
                --ids 0-$((tags - 1)) --sink shm:/stillheart-bench-4k --group= --quiet --stats --max-frames "$N4" \
                --trace "$T/4k.csv") || exit 1
            t1=$(date +%s.%N)
            fps=$(echo "$N4 $t0 $t1" | awk '{printf "%.1f", $1 / ($3 - $2)}')
            echo "daemon 3840x2160 $tags tags $method 2 threads, markers detect: $fps frames/s over $N4 frames (process start included), load $l0 -> $(load); $line"
            echo "  $(stages "$T/4k.csv")"
        done
    done
    rm -f /dev/shm/stillheart-bench-4k
fi
rm -rf "$T"
rm -f /dev/shm/stillheart-bench
