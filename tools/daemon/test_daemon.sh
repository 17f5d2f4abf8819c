#!/bin/sh
# Daemon tests (run by make check as build/tests/test_daemon): end to end against
# `stillheart warp`, gating on an occlusion sequence, bad configs refused, SIGTERM within 1 s,
# sd_notify against a socket this test opens. Prints cmocka-style summary lines.
# Over 600 lines: one script because its checks share one render, its points, warp's output, the
# temporary folder and the pass/fail counters; make check runs it as the one test binary it stands
# for.
# links resolved: make check-arm64 runs the tests through links in lane folders
B=${BUILD:-$(dirname "$(readlink -f "$0")")/..}
T=$(mktemp -d /tmp/sh-daemon-test.XXXXXX)
trap 'rm -rf "$T"; rm -f "/dev/shm$SHM"' EXIT
pass=0; fail=0
ok()  { echo "[       OK ] $1"; pass=$((pass + 1)); }
bad() { echo "[  FAILED  ] $1: $2"; fail=$((fail + 1)); }
SHM=/sh-dtest-$$
# Up to 30 s for the daemon's segment before a reader opens it: under qemu-aarch64 on a loaded
# machine, with a disk stalling for seconds, a daemon took longer than the 1 s the cases waited
# before, and stillheart-cat found no segment (issue 21's loops at 25e3aeb and 4a644ff).
wait_segment() { i=0; while [ $i -lt 300 ] && [ ! -e "/dev/shm$SHM" ]; do sleep 0.1; i=$((i + 1)); done; }
RUN="$B/stillheart run --group= --quiet"
# What a daemon frame may differ from warp's in the two comparisons below (their python imports
# it: PYTHONPATH=$T). The warp's grid is refined when a frame's map needs it and stays refined,
# so a frame after dropped ones can see a coarser grid than warp's run through every frame:
# either map is within max_error (0.05 px) of the exact one, so the two differ by at most 0.1 px
# times the steepest step between neighbouring luma pixels of the camera frame f (w x h), and 1
# for rounding.
cat > "$T/bound.py" <<'PY'
def bound(f, w, h):
    g = max(max(abs(f[y * w + x] - f[y * w + x + 1]) for x in range(w - 1)) for y in range(h))
    g = max(g, max(abs(f[y * w + x] - f[y * w + w + x]) for y in range(h - 1) for x in range(w)))
    return 1 + -(-g // 10)
PY

"$B/stillheart-render" --preset exvivo --frames 40 --cameras 1 --width 640 --height 360 --out "$T/ph" >/dev/null 2>&1 || { bad render "stillheart-render failed"; }
"$B/stillheart" track --ids 0-15 "$T/ph/cam0.y4m" > "$T/points.csv" 2>/dev/null || bad track "stillheart track failed"

# 1. end to end: what the daemon shows (its record and the shm read back) equals stillheart warp.
"$B/stillheart" warp --method tps --threads 2 --points "$T/points.csv" "$T/ph/cam0.y4m" "$T/warp.y4m" --quiet
$RUN --source "y4m:$T/ph/cam0.y4m" --no-loop --no-realtime --sink none --points "$T/points.csv" \
    --method tps --threads 2 --record "$T/rec.y4m" --min-markers 3 && cmp -s "$T/rec.y4m" "$T/warp.y4m" \
    && ok "record equals stillheart warp" || bad "record equals stillheart warp" "differs"
# [sink] outside = dimmed-raw, every pixel against what docs/warp.md promises, computed here: inside
# the hull of the frame's model (its markers' reference positions, frame 0's here) the bytes of
# stillheart warp; outside it the camera's frame halfway to black, (v + b + 1) // 2 with b = 16 for
# (limited-range) luma and 128 for chroma; within 2 luma pixels (1 chroma pixel) of the inside,
# BT.601 cyan. Then in real time, the key reloaded from black to dimmed-raw (SIGHUP): each frame read
# back from the segment equals the record's of its sequence number, and the record's warped frames
# turn from black to lit outside once, without anything reopened.
$RUN --source "y4m:$T/ph/cam0.y4m" --no-loop --no-realtime --sink none --points "$T/points.csv" \
    --method tps --threads 2 --record "$T/dim.y4m" --min-markers 3 --outside dimmed-raw
cat > "$T/outside.py" <<'PY'
import csv, math
def frames(p):
    hdr, rest = open(p, 'rb').read().split(b'\n', 1)
    w = int([t for t in hdr.split() if t.startswith(b'W')][0][1:]); h = int([t for t in hdr.split() if t.startswith(b'H')][0][1:])
    n = w * h * 3 // 2
    return [rest[i + 6:i + 6 + n] for i in range(0, len(rest), 6 + n)], w, h
def hull(pts):  # Andrew's monotone chain, counter-clockwise in x right, y up
    pts = sorted(set(pts))
    def half(ps):
        out = []
        for p in ps:
            while len(out) > 1 and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0]) <= 0: out.pop()
            out.append(p)
        return out[:-1]
    return half(pts) + half(pts[::-1])
def extent(poly, Y):  # [lo, hi] of the line at height Y inside the convex polygon, None if it misses
    lo, hi = -math.inf, math.inf
    for (ax, ay), (bx, by) in zip(poly, poly[1:] + poly[:1]):
        # inside: (bx - ax) (Y - ay) - (by - ay) (X - ax) >= 0
        c, k = (bx - ax) * (Y - ay) + (by - ay) * ax, by - ay
        if k == 0:
            if c < -1e-9: return None
        elif k > 0: hi = min(hi, c / k)
        else: lo = max(lo, c / k)
    return (lo, hi) if lo <= hi + 1e-9 else None
