#!/bin/sh
# The daemon replaying a 1080p phantom (exvivo: 16 tags) as fast as it can, 2 threads, into the
# shared-memory buffer: fps, latency from frame available to published (median, p99, max), RSS.
# BENCH_DAEMON_FRAMES (default 1200) frames published, looping over a 200-frame recording that is
# periodic (stillheart-render --periodic: its end joins its start, so the tracker runs on as it
# would on a live camera instead of starting afresh at every loop).
# Once with detection (the product), once from a points file (detection left out), then
# BENCH_DAEMON_RT_FRAMES (default 400) in real time with detection.
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
rm -rf "$T"
rm -f /dev/shm/stillheart-bench
