#!/bin/sh
# Daemon tests (run by make check as build/tests/test_daemon): end to end against
# `stillheart warp`, gating on an occlusion sequence, bad configs refused, SIGTERM within 1 s,
# sd_notify against a socket this test opens. Prints cmocka-style summary lines.
B=${BUILD:-$(dirname "$0")/..}
T=$(mktemp -d /tmp/sh-daemon-test.XXXXXX)
trap 'rm -rf "$T"' EXIT
pass=0; fail=0
ok()  { echo "[       OK ] $1"; pass=$((pass + 1)); }
bad() { echo "[  FAILED  ] $1: $2"; fail=$((fail + 1)); }
SHM=/sh-dtest-$$
RUN="$B/stillheart run --group= --quiet"

"$B/stillheart-render" --preset exvivo --frames 40 --cameras 1 --width 640 --height 360 --out "$T/ph" >/dev/null 2>&1 || { bad render "stillheart-render failed"; }
"$B/stillheart" track --ids 0-15 "$T/ph/cam0.y4m" > "$T/points.csv" 2>/dev/null || bad track "stillheart track failed"

# 1. end to end: what the daemon shows (its record and the shm read back) equals stillheart warp.
"$B/stillheart" warp --method tps --threads 2 --points "$T/points.csv" "$T/ph/cam0.y4m" "$T/warp.y4m" --quiet
$RUN --source "y4m:$T/ph/cam0.y4m" --no-loop --no-realtime --sink none --points "$T/points.csv" \
    --method tps --threads 2 --record "$T/rec.y4m" --min-markers 3 && cmp -s "$T/rec.y4m" "$T/warp.y4m" \
    && ok "record equals stillheart warp" || bad "record equals stillheart warp" "differs"
# shm: real time (23 fps) so the reader sees every frame; each frame read back equals warp's
$RUN --source "y4m:$T/ph/cam0.y4m" --no-loop --realtime --sink "shm:$SHM" --points "$T/points.csv" \
    --method tps --threads 2 --min-markers 3 & pid=$!
for i in 1 2 3 4 5 6 7 8 9 10; do [ -e "/dev/shm$SHM" ] && break; sleep 0.1; done
"$B/stillheart-cat" --name "$SHM" --count 20 --timeout 5 > "$T/cat.y4m" 2>/dev/null
wait $pid
python3 - "$T/cat.y4m" "$T/warp.y4m" <<'PY' && ok "shm frames equal stillheart warp" || bad "shm frames equal stillheart warp" "see above"
import sys
def frames(p):
    d = open(p, 'rb').read()
    hdr, rest = d.split(b'\n', 1)
    w = int([t for t in hdr.split() if t.startswith(b'W')][0][1:]); h = int([t for t in hdr.split() if t.startswith(b'H')][0][1:])
    n = w * h * 3 // 2
    out = []
    while rest:
        line, rest = rest.split(b'\n', 1)
        out.append(rest[:n]); rest = rest[n:]
    return out
a, b = frames(sys.argv[1]), frames(sys.argv[2])
if len(a) < 15: print("only", len(a), "frames read back"); sys.exit(1)
for f in a:
    best = min(max(abs(x - y) for x, y in zip(f[::97], g[::97])) for g in b)
    if best > 1: print("a frame read back matches no warp frame (max diff", best, ")"); sys.exit(1)
PY

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
rows = list(csv.DictReader(open(sys.argv[2])))
need(len(rows) == 240, "all.csv: %d frames" % len(rows))
bad_hidden = [int(r['index']) for r in rows if any_hidden(int(r['index'])) and r['status'] == 'stabilized']
clear = [r for r in rows if int(r['index']) > 0 and not near(int(r['index']), 2)]
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
runs, n = [], 0
for s in st + ['end']:
    if s == 'degraded': n += 1
    elif n: runs.append(n); n = 0
need(max(runs) <= 6, "a degraded stretch of %d frames (dropout_ms 200 = 4.6 frames)" % max(runs))
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
[ $rc -eq 2 ] && echo "$msg" | grep -q -- "--frobnicate: unknown option" && ok "unknown option refused" || bad "unknown option refused" "$msg"
msg=$($RUN --config "$T/bad.ini" --min-markers 5 --print-config 2>&1); rc=$?
[ $rc -eq 2 ] && ok "command line does not hide a bad file" || bad "command line does not hide a bad file" "$msg"
printf '[gating]\nmin_markers = 9\n' > "$T/good.ini"
msg=$($RUN --config "$T/good.ini" --min-markers 7 --print-config 2>&1)
echo "$msg" | grep -q "^min_markers = 7" && ok "command line wins" || bad "command line wins" "$msg"

# 4. SIGTERM stops within a second, segment closed; sd_notify READY/STATUS/WATCHDOG; SIGHUP bad reload kept
python3 - "$B/stillheart" "$T/ph/cam0.y4m" "$T/good.ini" "$SHM" <<'PY' && ok "notify, reload, SIGUSR1 reference, SIGTERM < 1 s" || bad "notify, reload, SIGUSR1 reference, SIGTERM < 1 s" "see above"
import os, socket, subprocess, sys, time, signal
exe, video, ini, shm = sys.argv[1:5]
sp = "/tmp/sh-notify-test-%d" % os.getpid()
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM); s.bind(sp); s.settimeout(5)
env = dict(os.environ, NOTIFY_SOCKET=sp, WATCHDOG_USEC="400000")
p = subprocess.Popen([exe, "run", "--group=", "--config", ini, "--source", "y4m:" + video, "--realtime",
                      "--loop", "--points", "", "--sink", "shm:" + shm], env=env, stderr=subprocess.PIPE)
got = []
t0 = time.time()
while time.time() - t0 < 3:
    try: got.append(s.recv(4096).decode())
    except socket.timeout: break
open(ini, "w").write("[gating]\nmin_markers = nope\n")
p.send_signal(signal.SIGHUP); time.sleep(0.5)
p.send_signal(signal.SIGUSR1); time.sleep(0.5)
alive = p.poll() is None
t1 = time.time(); p.send_signal(signal.SIGTERM); p.wait(timeout=5); dt = time.time() - t1
err = p.stderr.read().decode()
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

echo "[==========] $((pass + fail)) test(s) run."
[ $fail -eq 0 ] && echo "[  PASSED  ] $pass test(s)." || { echo "[  PASSED  ] $pass test(s)."; echo "[  FAILED  ] $fail test(s)."; exit 1; }
