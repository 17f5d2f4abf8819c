#!/bin/sh
# make bench: `stillheart warp` as a user runs it, the whole process (reading the Y4M, the models,
# the warp, writing the Y4M), beside the 20-line Python script a user would write instead
# (warp_remap.py: one precomputed map applied with cv2.remap to every plane, one thread), on the
# same 60 frames of 1920x1080 4:4:4 with 16 markers (issue 20; goal <= 0.5x for every method).
# The recording (stillheart-synth: minutes to make) and the script's map (`stillheart warp
# --map-out`, tps) are made once and kept in BENCH_WARP_PROCESS_DIR (default out/bench-warp-process).
# Each side runs BENCH_WARP_PROCESS_RUNS times (default 3), alternating; medians of the process's
# CPU time (user + system: on this shared machine it leaves out the time others hold the cores)
# and of its wall time. The last line: tps with --metric, the paper's e as it was on by default.
B=$(dirname "$0")/..
DIR=${BENCH_WARP_PROCESS_DIR:-out/bench-warp-process}
RUNS=${BENCH_WARP_PROCESS_RUNS:-3}
PEER=$(dirname "$0")/warp_remap.py
# the first Python that has the cv2 binding (python3-opencv: scripts/install-deps.sh --bench);
# a python3 of its own on PATH (pyenv, a venv) may lack it
PY=""
for p in ${PYTHON:-} python3 /usr/bin/python3; do
    if "$p" -c 'import cv2' 2>/dev/null; then PY=$p; break; fi
done
[ -n "$PY" ] || { echo "bench_warp_process: no Python with cv2 (scripts/install-deps.sh --bench)" >&2; exit 1; }
if [ ! -e "$DIR/.complete" ]; then
    rm -f "$DIR/map.npy"
    echo "bench_warp_process: making the recording in $DIR (once; minutes)" >&2
    "$B/stillheart-synth" --width 1920 --height 1080 --frames 60 --markers 16 --format yuv444 \
        --out "$DIR" --quiet || exit 1
    touch "$DIR/.complete"
fi
[ -s "$DIR/map.npy" ] || "$B/stillheart" warp --quiet --method tps --points "$DIR/points.csv" \
    --map-out "$DIR/map.npy" "$DIR/video.y4m" /dev/null || exit 1
T=$(mktemp -d "${TMPDIR:-/tmp}/sh-bench-warp-process.XXXXXX")
trap 'rm -rf "$T"' EXIT
"$PY" - "$B/stillheart" "$PY" "$PEER" "$DIR" "$T" "$RUNS" <<'PY' || exit 1
import os, statistics, subprocess, sys, time
app, py, peer, d, t, runs = sys.argv[1:6] + [int(sys.argv[6])]
video, points, out = f"{d}/video.y4m", f"{d}/points.csv", f"{t}/out.y4m"

def run(cmd):
    """(CPU s, wall s) of one process and its children"""
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.monotonic() - t0
    if status:
        sys.exit("bench_warp_process: %s failed (status %d)" % (" ".join(cmd), status))
    frames = lambda f: os.path.getsize(f) - len(open(f, "rb").readline())  # headers differ in tags
    if frames(out) != frames(video):
        sys.exit("bench_warp_process: %s wrote %d bytes of frames, not %d" % (cmd[0], frames(out), frames(video)))
    os.remove(out)
    return ru.ru_utime + ru.ru_stime, wall

print("machine: %d cores, load %s (1, 5, 15 min); 1920x1080 4:4:4, 60 frames, 16 markers; whole "
      "process, medians of %d runs" % (os.cpu_count(), " ".join(open("/proc/loadavg").read().split()[:3]), runs))
print("peer: %s (cv2 %s, one thread, one precomputed map)"
      % (os.path.basename(peer), subprocess.run([py, "-c", "import cv2; print(cv2.__version__)"],
                                                capture_output=True, text=True).stdout.strip()))
print("%-16s %9s %9s %7s %9s %9s %7s" % ("method", "ours cpu", "peer cpu", "ratio", "ours wall", "peer wall", "ratio"))
for method in ["affine", "pwlinear", "bspline", "rbf-local", "tps", "gaussian", "tps --metric"]:
    ours_cmd = [app, "warp", "--quiet", "--threads", "1", "--method"] + method.split() + ["--points", points, video, out]
    ours, theirs = [], []
    for _ in range(runs):
        ours.append(run(ours_cmd))
        theirs.append(run([py, peer, f"{d}/map.npy", video, out]))
    oc, ow = (statistics.median(x[i] for x in ours) for i in (0, 1))
    pc, pw = (statistics.median(x[i] for x in theirs) for i in (0, 1))
    print("%-16s %8.2fs %8.2fs %7.2f %8.2fs %8.2fs %7.2f" % (method, oc, pc, oc / pc, ow, pw, ow / pw), flush=True)
PY