def expected(raw, warp, poly, w, h):
    """The frame dimmed-raw must be, and the pixels too near the hull's edge to decide."""
    out, at, unsure = bytearray(), 0, 0
    cw, ch = (w + 1) // 2, (h + 1) // 2
    for p, (pw, ph, s, o, d, b, cyan) in enumerate([(w, h, 1, 0, 2, 16, 16 + 219 * 0.701),
                                                     (cw, ch, 2, 0.5, 1, 128, 128 + 224 * 0.299 / 1.772),
                                                     (cw, ch, 2, 0.5, 1, 128, 128 - 224 * 0.701 / 1.402)]):
        dim = bytes((v + b + 1) // 2 for v in range(256))
        rows = []
        for y in range(ph):
            e = extent(poly, s * y + o)
            f, l = (0, -1) if e is None else (max(0, math.ceil((e[0] - o) / s)), min(pw - 1, math.floor((e[1] - o) / s)))
            if e is not None and any(abs(s * x + o - v) < 1e-6 for x in (f - 1, f, l, l + 1) for v in e): unsure += 1
            rows.append((f, l))
        for y in range(ph):
            r = bytearray(raw[at + y * pw:at + (y + 1) * pw].translate(dim))
            for k in range(max(0, y - d), min(ph, y + d + 1)):
                f, l = rows[k]
                if f <= l: r[max(0, f - d):l + d + 1] = bytes([round(cyan)]) * (min(pw, l + d + 1) - max(0, f - d))
            f, l = rows[y]
            if f <= l: r[f:l + 1] = warp[at + y * pw + f:at + y * pw + l + 1]
            out += r
        at += pw * ph
    return bytes(out), unsure
def model_hulls(points, reference=0):
    """Per frame, the hull of its model: the reference positions of the markers the frame has."""
    rows = list(csv.DictReader(open(points)))
    ref = {r['id']: (float(r['x']), float(r['y'])) for r in rows if int(r['frame']) == reference}
    ids = {}
    for r in rows: ids.setdefault(int(r['frame']), set()).add(r['id'])
    return {f: hull([ref[i] for i in s if i in ref]) for f, s in ids.items()}
PY
PYTHONPATH="$T" python3 - "$T/dim.y4m" "$T/warp.y4m" "$T/ph/cam0.y4m" "$T/points.csv" <<'PY' \
    && ok "outside = dimmed-raw: the warp's bytes inside the hull, the camera dimmed outside, a cyan boundary" \
    || bad "outside = dimmed-raw: the warp's bytes inside the hull, the camera dimmed outside, a cyan boundary" "see above"
import sys
from outside import frames, expected, model_hulls
(dim, w, h), (warp, _, _), (raw, _, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[3])
hulls = model_hulls(sys.argv[4])
if len(dim) != len(warp) or len(dim) < 30: print(len(dim), "frames recorded,", len(warp), "by warp"); sys.exit(1)
for i, (f, g, r) in enumerate(zip(dim, warp, raw)):
    want, unsure = expected(r, g, hulls[i], w, h)
    if unsure: print("frame %d: %d rows with a pixel centre on the hull's edge: not decided here" % (i, unsure)); sys.exit(1)
    if f != want:
        k = next(j for j, (x, y) in enumerate(zip(f, want)) if x != y)
        print("frame %d: byte %d (plane offset) is %d, want %d (warp %d, camera %d)" % (i, k, f[k], want[k], g[k], r[k])); sys.exit(1)
PY
printf '[sink]\noutside = black\n' > "$T/outside.ini"
"$B/stillheart" run --group= --config "$T/outside.ini" --source "y4m:$T/ph/cam0.y4m" --loop --realtime --sink "shm:$SHM" \
    --points "$T/points.csv" --method tps --threads 2 --min-markers 3 --record "$T/dim-rt.y4m" --record-sync-ms 0 \
    2> "$T/dim-rt.log" & pid=$!
wait_segment
"$B/stillheart-cat" --name "$SHM" --count 40 --timeout 10 -v > "$T/dim-cat.y4m" 2> "$T/dim-cat.log" & cat_pid=$!
# SIGHUP once 10 frames are recorded: the next warped frames are dimmed outside, nothing reopened
# (up to 60 s: the record does not exist until the daemon has started, see wait_segment)
for i in $(seq 600); do n=$(grep -c FRAME "$T/dim-rt.y4m" 2>/dev/null); [ "${n:-0}" -ge 10 ] && break; sleep 0.1; done
printf '[sink]\noutside = dimmed-raw\n' > "$T/outside.ini"; kill -HUP $pid
for i in $(seq 100); do grep -q "config reloaded" "$T/dim-rt.log" && break; sleep 0.1; done
wait $cat_pid; kill $pid; wait $pid
rm -f "/dev/shm$SHM" # closed, not unlinked: the next run's reader must not find it
PYTHONPATH="$T" python3 - "$T/dim-cat.y4m" "$T/dim-rt.y4m" "$T/dim-cat.log" "$T/ph/cam0.y4m" "$T/dim-rt.log" <<'PY' \
    && ok "outside reloaded black -> dimmed-raw in real time: the segment's frames are the record's" \
    || bad "outside reloaded black -> dimmed-raw in real time: the segment's frames are the record's" "see above"
import re, sys
from outside import frames
(a, w, h), (rec, _, _), (raw, _, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[4])
seqs = [int(s) for s in re.findall(r'^frame (\d+) ', open(sys.argv[3]).read(), re.M)]
log = open(sys.argv[5]).read()
if len(a) < 30 or len(seqs) != len(a): print(len(a), "frames read back,", len(seqs), "-v lines"); sys.exit(1)
differ = [s for f, s in zip(a, seqs) if s > len(rec) or rec[s - 1] != f]
# the corner pixel lies outside the hull: black in a plain warp, the camera's dimmed after the reload
corners = ''.join('L' if f[0] else 'B' for f in rec if f not in raw)
if differ or not re.fullmatch('B{3,}L{3,}', corners) or "config reloaded (gating)" not in log or "cameras reopened" in log:
    print("frames read back unlike the record's:", differ, "; warped frames' corners, B black, L lit:", corners, log[-300:]); sys.exit(1)
PY
# In real time the reference is the first frame processing takes, and the camera does not wait
# for it: a daemon that starts behind its camera (qemu-aarch64 on a busy machine: issue 21) takes
# frame 1 or later, and every frame it shows is warped onto that one. So its frames are compared
# with `stillheart warp --reference N`, N the frame its log names. LOG OUT
warp_as_logged() {
    n=$(sed -n 's/.*-- reference: frame \([0-9]*\),.*/\1/p' "$1" | head -1)
    [ -n "$n" ] || { echo "no 'reference: frame' line in $1:"; tail -5 "$1"; return 1; }
    [ "$n" = 0 ] && { cp "$T/warp.y4m" "$2"; return 0; }
    echo "(the daemon took frame $n as its reference)"
    "$B/stillheart" warp --method tps --threads 2 --points "$T/points.csv" --reference "$n" "$T/ph/cam0.y4m" "$2" --quiet
}
# the window forced: the camera at 20,000 frames/s outruns the start of processing, frames are
# dropped from the first, and what is recorded is still warp's onto the reference the log names
python3 -c 'import re, sys; h, r = open(sys.argv[1], "rb").read().split(b"\n", 1); open(sys.argv[2], "wb").write(re.sub(rb" F\d+:\d+", b" F20000:1", h) + b"\n" + r)' \
    "$T/ph/cam0.y4m" "$T/fast.y4m"
"$B/stillheart" run --group= --source "y4m:$T/fast.y4m" --no-loop --realtime --sink none --points "$T/points.csv" \
    --method tps --threads 2 --record "$T/fast-rec.y4m" --trace "$T/fast.csv" --min-markers 3 2> "$T/fast.log"
warp_as_logged "$T/fast.log" "$T/fast-warp.y4m" && PYTHONPATH="$T" python3 - "$T/fast-rec.y4m" "$T/fast-warp.y4m" "$T/fast.csv" "$T/ph/cam0.y4m" <<'PY' \
    && ok "a daemon behind its camera from the first frame: record equals warp onto its reference" \
    || bad "a daemon behind its camera from the first frame: record equals warp onto its reference" "see above"
import csv, sys
def frames(p):
    hdr, rest = open(p, 'rb').read().split(b'\n', 1)
    w = int([t for t in hdr.split() if t.startswith(b'W')][0][1:]); h = int([t for t in hdr.split() if t.startswith(b'H')][0][1:])
    return [rest[i + 6:i + 6 + w * h * 3 // 2] for i in range(0, len(rest), 6 + w * h * 3 // 2)], w, h
(rec, w, h), (warp, _, _), (raw, _, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[4])
shown = [int(r['index']) for r in csv.DictReader(open(sys.argv[3]))]
# a frame after dropped ones can see a coarser grid than warp's run through every frame (bound.py)
from bound import bound
bad = []
for f, i in zip(rec, shown):
    d = max(abs(a - b) for a, b in zip(f, warp[i]))
    if d > 1 and d > bound(raw[i], w, h): bad.append("frame %d: max diff %d > %d" % (i, d, bound(raw[i], w, h)))
old = [i for f, i in zip(rec, shown) if min(max(abs(x - y) for x, y in zip(f[::97], g[::97])) for g in frames(sys.argv[2].replace("fast-warp", "warp"))[0]) > 1]
if len(rec) != len(shown) or not rec or bad: print(len(rec), "frames recorded,", len(shown), "traced;", bad); sys.exit(1)
print("frames %s shown; against reference 0, as the test assumed before, %d of them would match nothing" % (shown, len(old)))
PY
# shm: real time (23 fps) so the reader sees every frame; each frame read back equals warp's
"$B/stillheart" run --group= --source "y4m:$T/ph/cam0.y4m" --no-loop --realtime --sink "shm:$SHM" --points "$T/points.csv" \
    --method tps --threads 2 --min-markers 3 2> "$T/shm.log" & pid=$!
wait_segment
"$B/stillheart-cat" --name "$SHM" --count 20 --timeout 5 -v > "$T/cat.y4m" 2> "$T/cat.log"
wait $pid
warp_as_logged "$T/shm.log" "$T/warp-shm.y4m"
PYTHONPATH="$T" python3 - "$T/cat.y4m" "$T/warp-shm.y4m" "$T/ph/cam0.y4m" "$T/cat.log" <<'PY' && ok "shm frames equal stillheart warp" || bad "shm frames equal stillheart warp" "see above"
import re, sys
log = open(sys.argv[4]).read()
def frames(p):
    d = open(p, 'rb').read()
    if b'\n' not in d: print(p, "holds no Y4M header (%d bytes); stillheart-cat said:" % len(d), log[-500:]); sys.exit(1)
    hdr, rest = d.split(b'\n', 1)
    w = int([t for t in hdr.split() if t.startswith(b'W')][0][1:]); h = int([t for t in hdr.split() if t.startswith(b'H')][0][1:])
    n = w * h * 3 // 2
    out = []
    while rest:
        line, rest = rest.split(b'\n', 1) if b'\n' in rest else (rest, b'')
        if line != b'FRAME' or len(rest) < n:
            print(p, "frame", len(out), "is not whole: line %r, %d of %d bytes" % (line[:20], min(len(rest), n), n)); sys.exit(1)
        out.append(rest[:n]); rest = rest[n:]
    return out, w, h
(a, w, h), (b, _, _), (raw, _, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[3])
shown = re.findall(r'^frame (\d+) (.*)$', log, re.M)  # stillheart-cat -v: sequence, status and why
if len(a) < 15: print("only", len(a), "frames read back; stillheart-cat said:", log[-500:]); sys.exit(1)
def where(f, g):  # the largest difference over the whole frame, and its place
    d, i = max((abs(x - y), i) for i, (x, y) in enumerate(zip(f, g)))
    plane, k = ('Y', i) if i < w * h else ('U', i - w * h) if i < w * h * 5 // 4 else ('V', i - w * h * 5 // 4)
    pw = w if plane == 'Y' else w // 2
    return "%d at %s x=%d y=%d" % (d, plane, k % pw, k // pw)
# a frame shown before the reference's models are ready is the camera's own (raw): on a slow
# machine (qemu-aarch64 under load) that can be several; every other one is warp's, within what a
# grid refined at other frames makes of it (bound.py, as for the forced case above)
from bound import bound
warped = 0
for i, f in enumerate(a):
    diffs = [max(abs(x - y) for x, y in zip(f[::97], g[::97])) for g in b]
    best = min(diffs)
    j = diffs.index(best)
    if best <= 1 or max(abs(x - y) for x, y in zip(f, b[j])) <= bound(raw[j], w, h):
        warped += 1
    elif not any(f == g for g in raw):
        seq, status = shown[i] if i < len(shown) else ("?", "? (no -v line)")
        k = min(range(len(raw)), key=lambda k: max(abs(x - y) for x, y in zip(f[::97], raw[k][::97])))
        print("frame %d read back (sequence %s, %s) matches no warp frame and no camera frame: nearest warp "
              "frame %d, max diff %s; nearest camera frame %d, max diff %s" % (i, seq, status, j, where(f, b[j]), k, where(f, raw[k])))
        sys.exit(1)
if warped < 5: print("only", warped, "of", len(a), "frames read back were warp's; statuses:", [s for _, s in shown]); sys.exit(1)
PY

# 1b. the hot loop allocates nothing (DESIGN.md): test mode on the render above with landmarks,
#    tps and pwlinear (a grid and the per-frame triangulation), frames 15 to 30 against the first
#    15 under tools/alloc/count.c (LD_PRELOAD): not one heap allocation more, in any library. Live,
#    libapriltag's detection allocates inside each call (docs/architecture.md). The plain build on
#    the host only: ASan replaces malloc itself, and the counter is built for the host.
if [ -z "${SH_TEST_EMULATED:-}" ] && [ -e "$B/tests/alloc_count.so" ] && ! ldd "$B/stillheart" 2>/dev/null | grep -q libasan; then
    for m in tps pwlinear; do
        for f in 15 30; do
            ALLOC_COUNT_OUT="$T/alloc$f" LD_PRELOAD="$B/tests/alloc_count.so" $RUN --source "y4m:$T/ph/cam0.y4m" \
                --no-loop --no-realtime --sink none --points "$T/points.csv" --method $m --landmarks 30 \
                --threads 2 --min-markers 3 --max-frames $f 2>/dev/null
        done
        more=$(awk 'FNR == NR { a[$2] = $1; next } { if ($1 != a[$2]) printf "%s %+d, ", $2, $1 - a[$2] }' \
            "$T/alloc15" "$T/alloc30")
        [ -s "$T/alloc30" ] && [ -z "$more" ] && ok "hot loop: no allocation in frames 15 to 30 ($m, landmarks)" \
            || bad "hot loop: no allocation in frames 15 to 30 ($m, landmarks)" "${more:-no counts written}"
    done
fi

# 2. gating on the phantom's occlusions against its ground truth (markers.csv: a tag counts as
#    hidden when a corner or its centre is). 240 frames (10 s): the tracker locks the heart rate
#    after about 4 s, so dropouts come both before the lock (uncertain at once -> raw) and after
#    it (predicted -> degraded).
"$B/stillheart-render" --preset exvivo --frames 240 --cameras 1 --width 640 --height 360 --occlusions --out "$T/occ" >/dev/null 2>&1
$RUN --source "y4m:$T/occ/cam0.y4m" --no-loop --no-realtime --sink none --min-markers 16 --trace "$T/all.csv" 2> "$T/all.log"
$RUN --source "y4m:$T/occ/cam0.y4m" --no-loop --no-realtime --sink none --trace "$T/occ.csv" 2> "$T/occ.log"
python3 - "$T/occ/markers.csv" "$T/all.csv" "$T/occ.csv" <<'PY' && ok "occlusions: raw / degraded / stabilized as the ground truth says" || bad "occlusions: raw / degraded / stabilized as the ground truth says" "see above"
import csv, math, sys
hidden = {}
for r in csv.DictReader(open(sys.argv[1])):
    if r['camera'] == '0':
        k = (int(r['frame']), int(r['id']))
        hidden[k] = hidden.get(k, False) or r['visible'] == '0'
ids = sorted({i for _, i in hidden})
def any_hidden(f): return any(hidden.get((f, i), False) for i in ids)
def near(f, d): return any(any_hidden(g) for g in range(f - d, f + d + 1))
ok = True
def need(c, m):
    global ok
    if not c: print("FAIL:", m); ok = False
# every marker needed: a hidden one (predicted, then stale) never leaves a frame stabilized, and
# with all visible (2 frames either side: a tag's border goes before its corners) it is stabilized
# The reference's model is built beside the first frames (nothing waits for it): they are raw
# for as long as the build takes, which a loaded machine stretches; judged from the first
# stabilized frame on, which must come within 40 frames.
rows = list(csv.DictReader(open(sys.argv[2])))
need(len(rows) == 240, "all.csv: %d frames" % len(rows))
bad_hidden = [int(r['index']) for r in rows if any_hidden(int(r['index'])) and r['status'] == 'stabilized']
start = next((int(r['index']) for r in rows if r['status'] == 'stabilized'), 999)
need(start <= 40, "the first stabilized frame is %d" % start)
clear = [r for r in rows if int(r['index']) >= max(start, 1) and not near(int(r['index']), 2)]
bad_clear = [int(r['index']) for r in clear if r['status'] != 'stabilized']
need(not bad_hidden, "stabilized with a marker hidden: frames %s" % bad_hidden[:10])
need(len(clear) >= 30 and len(bad_clear) <= len(clear) // 20, "%d of %d clear frames not stabilized: %s" % (len(bad_clear), len(clear), bad_clear[:10]))
def resumed(rows): return sum(1 for a, b in zip(rows[1:], rows[2:]) if a['status'] != 'stabilized' and b['status'] == 'stabilized')
need(resumed(rows) >= 1 and rows[-1]['status'] == 'stabilized', "stabilization resumed %d times" % resumed(rows))
# default gating (6 markers): short dropouts after the lock are degraded, never without an
# occlusion nearby; residuals are finite and within the gate on every shown warp
rows = list(csv.DictReader(open(sys.argv[3])))
st = [r['status'] for r in rows]
need(st.count('degraded') >= 3 and st.count('raw') >= 3, "statuses %s" % {s: st.count(s) for s in set(st)})
need(all(near(int(r['index']), 3) for r in rows if r['status'] == 'degraded'), "degraded with no occlusion nearby")
runs, n = [], 0  # a dropout is degraded for dropout_ms at most (model builds run on their own clock)
for r in rows + [{'reason': ''}]:
    if r['reason'].startswith('dropout'): n += 1
    elif n: runs.append(n); n = 0
need(runs and max(runs) <= 6, "dropout stretches %s (dropout_ms 200 = 4.6 frames)" % runs)
for r in rows:
    res = float(r['residual'])
    need(math.isfinite(res), "frame %s residual %s" % (r['index'], r['residual']))
    if r['status'] == 'stabilized': need(0 <= res <= 3 and int(r['markers']) >= 6, "stabilized frame %s: %s" % (r['index'], r))
    if r['status'] == 'degraded': need(res == -1 or 0 <= res <= 3, "degraded frame %s: %s" % (r['index'], r))
    if r['status'] == 'raw': need(res == -1 or res > 3, "raw frame %s: %s" % (r['index'], r))
need(resumed(rows) >= 5 and st[-1] == 'stabilized', "stabilization resumed %d times, ends %s" % (resumed(rows), st[-1]))
sys.exit(0 if ok else 1)
PY
grep -qi nan "$T/occ.log" "$T/occ.csv" "$T/all.csv" && bad "no NaN" "NaN in a log or trace" || ok "no NaN in status lines or traces"

# 3. bad configs are refused before anything starts, naming file, line and key
printf '[gating]\nmin_markers = lots\n' > "$T/bad.ini"
msg=$($RUN --config "$T/bad.ini" 2>&1); rc=$?
[ $rc -eq 2 ] && echo "$msg" | grep -q "bad.ini:2: \[gating\] min_markers" && ok "bad value refused" || bad "bad value refused" "$msg"
msg=$($RUN --config "$T/none.ini" 2>&1); rc=$?
[ $rc -eq 2 ] && echo "$msg" | grep -q "none.ini: cannot open" && ok "missing file refused" || bad "missing file refused" "$msg"
msg=$($RUN --frobnicate 3 2>&1); rc=$?
[ $rc -eq 2 ] && echo "$msg" | grep -q -- "unknown option '--frobnicate'; try 'stillheart run --help'" && ok "unknown option refused" || bad "unknown option refused" "$msg"
# an unedited install names no camera: one line and exit 6 (not configured), which the unit does
# not restart on (RestartPreventExitStatus; make deb-test checks the two agree)
printf '[camera0]\nspec =\n' > "$T/empty.ini"
msg=$($RUN --config "$T/empty.ini" 2>&1); rc=$?
[ $rc -eq 6 ] && [ "$(echo "$msg" | wc -l)" -eq 1 ] && echo "$msg" | grep -q "not configured: no camera named" \
    && ok "no camera: one line, exit 6" || bad "no camera: one line, exit 6" "rc $rc: $msg"
msg=$($RUN --config "$T/bad.ini" --min-markers 5 --print-config 2>&1); rc=$?
[ $rc -eq 2 ] && ok "command line does not hide a bad file" || bad "command line does not hide a bad file" "$msg"
printf '[gating]\nmin_markers = 9\n' > "$T/good.ini"
msg=$($RUN --config "$T/good.ini" --min-markers 7 --print-config 2>&1)
echo "$msg" | grep -q "^min_markers = 7" && ok "command line wins" || bad "command line wins" "$msg"
# a message prefixed with its context keeps the cause (the prefix used to overwrite it)
msg=$($RUN --source "y4m:$T/ph/cam0.y4m" --points "$T/none.csv" --sink none 2>&1); rc=$?
[ $rc -ne 0 ] && echo "$msg" | grep -q "\[run\] points: $T/none.csv: No such file" && ok "missing points file named" \
    || bad "missing points file named" "$msg"
# the exit-code table (stillheart run --help, docs/daemon.md): 2 for what no restart mends (the
# unit's RestartPreventExitStatus=2 6), 1 for what one can, 0 for a normal end
got=""
for c in "2 --source y4m:$T/none.y4m" "2 --source y4m:$T/ph/cam0.y4m --points $T/none.csv" \
         "2 --source y4m:$T/ph/cam0.y4m --calibration $T/none.yaml" "2 --source y4m:$T/ph/cam0.y4m --min-markers lots" \
         "1 --source v4l2:$T/no-video" "1 --source y4m:$T/ph/cam0.y4m --trace $T/no/dir/t.csv" \
         "0 --source y4m:$T/ph/cam0.y4m --no-realtime --max-frames 2"; do
    want=${c%% *}; $RUN --sink none ${c#* } > /dev/null 2>&1; rc=$?
    [ $rc -eq "$want" ] || got="$got [exit $rc, not $want: ${c#* }]"
done
[ -z "$got" ] && ok "exit codes: 2 what no restart mends, 1 what one can, 0 a normal end" \
    || bad "exit codes: 2 what no restart mends, 1 what one can, 0 a normal end" "$got"

# 3a. configs that imply no model (issue 16) are refused before the first frame with exit 2, naming
#    the file and line or the command-line option (docs/daemon.md, "What a config must imply"); the
#    nearest valid values start. Those that depend on the frames are checked once the source is
#    open: on the phantom's 640x360 frames a Gaussian over [gating] min_markers = 6 markers spread
#    evenly is singular (rcond < 1e-15) from sigma 1e5, not at 3e4 (sh_interp_create on that layout).
printf '[method]\nname = bspline\n\nlevels = 11\n' > "$T/lv.ini"
printf '[method]\nname = gaussian\n[gating]\nmin_markers = 6\n[method]\nsigma = 1e6\n' > "$T/sg.ini"
got=""
for c in "command line: --grid 3: 3 px is not a power of two|--grid 3" "command line: --grid 0.5:|--grid 0.5" \
         "command line: --levels 16: bspline: 16 levels make a lattice|--method bspline --levels 16" \
         "lv.ini:4: [method] levels: bspline: 11 levels|--config $T/lv.ini" \
         "command line: --sigma 1e+06: no model on 640x360 frames|--method gaussian --sigma 1e6" \
         "command line: --sigma 100000: no model on 640x360 frames|--method gaussian --sigma 1e5" \
         "sg.ini:6: [method] sigma: no model on 640x360 frames|--config $T/sg.ini" \
         "command line: --levels 4: tps: levels apply to bspline only|--levels 4" \
         "command line: --min-markers 2: 2 is fewer than tps needs (3)|--min-markers 2"; do
    want=${c%%|*}; msg=$($RUN --source "y4m:$T/ph/cam0.y4m" --sink none --no-realtime --max-frames 2 ${c#*|} 2>&1); rc=$?
    { [ $rc -eq 2 ] && echo "$msg" | grep -qF "$want"; } || got="$got [exit $rc, not 2: ${c#*|}: $msg]"
done
for c in "--grid 4" "--grid 2" "--grid 1" "--method bspline --levels 10" "--method gaussian --sigma 3e4" \
         "--method gaussian --sigma 1e6 --smoothing 1" "--min-markers 3"; do
    $RUN --source "y4m:$T/ph/cam0.y4m" --sink none --no-realtime --max-frames 2 $c > /dev/null 2>&1; rc=$?
    [ $rc -eq 0 ] || got="$got [exit $rc, not 0: $c]"
done
[ -z "$got" ] && ok "configs that imply no model: exit 2 naming file:line or the option; the nearest valid start" \
    || bad "configs that imply no model: exit 2 naming file:line or the option; the nearest valid start" "$got"

# 3b. a damaged replay (issue 16) is never a silent prefix: damage with good frames behind it stops
#    the replay with one ERROR naming the place and exit status 2 (a restart cannot mend a file:
#    RestartPreventExitStatus), with or without --loop; a torn last frame (a recorder killed) is
#    said once at WARNING and the frames before it loop on
python3 - "$T" <<'PY'
import sys
W, H = 64, 48
fr = [bytes([50 + 5 * k]) * (W * H) + bytes([128]) * (W * H // 2) for k in range(8)]
hdr = b"YUV4MPEG2 W64 H48 F25:1 Ip A1:1 C420jpeg\n"
open(sys.argv[1] + "/bad.y4m", "wb").write(hdr + b"".join((b"FRAMX\n" if k == 3 else b"FRAME\n") + f for k, f in enumerate(fr)))
whole = hdr + b"".join(b"FRAME\n" + f for f in fr)
open(sys.argv[1] + "/torn.y4m", "wb").write(whole[:len(whole) - 2000])
PY
$RUN --source "y4m:$T/bad.y4m" --loop --no-realtime --sink none --max-frames 20 2> "$T/bad.log"; rc_bad=$?
$RUN --source "y4m:$T/torn.y4m" --loop --no-realtime --sink none --max-frames 20 --trace "$T/torn.csv" 2> "$T/torn.log"; rc_torn=$?
n_err=$(grep -c "frame 3: bad FRAME line" "$T/bad.log"); n_warn=$(grep -c "WARN.*frame 7 truncated" "$T/torn.log")
[ $rc_bad -eq 2 ] && [ "$n_err" -eq 1 ] && [ $rc_torn -eq 0 ] && [ "$n_warn" -eq 1 ] && [ "$(grep -c '^[0-9]' "$T/torn.csv")" -eq 20 ] \
    && ok "damaged replays: stopped with exit 2 where frames lie behind the damage, a torn tail said once and looped" \
    || bad "damaged replays: stopped with exit 2 where frames lie behind the damage, a torn tail said once and looped" \
           "exit $rc_bad, $n_err ERROR lines; torn: exit $rc_torn, $n_warn WARN lines: $(tail -3 "$T/bad.log" "$T/torn.log")"

# 4. SIGTERM stops within a second, segment closed; sd_notify READY/STATUS/WATCHDOG; SIGHUP bad reload kept
python3 - "$B/stillheart" "$T/ph/cam0.y4m" "$T/good.ini" "$SHM" <<'PY' && ok "notify, reload, SIGUSR1 reference, SIGTERM < 1 s" || bad "notify, reload, SIGUSR1 reference, SIGTERM < 1 s" "see above"
import os, socket, subprocess, sys, time, signal
exe, video, ini, shm = sys.argv[1:5]
sp = "/tmp/sh-notify-test-%d" % os.getpid()
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM); s.bind(sp); s.settimeout(5)
env = dict(os.environ, NOTIFY_SOCKET=sp, WATCHDOG_USEC="400000")
p = subprocess.Popen([exe, "run", "--group=", "--config", ini, "--source", "y4m:" + video, "--realtime",
                      "--loop", "--points", "", "--sink", "shm:" + shm], env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
# stderr read as it comes (a thread): the test waits for the new reference's line, whose models
# are built beside the frames and take a while under qemu-aarch64 on a busy machine
import threading
lines = []
def drain():
    for l in p.stderr: lines.append(l.decode())
reader = threading.Thread(target=drain, daemon=True)
reader.start()
# the notify socket read throughout, as systemd does (the daemon drops a message its listener
# leaves queued for 200 ms, src/notify)
got = []
def listen():
    while True:
        try: got.append(s.recv(4096).decode())
        except socket.timeout: continue
        except OSError: return
threading.Thread(target=listen, daemon=True).start()
t0 = time.time()  # up and running first (qemu-aarch64 on a loaded machine takes seconds), then 1 s of pings
while time.time() - t0 < 60 and not any(g.startswith("READY=1") for g in got): time.sleep(0.1)
time.sleep(1)
open(ini, "w").write("[gating]\nmin_markers = nope\n")
p.send_signal(signal.SIGHUP); time.sleep(0.5)
p.send_signal(signal.SIGUSR1)
t2 = time.time()
while time.time() - t2 < 30 and sum(l.count("reference: frame") for l in lines) < 2: time.sleep(0.1)
alive = p.poll() is None
t1 = time.time(); p.send_signal(signal.SIGTERM); p.wait(timeout=5); dt = time.time() - t1
reader.join(timeout=5) # the rest, up to the end of the pipe
err = "".join(lines)
os.unlink(sp)
ok = True
def need(c, m):
    global ok
    if not c: print("FAIL:", m); ok = False
need(got and got[0].startswith("READY=1"), "READY=1 first: %r" % got[:2])
need(any(g.startswith("STATUS=") and "fps" in g for g in got), "STATUS with fps")
need(sum(g == "WATCHDOG=1" for g in got) >= 3, "WATCHDOG=1 pings: %d" % sum(g == "WATCHDOG=1" for g in got))
need(alive and "reload refused, keeping the running config" in err and "min_markers" in err, "bad reload kept: " + err[-300:])
need(err.count("reference: frame") == 2 and "new reference requested" in err, "SIGUSR1 new reference")
need(dt < 1.0 and p.returncode == 0, "SIGTERM took %.2f s rc %s" % (dt, p.returncode))
sys.exit(0 if ok else 1)
PY
[ -e "/dev/shm$SHM" ] && rm -f "/dev/shm$SHM"

# 4b. signals while the daemon starts: it waits in open() for a FIFO's writer (as for a camera
#     slow to open); SIGHUP and SIGUSR1 then must not end it by their default action. Host only:
#     under qemu-user /proc shows qemu's own handlers, not whether the daemon's are in place yet.
if [ -z "${SH_TEST_EMULATED:-}" ]; then
python3 - "$B/stillheart" "$T/ph/cam0.y4m" "$T" <<'PY' && ok "SIGHUP and SIGUSR1 while starting: caught, not fatal" || bad "SIGHUP and SIGUSR1 while starting: caught, not fatal" "see above"
import os, signal, subprocess, sys, threading, time
exe, video, tmp = sys.argv[1:4]
fifo = os.path.join(tmp, "slow-start.fifo"); os.mkfifo(fifo)
p = subprocess.Popen([exe, "run", "--group=", "--source", "y4m:" + fifo, "--no-loop", "--sink", "none"],
                     stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
def caught():  # SIGHUP (1) and SIGUSR1 (10) have handlers
    try: line = [l for l in open("/proc/%d/status" % p.pid) if l.startswith("SigCgt:")][0]
    except (OSError, IndexError): return False
    return int(line.split()[1], 16) & 0x201 == 0x201
t0 = time.time()
while time.time() - t0 < 10 and not caught() and p.poll() is None: time.sleep(0.01)
fails = []
if not caught(): fails.append("no handlers within 10 s (exit %s)" % p.poll())
p.send_signal(signal.SIGHUP); p.send_signal(signal.SIGUSR1); time.sleep(0.3)
if p.poll() is not None: fails.append("ended by a signal while starting: exit %s" % p.returncode)
def feed():  # the writer comes: the whole recording through the FIFO
    with open(fifo, "wb") as w: w.write(open(video, "rb").read())
threading.Thread(target=feed, daemon=True).start()
try: err = p.communicate(timeout=60)[1].decode()
except subprocess.TimeoutExpired: p.kill(); err = p.communicate()[1].decode(); fails.append("no end")
if p.returncode != 0 or "reference: frame" not in err: fails.append("exit %s: %s" % (p.returncode, err[-400:]))
for f in fails: print("FAIL:", f)
sys.exit(1 if fails else 0)
PY
fi

# 5. a new reference without a hitch, asked for on the control socket and by SIGUSR1: frames keep
#    being stabilized with the old reference while the new one's models are built; status and
#    unknown commands answered. The markers are the phantom's true centres (a points file): what
#    is under test is the swap, not whether detection keeps up in real time (under qemu-aarch64
#    it does not, and markers dropped that way would read as a hitch).
"$B/stillheart-render" --preset exvivo --frames 120 --cameras 1 --width 640 --height 360 --out "$T/clean" >/dev/null 2>&1
python3 - "$T/clean/markers.csv" "$T/clean.csv" <<'PY'
import csv, sys
out = open(sys.argv[2], 'w')
out.write("frame,id,x,y\n")
for r in csv.DictReader(open(sys.argv[1])):
    if r['camera'] == '0' and r['point'] == 'c' and r['visible'] == '1':
        out.write("%s,%s,%s,%s\n" % (r['frame'], r['id'], r['x'], r['y']))
PY
python3 - "$B/stillheart" "$T/clean/cam0.y4m" "$T/ctl" "$T/ref.csv" "$T/clean.csv" <<'PY' && ok "control socket and SIGUSR1: new reference without a hitch" || bad "control socket and SIGUSR1: new reference without a hitch" "see above"
import csv, os, re, signal, socket, subprocess, sys, time
exe, video, ctl, trace, points = sys.argv[1:6]
if os.environ.get("SH_TEST_EMULATED"):
    # qemu-aarch64 on a loaded machine keeps up with a third of the phantom's 23 frames/s: the
    # same frames at 8 frames/s, so that the trace holds enough of them to show a hitch
    d = open(video, "rb").read(); head, body = d.split(b"\n", 1)
    video = video + ".8fps.y4m"
    open(video, "wb").write(re.sub(rb" F\d+:\d+", b" F8:1", head) + b"\n" + body)
p = subprocess.Popen([exe, "run", "--group=", "--source", "y4m:" + video, "--realtime", "--no-loop", "--sink", "none",
                      "--points", points, "--control", ctl, "--trace", trace], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
def ask(cmd):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); s.settimeout(3); s.connect(ctl)
    s.sendall(cmd.encode() + b"\n"); out = b""
    while True:
        b = s.recv(256)
        if not b: break
        out += b
    s.close(); return out.decode().strip()
for i in range(600):
    if os.path.exists(ctl): break
    time.sleep(0.1)
t0 = time.time()  # a frame shown first: the status then names it (a loaded qemu-aarch64 takes seconds)
while time.time() - t0 < 60 and not ask("status").startswith("frame "): time.sleep(0.2)
replies = [ask("status"), ask("reference")]
time.sleep(1.2)
p.send_signal(signal.SIGUSR1)
time.sleep(1.2)
replies.append(ask("frobnicate"))
err = p.communicate(timeout=20)[1].decode()
ok = True
def need(c, m):
    global ok
    if not c: print("FAIL:", m); ok = False
need(replies[0].startswith("frame ") and "markers" in replies[0] and "residual" in replies[0], "status reply %r" % replies[0])
need(replies[1] == "ok: new reference requested", "reference reply %r" % replies[1])
need(replies[2].startswith("error: 'frobnicate'"), "unknown command reply %r" % replies[2])
need(err.count("reference: frame") == 3 and "(control socket)" in err and "(SIGUSR1)" in err, "three references: " + err[-400:])
need(p.returncode == 0 and not os.path.exists(ctl), "exit %s, socket left: %s" % (p.returncode, os.path.exists(ctl)))
rows = list(csv.DictReader(open(trace)))
first = next(i for i, r in enumerate(rows) if r['status'] == 'stabilized')
hitch = [r['index'] + ' ' + r['status'] + ' ' + r['reason'] for r in rows[first:] if r['status'] != 'stabilized']
# the whole file shown (a slow machine, such as qemu-aarch64, drops frames in real time: a count
# of rows would judge its speed, not the hitch)
need(int(rows[-1]['index']) >= 100 and len(rows) >= 40 and not hitch,
     "%d frames up to %s; not stabilized after the first reference: %s" % (len(rows), rows[-1]['index'], hitch[:5]))
sys.exit(0 if ok else 1)
PY

# 6. PNG record: each PNG equals the frame the shared-memory buffer showed under the same sequence
#    number (I420 -> RGB by BT.601 computed here, bilinear chroma at the centre siting)
#    320x180: compressing is the slow part, and a loaded machine must still leave frames to compare
"$B/stillheart-render" --preset exvivo --frames 40 --cameras 1 --width 320 --height 180 --out "$T/small" >/dev/null 2>&1
$RUN --source "y4m:$T/small/cam0.y4m" --no-loop --realtime --sink "shm:$SHM" --record "png:$T/png" --min-markers 4 2> "$T/png.log" & pid=$!
wait_segment
"$B/stillheart-cat" --name "$SHM" --count 25 --timeout 5 -v > "$T/catpng.y4m" 2> "$T/catpng.log"
wait $pid
python3 - "$T/catpng.y4m" "$T/catpng.log" "$T/png" <<'PY' && ok "PNG record equals the shm frames" || bad "PNG record equals the shm frames" "see above"
import os, re, struct, sys, zlib
def png(path):
    d = open(path, 'rb').read(); pos = 8; idat = b''
    while pos < len(d):
        n, t = struct.unpack('>I4s', d[pos:pos + 8]); body = d[pos + 8:pos + 8 + n]; pos += 12 + n
        if t == b'IHDR': w, h, depth, ctype = struct.unpack('>IIBB', body[:10])
        if t == b'IDAT': idat += body
    bpp = {0: 1, 2: 3}[ctype]; raw = zlib.decompress(idat); stride = w * bpp; rows = []; prev = bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]; cur = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = cur[i - bpp] if i >= bpp else 0; b = prev[i]; c = prev[i - bpp] if i >= bpp else 0
            if f == 1: cur[i] = (cur[i] + a) & 255
            elif f == 2: cur[i] = (cur[i] + b) & 255
            elif f == 3: cur[i] = (cur[i] + (a + b) // 2) & 255
            elif f == 4:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                cur[i] = (cur[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(cur)); prev = cur
    return w, h, bpp, rows
d = open(sys.argv[1], 'rb').read()
if b'\n' not in d: print("stillheart-cat wrote no Y4M header (%d bytes); it said:" % len(d), open(sys.argv[2]).read()[-500:]); sys.exit(1)
hdr, rest = d.split(b'\n', 1)
w = int(re.search(rb' W(\d+)', hdr).group(1)); h = int(re.search(rb' H(\d+)', hdr).group(1))
full = b'XCOLORRANGE=FULL' in hdr
frames = []
while rest:
    line, rest = rest.split(b'\n', 1) if b'\n' in rest else (rest, b'')
    if line != b'FRAME' or len(rest) < w * h * 3 // 2:
        print("frame", len(frames), "of stillheart-cat's stream is not whole: line %r, %d of %d bytes" % (line[:20], min(len(rest), w * h * 3 // 2), w * h * 3 // 2)); sys.exit(1)
    frames.append(rest[:w * h * 3 // 2]); rest = rest[w * h * 3 // 2:]
seqs = [int(m.group(1)) for m in re.finditer(r'^frame (\d+) ', open(sys.argv[2]).read(), re.M)]
ys, yo, cs = (1, 0, 1) if full else (255 / 219, 16, 255 / 224)
kr, kb = 0.299, 0.114; kg = 1 - kr - kb
def tap(x, n):
    q = 2 * x - 1; a = q // 4; fr = q - 4 * a
    return min(max(a, 0), n - 1), min(max(a + 1, 0), n - 1), (4 - fr) / 4, fr / 4
cw, ch = (w + 1) // 2, (h + 1) // 2
matched = 0; worst = 0; at = ""
for seq, f in zip(seqs, frames):
    path = os.path.join(sys.argv[3], '%06d.png' % seq)
    if not os.path.exists(path): continue
    pw, ph, bpp, rows = png(path)
    if (pw, ph, bpp) != (w, h, 3): print("PNG", path, pw, ph, bpp); sys.exit(1)
    U = f[w * h:w * h + cw * ch]; V = f[w * h + cw * ch:]
    for y in range(0, h, 7):
        va, vb, vwa, vwb = tap(y, ch)
        for x in range(0, w, 5):
            ha, hb, hwa, hwb = tap(x, cw)
            u = vwa * (hwa * U[va * cw + ha] + hwb * U[va * cw + hb]) + vwb * (hwa * U[vb * cw + ha] + hwb * U[vb * cw + hb])
            v = vwa * (hwa * V[va * cw + ha] + hwb * V[va * cw + hb]) + vwb * (hwa * V[vb * cw + ha] + hwb * V[vb * cw + hb])
            Y = ys * (f[y * w + x] - yo); cb = cs * (u - 128); cr = cs * (v - 128)
            rgb = (Y + 2 * (1 - kr) * cr, Y - (2 * kb * (1 - kb) * cb + 2 * kr * (1 - kr) * cr) / kg, Y + 2 * (1 - kb) * cb)
            for k in range(3):
                want = min(max(int(rgb[k] + 0.5 if rgb[k] >= 0 else 0), 0), 255)
                if abs(rows[y][3 * x + k] - want) > worst:
                    worst = abs(rows[y][3 * x + k] - want); at = "sequence %d, %s x=%d y=%d: PNG %d, shm %d" % (seq, "RGB"[k], x, y, rows[y][3 * x + k], want)
    matched += 1
print("matched", matched, "of", len(frames), "frames, largest difference", worst, "(%s)" % at if worst > 1 else "")
sys.exit(0 if matched >= 5 and worst <= 1 else 1)  # under load the writer skips some
PY

# 7. 3D with calibrated cameras: three phantom cameras and their calibration. In test mode (3D
#    points from `stillheart track --cameras`) what the daemon shows is byte-identical to
#    `stillheart warp3d` of the same points; tracking itself, every frame stabilized with a small
#    residual.
"$B/stillheart-render" --preset exvivo --frames 40 --cameras 3 --width 640 --height 360 --out "$T/s3" >/dev/null 2>&1
"$B/stillheart" track --cameras "$T/s3/calibration.yaml" --ids 0-15 "$T/s3/cam0.y4m" "$T/s3/cam1.y4m" "$T/s3/cam2.y4m" > "$T/p3.csv" 2>/dev/null
"$B/stillheart" warp3d --cameras "$T/s3/calibration.yaml" --points "$T/p3.csv" --method tps --threads 2 --quiet "$T/s3/cam0.y4m" "$T/w3.y4m"
CAMS="--source y4m:$T/s3/cam0.y4m --camera1-spec y4m:$T/s3/cam1.y4m --camera2-spec y4m:$T/s3/cam2.y4m --calibration $T/s3/calibration.yaml"
$RUN $CAMS --no-loop --no-realtime --sink none --points "$T/p3.csv" --method tps --threads 2 --record "$T/r3.y4m" \
    && cmp -s "$T/r3.y4m" "$T/w3.y4m" && ok "3D: record equals stillheart warp3d" || bad "3D: record equals stillheart warp3d" "differs"
# camera 1's replay ends after 20 of the 40 frames (as a camera that fails for good): the sets
# go on without it, each once cameras 0 and 2 are in it, and no frame of the output camera is
# refused as late or lost (a flush at each frame after the loss lost a third of them, 2026-12-05)
hdr=$(head -n 1 "$T/s3/cam1.y4m" | wc -c)
head -c $((hdr + 20 * (6 + 640 * 360 * 3 / 2))) "$T/s3/cam1.y4m" > "$T/short1.y4m"
msg=$("$B/stillheart" run --group= ${CAMS%%--camera1-spec*} --camera1-spec "y4m:$T/short1.y4m" \
    --camera2-spec "y4m:$T/s3/cam2.y4m" --calibration "$T/s3/calibration.yaml" --no-loop --no-realtime --sink none \
    --points "$T/p3.csv" --method tps --threads 2 --stats 2>&1)
{ echo "$msg" | grep -q "camera 0 (y4m:.*): 40 frames, .* 0 late" && echo "$msg" | grep -q "sets: 40 (20 incomplete)" \
    && echo "$msg" | grep -q "0 without the output camera's frame" && echo "$msg" | grep -q "^stats: 40 published"; } \
    && ok "3D: a camera gone for good, the others' frames all in their sets" \
    || bad "3D: a camera gone for good, the others' frames all in their sets" "$(echo "$msg" | grep 'sets:\|camera 0\|^stats')"
# --outside dimmed-raw in 3D (the view's hull, the projected reference markers): a byte differs from
# warp3d's only where warp3d left black (0 luma, 128 chroma), and is there the camera's dimmed or
# the cyan line; every frame has such bytes (sampled every 7th byte: Python is slow)
$RUN $CAMS --no-loop --no-realtime --sink none --points "$T/p3.csv" --method tps --threads 2 --record "$T/r3d.y4m" \
    --outside dimmed-raw
PYTHONPATH="$T" python3 - "$T/r3d.y4m" "$T/w3.y4m" "$T/s3/cam0.y4m" <<'PY' \
    && ok "3D: outside = dimmed-raw changes only what warp3d left black" || bad "3D: outside = dimmed-raw changes only what warp3d left black" "see above"
import sys
from outside import frames
(dim, w, h), (warp, _, _), (raw, _, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[3])
n = w * h
cyan = (round(16 + 219 * 0.701), round(128 + 224 * 0.299 / 1.772), round(128 - 224 * 0.701 / 1.402))  # BT.601 limited
if len(dim) != len(warp) or len(dim) < 30: print(len(dim), "frames recorded,", len(warp), "by warp3d"); sys.exit(1)
for i, (f, g, r) in enumerate(zip(dim, warp, raw)):
    changed = 0
    for k in range(0, len(f), 7):
        if f[k] == g[k]: continue
        p = 0 if k < n else 1 if k < n * 5 // 4 else 2
        b = 16 if p == 0 else 128
        if g[k] != (0 if p == 0 else 128) or f[k] not in ((r[k] + b + 1) // 2, cyan[p]):
            print("frame %d byte %d (plane %d): %d, warp3d %d, camera %d" % (i, k, p, f[k], g[k], r[k])); sys.exit(1)
        changed += 1
    if changed < 1000: print("frame %d: only %d bytes of 1 in 7 changed" % (i, changed)); sys.exit(1)
PY
# Frames are shown raw while the reference's 3D models are built beside them (no frame waits for
# a build); under qemu-aarch64 on a busy machine that build can outlast a 40-frame pass, so the
# replay loops (the tracker starting afresh at each loop) for 160 frames: the first stabilized
# frame comes when the build is done, and every frame after it must be stabilized.
$RUN $CAMS --loop --max-frames 160 --no-realtime --sink none --method tps --trace "$T/t3.csv"
python3 - "$T/t3.csv" <<'PY' && ok "3D: tracked in 3D, every frame stabilized, residual < 0.5 px" || bad "3D: tracked in 3D, every frame stabilized, residual < 0.5 px" "see above"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
first = next((i for i, r in enumerate(rows) if r['status'] == 'stabilized'), 999)
bad = [(r['index'], r['status'], r['residual'], r['reason']) for r in rows[first:] if r['status'] != 'stabilized' or not 0 <= float(r['residual']) < 0.5]
if bad or len(rows) != 160 or first > 120: print(len(rows), "frames, first stabilized", first, "; off:", bad[:5])
sys.exit(1 if bad or len(rows) != 160 or first > 120 else 0)
PY
# two cameras' calibrations swapped (issue 16): triangulation still finds points, and the residual
# stays under its gate, but the markers every camera sees do not reproject: never shown stabilized
python3 -c 'import re, sys; s = open(sys.argv[1]).read(); open(sys.argv[2], "w").write(re.sub(r"^(K|dist|R|t|P)_([01]):", lambda m: "%s_%d:" % (m.group(1), 1 - int(m.group(2))), s, flags=re.M))' \
    "$T/s3/calibration.yaml" "$T/s3/swapped.yaml"
# The replay loops for 120 frames: one aarch64 run at 959577f (qemu on a loaded machine) showed
# all 40 frames of a single pass raw without the check having concluded (issue 21's loop, run 5);
# every frame must be raw either way, and once the mismatch is caught every later frame is raw
# for it. On a failure the reasons are counted, so that it explains itself.
"$B/stillheart" run --group= ${CAMS%--calibration*} --calibration "$T/s3/swapped.yaml" --loop --max-frames 120 --no-realtime \
    --sink none --method tps --trace "$T/swap.csv" 2> "$T/swap.log"
python3 - "$T/swap.csv" "$T/swap.log" <<'PY' && ok "3D: swapped calibrations caught, never shown stabilized" || bad "3D: swapped calibrations caught, never shown stabilized" "see above"
import collections, csv, re, sys
rows = list(csv.DictReader(open(sys.argv[1]))); log = open(sys.argv[2]).read()
shown = [r['index'] for r in rows if r['status'] != 'raw']
first = next((i for i, r in enumerate(rows) if r['reason'].startswith('calibration mismatch')), None)
after = [] if first is None else [r for r in rows[first:] if not r['reason'].startswith('calibration mismatch')]
m = re.search(r'median reprojection error ([0-9.]+) px', log)
print("swapped cameras 0 and 1: %d frames, %d shown not raw, the mismatch caught at frame %s, %d frames after it raw for "
      "another reason; the log: %s" % (len(rows), len(shown), first, len(after), m.group(0) if m else "no line"))
failed = shown or first is None or after or not m or float(m.group(1)) <= 0.5 or len(rows) != 120
if failed:
    reasons = collections.Counter(re.sub(r'[0-9.]+', 'N', r['status'] + ': ' + r['reason']) for r in rows)
    for k, v in reasons.most_common(): print("  %3d frames %s" % (v, k))
    print("  first frames:", [(r['index'], r['status'], r['reason']) for r in rows[:3]])
sys.exit(1 if failed else 0)
PY
msg=$($RUN --source "y4m:$T/s3/cam0.y4m" --calibration "$T/s3/calibration.yaml" --sink none 2>&1); rc=$?
[ $rc -ne 0 ] && echo "$msg" | grep -q "calibration.*3 cameras, 1 configured" && ok "3D: calibration for other cameras refused" || bad "3D: calibration for other cameras refused" "$msg"

# 7b. The stereo pair of a calibrated rig (issue 17; paper section IV): with [method] view = stereo
#     the daemon shows the two virtual eyes in the layout, and in test mode its frames are
#     byte-identical to `stillheart warp3d --view stereo --layout L` of the same points (all four
#     layouts on the host; under qemu one full and one squeezed). Tracking, every frame after the
#     first stabilized; the dimmed outside per eye; a reload to and from stereo remakes the
#     segment at the pair's size; what cannot be shown so is refused naming the key.
LAYOUTS="sbs tb sbs-half tb-half"; [ -n "${SH_TEST_EMULATED:-}" ] && LAYOUTS="sbs tb-half"
same=""; differ=""
for L in $LAYOUTS; do
    "$B/stillheart" warp3d --cameras "$T/s3/calibration.yaml" --points "$T/p3.csv" --method tps --threads 2 --quiet \
        --view stereo --layout $L "$T/s3/cam0.y4m" "$T/w3-$L.y4m"
    $RUN $CAMS --no-loop --no-realtime --sink none --points "$T/p3.csv" --method tps --threads 2 --record "$T/r3-$L.y4m" \
        --view stereo --layout $L
    if cmp -s "$T/r3-$L.y4m" "$T/w3-$L.y4m" && [ -s "$T/r3-$L.y4m" ]; then same="$same $L"
    else differ="$differ $L: $(cmp "$T/r3-$L.y4m" "$T/w3-$L.y4m" 2>&1 | head -c 200)"; fi
done
[ -z "$differ" ] && ok "stereo: record equals stillheart warp3d --view stereo (layouts$same)" || bad "stereo: record equals stillheart warp3d --view stereo" "$differ"
$RUN $CAMS --loop --max-frames 80 --no-realtime --sink none --method tps --view stereo --layout sbs-half \
    --trace "$T/ts.csv" --record "$T/ts.y4m"
python3 - "$T/ts.csv" "$T/ts.y4m" <<'PY' && ok "stereo: tracked in 3D, every frame after the first stabilized, the pair in the camera's size (sbs-half)" || bad "stereo: tracked in 3D, sbs-half" "see above"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
hdr = open(sys.argv[2], 'rb').readline().split()
first = next((i for i, r in enumerate(rows) if r['status'] == 'stabilized'), 999)
off = [(r['index'], r['status'], r['reason']) for r in rows[first:] if r['status'] != 'stabilized']
if off or len(rows) != 80 or first > 60 or b'W640' not in hdr or b'H360' not in hdr:
    print(len(rows), "frames, first stabilized", first, "; off:", off[:5], "; header", hdr[:3]); sys.exit(1)
PY
# the dimmed outside in each eye: side by side, a byte differs from warp3d's only where warp3d
# left black and is there the camera's dimmed (the same pixel of the camera frame in either eye)
# or the cyan line
$RUN $CAMS --no-loop --no-realtime --sink none --points "$T/p3.csv" --method tps --threads 2 --record "$T/r3d-sbs.y4m" \
    --view stereo --layout sbs --outside dimmed-raw
PYTHONPATH="$T" python3 - "$T/r3d-sbs.y4m" "$T/w3-sbs.y4m" "$T/s3/cam0.y4m" <<'PY' \
    && ok "stereo: outside = dimmed-raw per eye changes only what warp3d left black" || bad "stereo: outside = dimmed-raw per eye" "see above"
import sys
from outside import frames
(dim, w2, h), (warp, _, _), (raw, w, _) = frames(sys.argv[1]), frames(sys.argv[2]), frames(sys.argv[3])
cyan = (round(16 + 219 * 0.701), round(128 + 224 * 0.299 / 1.772), round(128 - 224 * 0.701 / 1.402))  # BT.601 limited
if w2 != 2 * w or len(dim) != len(warp) or len(dim) < 30: print(len(dim), "frames", w2, "wide, warp3d", len(warp)); sys.exit(1)
def planes(f, W, H):  # (plane, width, offset) of 4:2:0
    return [(0, W, 0), (1, W // 2, W * H), (2, W // 2, W * H * 5 // 4)]
for i, (f, g, r) in enumerate(zip(dim, warp, raw)):
    changed = 0
    for (p, PW, off), (_, pw, roff) in zip(planes(f, w2, h), planes(r, w, h)):
        rows = h if p == 0 else h // 2
        for y in range(0, rows, 3):
            for x in range(0, PW, 5):
                k = off + y * PW + x
                if f[k] == g[k]: continue
                b = 16 if p == 0 else 128
                c = r[roff + y * pw + x % pw]  # the camera's pixel under either eye
                if g[k] != (0 if p == 0 else 128) or f[k] not in ((c + b + 1) // 2, cyan[p]):
                    print("frame %d plane %d x %d y %d: %d, warp3d %d, camera %d" % (i, p, x, y, f[k], g[k], c)); sys.exit(1)
                changed += 1
    if changed < 300: print("frame %d: only %d sampled bytes changed" % (i, changed)); sys.exit(1)
PY
fails=""
msg=$($RUN --source "y4m:$T/s3/cam0.y4m" --view stereo --sink none 2>&1); rc=$?
{ [ $rc -eq 2 ] && echo "$msg" | grep -q -- "--view stereo: stereo needs a calibrated rig"; } || fails="$fails no calibration: rc $rc $msg;"
msg=$($RUN $CAMS --layout tb --sink none 2>&1); rc=$?
{ [ $rc -eq 2 ] && echo "$msg" | grep -q -- "--layout tb: only the stereo view has a layout"; } || fails="$fails layout without stereo: rc $rc $msg;"
msg=$($RUN $CAMS --baseline 20 --sink none 2>&1); rc=$?
{ [ $rc -eq 2 ] && echo "$msg" | grep -q -- "--baseline 20: 20 mm, but only the stereo view"; } || fails="$fails baseline without stereo: rc $rc $msg;"
"$B/stillheart-render" --preset exvivo --frames 4 --cameras 2 --width 320 --height 182 --out "$T/odd" >/dev/null 2>&1
msg=$($RUN --source "y4m:$T/odd/cam0.y4m" --camera1-spec "y4m:$T/odd/cam1.y4m" --calibration "$T/odd/calibration.yaml" \
      --view stereo --layout tb-half --sink none --no-loop --no-realtime 2>&1); rc=$?
{ [ $rc -eq 2 ] && echo "$msg" | grep -q -- "--layout tb-half: 320x182 camera frames: .*height (182) must be a multiple of 4"; } \
    || fails="$fails tb-half of 182 rows: rc $rc $msg;"
[ -z "$fails" ] && ok "stereo: refused without a rig, a layout or baseline without stereo, a height tb-half cannot halve" \
    || bad "stereo: refusals" "$fails"
# a reload turns the stereo pair off and on again: the segment is made anew at each size
printf '[method]\nname = tps\ncalibration = %s\nview = stereo\nlayout = sbs\n' "$T/s3/calibration.yaml" > "$T/stereo.ini"
rm -f "/dev/shm$SHM" # an earlier case's, closed: the reader must find this daemon's
"$B/stillheart" run --group= --config "$T/stereo.ini" $CAMS --loop --realtime --sink "shm:$SHM" 2> "$T/stereo.log" & pid=$!
wait_segment
w1=$("$B/stillheart-cat" --name "$SHM" --count 2 --timeout 60 2>/dev/null | head -c 64 | head -1 | tr ' ' '\n' | grep '^W')
sed -i 's/^view = stereo/view = reference/; /^layout/d' "$T/stereo.ini"
kill -HUP $pid
w2=""; i=0
while [ $i -lt 60 ] && [ "$w2" != W640 ]; do
    w2=$("$B/stillheart-cat" --name "$SHM" --count 1 --timeout 10 2>/dev/null | head -c 64 | head -1 | tr ' ' '\n' | grep '^W'); i=$((i + 1))
done
kill $pid; wait $pid; rc=$?
[ "$w1" = W1280 ] && [ "$w2" = W640 ] && [ $rc -eq 0 ] && grep -q "sink shm:$SHM made again for 640x360 frames" "$T/stereo.log" \
    && ok "stereo: a reload to the camera's own view remakes the segment (1280 -> 640 wide)" \
    || bad "stereo: reload" "widths $w1 then $w2, exit $rc: $(grep -i 'reload\|error' "$T/stereo.log" | tail -3)"
rm -f "/dev/shm$SHM"

# 8. looping replays: a periodic recording (stillheart-render --periodic, tagged XLOOP=SEAMLESS)
#    loops with the tracker running on, as on a live camera; the same heart rendered without the
#    tag jumps at each loop, and the tracker starts afresh there (logged once). 129 frames at 23
#    frames/s hold 4 beats at 0.713 Hz. Every frame from the first stabilized one on (within 40
#    frames: the reference's model is built beside them) is stabilized in both.
"$B/stillheart-render" --preset exvivo --frames 129 --cameras 1 --width 640 --height 360 --periodic --out "$T/per" >/dev/null 2>&1
head -n 1 "$T/per/cam0.y4m" | grep -q XLOOP=SEAMLESS || bad "periodic render tagged" "no XLOOP=SEAMLESS in the header"
python3 - "$T/per/cam0.y4m" "$T/jump.y4m" <<'PY'
import sys
d = open(sys.argv[1], 'rb').read()
hdr, rest = d.split(b'\n', 1)
open(sys.argv[2], 'wb').write(hdr.replace(b' XLOOP=SEAMLESS', b'') + b'\n' + rest)
PY
for kind in per jump; do
    src="$T/jump.y4m"; [ $kind = per ] && src="$T/per/cam0.y4m"
    "$B/stillheart" run --group= --source "y4m:$src" --loop --no-realtime --sink none --max-frames 387 \
        --trace "$T/loop-$kind.csv" > "$T/loop-$kind.out" 2> "$T/loop-$kind.log"
done
# The periodic run also locks the tracker's rates (exvivo: after about 4 s of history, 97 frames
# at 23 frames/s, docs/tracking.md), and a replay as fast as possible drops no set, so the stats
# line counts 0 dropped after that lock, at the frame the log names.
python3 - "$T" <<'PY' && ok "looping: periodic runs on, a jump restarts the tracker, every frame stabilized, the lock counted" || bad "looping: periodic runs on, a jump restarts the tracker, every frame stabilized, the lock counted" "see above"
import csv, re, sys
ok = True
for kind, restarts, frames in (("per", 0, 387), ("jump", 1, 129)):
    log = open("%s/loop-%s.log" % (sys.argv[1], kind)).read()
    rows = list(csv.DictReader(open("%s/loop-%s.csv" % (sys.argv[1], kind))))
    said = log.count("tracking starts afresh")
    m = re.search(r"tracker: (\d+) frames", log)
    # the reference's model is built beside the first frames, raw until it is (section 7)
    first = next((i for i, r in enumerate(rows) if r['status'] == 'stabilized'), 999)
    off = [(r['index'], r['status'], r['reason']) for r in rows[first:] if r['status'] != 'stabilized']
    if first > 40: off.insert(0, ("first stabilized", first, ""))
    if said != restarts or not m or int(m.group(1)) != frames or len(rows) != 387 or off:
        print(kind, ": restart logged", said, "times, tracker frames", m and m.group(1), ",", len(rows), "rows, not stabilized:", off[:5])
        ok = False
out, log = open(sys.argv[1] + "/loop-per.out").read(), open(sys.argv[1] + "/loop-per.log").read()
stats = re.search(r"(\d+) dropped after the tracker's first lock \(at frame (\d+) published\)$", out.strip())
said = re.search(r"the tracker's rates locked, (\d+) frames published and (\d+) sets dropped before", log)
if not stats or not said or stats.group(1) != "0" or said.group(2) != "0" or stats.group(2) != said.group(1) \
        or not 40 <= int(said.group(1)) <= 200:
    print("lock: stats line %r, log %r" % (out.strip()[-120:], said and said.group(0)))
    ok = False
sys.exit(0 if ok else 1)
PY

# 9. SIGHUP reloads every key in place: a config rewritten to another recording (another size)
#    and another method reopens the cameras, remakes the segment for the new size and says what
#    changed; another file of the same size keeps the segment and its readers; a camera that
#    cannot open is refused by name and the previous cameras come back;
#    systemd hears RELOADING=1, a watchdog ping and READY=1; SIGTERM still stops within a second.
#    Conditions are waited for (qemu-aarch64 is slow), never slept on.
"$B/stillheart-render" --preset exvivo --frames 40 --cameras 1 --width 320 --height 180 --out "$T/reload" >/dev/null 2>&1
python3 - "$B" "$T/ph/cam0.y4m" "$T/reload/cam0.y4m" "$T" "$SHM" > "$T/reload.out" <<'PY'
import os, re, shutil, signal, socket, subprocess, sys, time
B, big, small, T, shm = sys.argv[1:6]
ini, log = T + "/reload.ini", T + "/reload.log"
def config(spec, method):
    open(ini, "w").write("[camera0]\nspec = y4m:%s\n[source]\nrealtime = yes\nloop = yes\n[method]\nname = %s\n"
                         "[sink]\ndisplay = shm:%s\ngroup =\n" % (spec, method, shm))
sp = "/tmp/sh-notify-reload-%d" % os.getpid()
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM); s.bind(sp); s.settimeout(0.2)
got = []
# a start or a reload under qemu-aarch64 beside the other lanes took up to 12 s, once over 30 s
# (issue 21's loop at f4500cf): the time is not what this case tests
WAIT_S = 120 if os.environ.get("SH_TEST_EMULATED") else 30
def wait(cond, timeout=WAIT_S):  # collects notify messages meanwhile
    t0 = time.time()
    while time.time() - t0 < timeout:
        try: got.append(s.recv(4096).decode())
        except socket.timeout: pass
        if cond(): return True
    return False
def readback():  # the Y4M header's size and the number of frames stillheart-cat got
    r = subprocess.run([B + "/stillheart-cat", "--name", shm, "--count", "5", "--timeout", "10"], capture_output=True)
    m = re.match(rb"YUV4MPEG2 W(\d+) H(\d+)", r.stdout)
    return (int(m.group(1)), int(m.group(2)), r.stdout.count(b"FRAME")) if m else (0, 0, 0)
def after(prefix, start):  # index of the first message from start on that begins with prefix
    return next((i for i in range(start, len(got)) if got[i].startswith(prefix)), -1)
def reloaded(mark):  # RELOADING=1 and then READY=1 since message mark
    r = after("RELOADING=1", mark)
    return r >= 0 and after("READY=1", r + 1) >= 0
def result(name, fails):
    print("ok|" + name if not fails else "bad|%s|%s" % (name, "; ".join(fails).replace("\n", " / ")[:600]))
config(big, "tps")
p = subprocess.Popen([B + "/stillheart", "run", "--group=", "--config", ini], stderr=open(log, "w"), stdout=subprocess.DEVNULL,
                     env=dict(os.environ, NOTIFY_SOCKET=sp, WATCHDOG_USEC="2000000"))
up = wait(lambda: after("READY=1", 0) >= 0 and os.path.exists("/dev/shm" + shm))
before = readback() if up else None
# 1. another recording, another size, another method
config(small, "bspline")
mark1 = len(got); p.send_signal(signal.SIGHUP)
done1 = wait(lambda: reloaded(mark1))
r1 = after("RELOADING=1", mark1); r2 = after("READY=1", r1 + 1) if r1 >= 0 else -1
pinged = done1 and "WATCHDOG=1" in got[r1 + 1:r2]
new = readback()
text = open(log).read()
fails = []
if not up or before != (640, 360, 5): fails.append("before the reload: started %s, read back %s" % (up, before))
if new != (320, 180, 5): fails.append("after the reload read back (W, H, frames) %s, want (320, 180, 5)" % (new,))
if not re.search(r"config reloaded: cameras reopened \(640x360 \S+ -> 320x180 \S+\), method tps -> bspline", text):
    fails.append("no reload line: " + text[-400:])
if p.poll() is not None: fails.append("exited with %s" % p.returncode)
result("reload: new cameras, size and method applied in place", fails)
# 2. another file of the same size: the segment is kept, a reader attached across the reload
#    reads on without a break (the display's sequence numbers keep rising)
shutil.copy(small, T + "/reload2.y4m")
config(T + "/reload2.y4m", "tps")
cat = subprocess.Popen([B + "/stillheart-cat", "--name", shm, "--count", "30", "--timeout", "10", "-v"],
                       stdout=open(T + "/kept.y4m", "wb"), stderr=subprocess.PIPE)
first = cat.stderr.readline().decode()
mark3 = len(got); p.send_signal(signal.SIGHUP)
wait(lambda: reloaded(mark3))
# waited for, then read: communicate() with a timeout reads the descriptor itself and would miss
# the lines readline() has already buffered (a loaded machine writes several before it returns);
# 30 short lines fit in the pipe
try: cat.wait(timeout=60)
except subprocess.TimeoutExpired: cat.kill(); cat.wait()
rest = cat.stderr.read().decode()
seqs = [int(x) for x in re.findall(r"^frame (\d+) ", first + rest, re.M)]
text = open(log).read()
fails = []
if cat.returncode != 0 or len(seqs) != 30 or any(b <= a for a, b in zip(seqs, seqs[1:])):
    fails.append("reader across the reload: exit %s, sequences %s" % (cat.returncode, seqs))
if "config reloaded: cameras reopened, method bspline -> tps, sink kept" not in text:
    fails.append("no reload line: " + text[-400:])
result("reload: same size, segment kept, a reader reads on", fails)
# 3. a camera that cannot open: refused by name, the previous cameras back
config("/nonexistent.y4m", "tps")
mark2 = len(got); p.send_signal(signal.SIGHUP)
wait(lambda: reloaded(mark2))
kept = readback()
text = open(log).read()
fails = []
if not re.search(r"ERROR .*reload refused.*/nonexistent\.y4m.*the previous cameras are back", text):
    fails.append("no refusal naming the camera: " + text[-400:])
if kept != (320, 180, 5): fails.append("after the refused reload read back %s, want (320, 180, 5)" % (kept,))
if p.poll() is not None: fails.append("exited with %s" % p.returncode)
result("reload: a camera that cannot open is refused, the previous cameras run on", fails)
t1 = time.time(); p.send_signal(signal.SIGTERM)
try: p.wait(timeout=5)
except subprocess.TimeoutExpired: p.kill(); p.wait()
dt = time.time() - t1
os.unlink(sp)
fails = []
if not done1 or not pinged or not reloaded(mark2):
    fails.append("RELOADING=1, WATCHDOG=1, READY=1 in order: %r" % [g for g in got[mark1:] if not g.startswith("STATUS=")][:12])
if dt >= 1.0 or p.returncode != 0: fails.append("SIGTERM took %.2f s, exit %s" % (dt, p.returncode))
result("reload: RELOADING=1, watchdog ping, READY=1; SIGTERM < 1 s after reloads", fails)
PY
n=0
while IFS='|' read -r res name why; do
    n=$((n + 1)); [ "$res" = ok ] && ok "$name" || bad "$name" "$why"
done < "$T/reload.out"
[ $n -eq 4 ] || bad "reload" "the reload script reported $n of 4 results"
[ -e "/dev/shm$SHM" ] && rm -f "/dev/shm$SHM"

echo "[==========] $((pass + fail)) test(s) run."
[ $fail -eq 0 ] && echo "[  PASSED  ] $pass test(s)." || { echo "[  PASSED  ] $pass test(s)."; echo "[  FAILED  ] $fail test(s)."; exit 1; }
