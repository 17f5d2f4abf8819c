#!/bin/sh
# A recording survives its daemon (issue 16), run by make check as build/tests/test_record_kill:
# `stillheart run` recording a Y4M file is SIGKILLed at 50 random moments (10 under emulation).
# After each kill the file holds, as whole frames, at least every frame published more than
# [sink] record_sync_ms before the kill, each of them a frame of the source (a torn last frame is
# allowed: a kill can land in a write); each start writes a new file (rec.y4m, rec-2.y4m, ...) and
# every earlier one is still byte for byte what it was. Prints cmocka-style summary lines.
B=${BUILD:-$(dirname "$(readlink -f "$0")")/..}
T=$(mktemp -d /tmp/sh-record-kill.XXXXXX)
trap 'rm -rf "$T"' EXIT
python3 - "$B/stillheart" "$T" <<'PY'
import hashlib, os, random, signal, socket, subprocess, sys, time
exe, tmp = sys.argv[1:3]
W, H, FPS, SYNC_MS = 64, 48, 50, 200
N = 10 if os.environ.get("SH_TEST_EMULATED") else 50
size = W * H * 3 // 2
# 25 frames, each of one grey level: a frame read back is whole and the source's, or it is not
frames = [bytes([(16 + 9 * k) % 256]) * (W * H) + bytes([128]) * (W * H // 2) for k in range(25)]
src = os.path.join(tmp, "src.y4m")
with open(src, "wb") as f:
    f.write(b"YUV4MPEG2 W%d H%d F%d:1 Ip A1:1 C420jpeg\n" % (W, H, FPS))
    for fr in frames: f.write(b"FRAME\n" + fr)
rec = os.path.join(tmp, "rec.y4m")
def name(k): return rec if k == 0 else os.path.join(tmp, "rec-%d.y4m" % (k + 1))
def whole(path):  # whole frames, and whether a torn one follows
    d = open(path, "rb").read()
    if b"\n" not in d: return None, "no header"
    rest = d.split(b"\n", 1)[1]; out = []
    while len(rest) >= 6 + size and rest[:6] == b"FRAME\n":
        out.append(rest[6:6 + size]); rest = rest[6 + size:]
    if len(rest) >= 6 + size or (rest and not b"FRAME\n".startswith(rest[:6])): return out, "garbage after frame %d" % len(out)
    return out, ""
random.seed(16)
ns = os.path.join(tmp, "notify")
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM); s.bind(ns); s.settimeout(0.05)
env = dict(os.environ, NOTIFY_SOCKET=ns)
sums, fails, least = [], [], None
for k in range(N):
    p = subprocess.Popen([exe, "run", "--group=", "--source", "y4m:" + src, "--loop", "--realtime", "--sink", "none",
                          "--record", rec, "--record-sync-ms", str(SYNC_MS), "--quiet"], env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    t_ready, t0 = None, time.time()
    while t_ready is None and time.time() - t0 < 20 and p.poll() is None:
        try:
            if b"READY=1" in s.recv(4096): t_ready = time.time()
        except socket.timeout: pass
    if t_ready is None:
        p.kill(); fails.append("start %d: no READY=1 (%s)" % (k, p.communicate()[1].decode()[-300:])); break
    time.sleep(random.uniform(0.15, 0.7))
    p.send_signal(signal.SIGKILL); t_kill = time.time(); p.wait()
    if not os.path.exists(name(k)): fails.append("kill %d: no file %s" % (k, name(k))); break
    sums.append(hashlib.sha256(open(name(k), "rb").read()).hexdigest())
    got, why = whole(name(k))
    # published by kill - sync at the source's rate (half of it: a loaded machine drops frames)
    need = int((t_kill - t_ready - SYNC_MS / 1000 - 0.1) * FPS * 0.5)
    if got is None or why: fails.append("kill %d: %s" % (k, why)); continue
    if any(f not in frames for f in got): fails.append("kill %d: a frame that is not the source's" % k)
    if len(got) < need: fails.append("kill %d after %.2f s: %d whole frames on disk, at least %d published %d ms "
                                     "before it" % (k, t_kill - t_ready, len(got), need, SYNC_MS))
    least = min(least, len(got) - need) if least is not None else len(got) - need
    changed = [i for i in range(len(sums) - 1) if hashlib.sha256(open(name(i), "rb").read()).hexdigest() != sums[i]]
    if changed: fails.append("kill %d: earlier recordings changed: %s" % (k, changed))
    p.stderr.close()
print("%d kills; every file new, earlier ones unchanged; whole frames on disk exceed those due by at least %s"
      % (len(sums), least))
for f in fails[:8]: print("FAIL:", f)
ok = not fails and len(sums) == N
print("[       OK ] killed while recording: nothing older than the sync interval lost, nothing written over" if ok else
      "[  FAILED  ] killed while recording: nothing older than the sync interval lost, nothing written over: see above")
print("[==========] 1 test(s) run.")
print("[  PASSED  ] 1 test(s)." if ok else "[  FAILED  ] 1 test(s).")
sys.exit(0 if ok else 1)
PY
