#!/bin/sh
# The daemon replaying a 1080p phantom (exvivo: 16 tags) as fast as it can, 2 threads, into the
# shared-memory buffer: fps, latency from frame available to published (median, p99, max), RSS.
# BENCH_DAEMON_FRAMES (default 1200) frames published, looping over a 200-frame recording.
# Once with detection (the product), once from a points file (detection left out).
B=$(dirname "$0")/..
DIR=${BENCH_DAEMON_DIR:-out/bench-daemon}
N=${BENCH_DAEMON_FRAMES:-1200}
[ -s "$DIR/cam0.y4m" ] || "$B/stillheart-render" --preset exvivo --frames 200 --cameras 1 --out "$DIR" >/dev/null || exit 1
[ -s "$DIR/points.csv" ] || "$B/stillheart" track --ids 0-15 "$DIR/cam0.y4m" > "$DIR/points.csv" 2>/dev/null || exit 1
for mode in detect points; do
    extra=""; [ $mode = points ] && extra="--points $DIR/points.csv"
    t0=$(date +%s.%N)
    line=$("$B/stillheart" run --source "y4m:$DIR/cam0.y4m" --no-realtime --loop --threads 2 --method tps \
        --sink shm:/stillheart-bench --group= --quiet --stats --max-frames "$N" $extra) || exit 1
    t1=$(date +%s.%N)
    fps=$(echo "$N $t0 $t1" | awk '{printf "%.1f", $1 / ($3 - $2)}')
    echo "daemon 1920x1080 tps 2 threads, markers $mode: $fps frames/s over $N frames (process start included); $line"
done
rm -f /dev/shm/stillheart-bench
