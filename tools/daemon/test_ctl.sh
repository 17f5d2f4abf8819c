#!/bin/sh
# Control socket tests (run by make check as build/tests/test_ctl): who may do what, judged from
# the peer's credentials, every command logged with uid and pid; idle clients cannot lock others
# out (100 idle connections, from another uid and from the same one, and the daemon still answers
# status within 100 ms, the issue's bound, on the socket and through `stillheart ctl status`); a
# silent client is dropped. Another user is
# played with setpriv (uid 65534), so the tests need root; without it they say so and pass none.
# Prints cmocka-style summary lines.
B=${BUILD:-$(dirname "$(readlink -f "$0")")/..}
if [ "$(id -u)" != 0 ] || ! command -v setpriv >/dev/null || ! command -v python3 >/dev/null; then
    echo "test_ctl: skipped: needs root, setpriv and python3 to play another user (uid $(id -u))"
    echo "[==========] 0 test(s) run."
    echo "[  PASSED  ] 0 test(s)."
    exit 0
fi
T=$(mktemp -d /tmp/sh-ctl-test.XXXXXX)
trap 'rm -rf "$T"' EXIT
chmod 0755 "$T" # uid 65534 must reach the socket: the daemon, not the file mode, decides

python3 - "$B/stillheart" "$T" <<'PY'
import grp, os, socket, subprocess, sys, time
exe, T = sys.argv[1:3]
ctl = T + "/control"
passed = failed = 0
def result(name, fails):
    global passed, failed
    if fails: print("[  FAILED  ] %s: %s" % (name, "; ".join(fails))); failed += 1
    else: print("[       OK ] %s" % name); passed += 1

# two groups of this system that the test user is not in: one for control, one for display
gs = [g for g in grp.getgrall() if 0 < g.gr_gid < 60000]
if len(gs) < 2: print("test_ctl: need two groups besides root's and nobody's"); sys.exit(1)
cg, dg = gs[0], gs[1]
# a small grey Y4M looped in real time: the daemon's status line moves, nothing is detected
w, h = 160, 120
with open(T + "/in.y4m", "wb") as f:
    f.write(b"YUV4MPEG2 W%d H%d F30:1 Ip A1:1 C420jpeg\n" % (w, h))
    for i in range(10): f.write(b"FRAME\n" + bytes([100 + i]) * (w * h) + b"\x80" * (w * h // 2))
# a socket left at the path by a crashed daemon (bound, nobody listening): replaced at start
stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); stale.bind(ctl); stale.close()
log = open(T + "/daemon.log", "w")
def write_ini(control_group, group):
    with open(T + "/ctl.ini", "w") as f: f.write("[run]\ncontrol_group = %s\n[sink]\ngroup = %s\n" % (control_group, group))
write_ini(cg.gr_name, dg.gr_name)
d = subprocess.Popen([exe, "run", "--config", T + "/ctl.ini", "--source", "y4m:" + T + "/in.y4m", "--loop", "--realtime",
                      "--sink", "none", "--control", ctl], stderr=log, stdout=subprocess.DEVNULL)
# ready when the socket takes a connection: the stale one is there from the start (a loop on
# its existence let the test in before the daemon listened: qemu-aarch64, issue 21's pattern)
for i in range(400):
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try: probe.connect(ctl); probe.close(); break
    except OSError: probe.close(); time.sleep(0.05)

# How long a client process may take before it counts as hung: the client's own socket timeouts
# are 3 s, so on the host 10 s means a hang. Under qemu-aarch64 beside the other lanes a fresh
# process took over 10 s to start and ask (issue 21's loop at bb21afd, run 2: 'ctl reference' from
# uid 65534, after the reload case); its time is not what these cases test.
CLIENT_S = 120 if os.environ.get("SH_TEST_EMULATED") else 10
def as_user(groups):  # setpriv as uid/gid 65534 with exactly these supplementary groups
    return ["setpriv", "--reuid=65534", "--regid=65534"] + (["--groups=" + ",".join(str(g) for g in groups)] if groups else ["--clear-groups"])
def daemon_log():
    log.flush(); return open(T + "/daemon.log").read()
def hung(t0, e):  # a client with no answer in CLIENT_S: a failure that says what the daemon logged meanwhile
    tail = daemon_log().splitlines()[-6:]
    return "no answer in %.1f s (stdout %r, stderr %r); daemon %s, its last log lines: %r" % (
        time.monotonic() - t0, e.stdout, e.stderr, "running" if d.poll() is None else "exited %s" % d.returncode, tail)
def ask(cmd, who=None):
    t0 = time.monotonic()
    try: p = subprocess.run((who or []) + [exe, "ctl", "--socket", ctl, cmd], capture_output=True, text=True, timeout=CLIENT_S)
    except subprocess.TimeoutExpired as e: return -1, "", hung(t0, e)
    return p.returncode, p.stdout.strip(), p.stderr.strip()
def ask_logged(cmd, who):  # the reply and the daemon's log line about this very process
    t0 = time.monotonic()
    p = subprocess.Popen((who or []) + [exe, "ctl", "--socket", ctl, cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try: out, err = p.communicate(timeout=CLIENT_S)
    except subprocess.TimeoutExpired as e:
        p.kill(); p.communicate(); return -1, "", hung(t0, e), []
    time.sleep(0.1)
    lines = [l for l in daemon_log().splitlines() if " pid %d" % p.pid in l]
    return p.returncode, out.strip(), err.strip(), lines

f = []
rc, out, err = ask("status")
if rc or not (out.startswith("frame ") or out.startswith("starting")): f.append("root status: rc %d %r %r" % (rc, out, err))
result("root: status answered", f)

# status --json: the socket's status-json, one JSON object; the grey frames have no markers, so
# every frame is shown raw with 0 markers; refused to whom status is refused
import json
def ask_json(who=None):
    # a client that gets no answer in CLIENT_S is a failure that says what the daemon logged
    # meanwhile (the aarch64 loop once met one: issue 21), not a traceback that ends the suite
    t0 = time.monotonic()
    try:
        p = subprocess.run((who or []) + [exe, "ctl", "--socket", ctl, "--json", "status"], capture_output=True, text=True, timeout=CLIENT_S)
    except subprocess.TimeoutExpired as e:
        return -1, "", hung(t0, e)
    return p.returncode, p.stdout.strip(), p.stderr.strip()
f = []
for i in range(100):
    rc, out, err = ask_json()
    try: js = json.loads(out)
    except ValueError as e: js = None; f.append("not JSON: rc %d %r %r (%s)" % (rc, out, err, e)); break
    if rc or js.get("state") not in ("starting", "running"): f.append("rc %d %r" % (rc, out)); break
    if js.get("state") == "running": break
    time.sleep(0.05)
if js and js.get("state") == "running":
    if js.get("status") != "raw" or js.get("markers") != 0 or not js.get("published") or "dropped" not in js or "frame" not in js:
        f.append("running: %r" % js)
elif not f: f.append("never running: %r" % out)
rc, out, err = ask_json(as_user([]))
if rc != 1 or "not permitted" not in err or out: f.append("uid 65534 status --json: rc %d %r %r" % (rc, out, err))
result("status --json: state, frame, status raw, 0 markers, published, dropped; refused as status is", f)

f = []
refs0 = daemon_log().count("new reference requested (control socket)")
rc, out, err, lines = ask_logged("reference", as_user([]))
if rc != 1 or "not permitted" not in err: f.append("uid 65534 reference: rc %d %r %r" % (rc, out, err))
if not any("uid 65534" in l and "refused: reference: not permitted" in l for l in lines): f.append("no refusal logged with uid and pid: %r" % lines)
rc, out, err, lines = ask_logged("status", as_user([]))
if rc != 1 or "not permitted" not in err: f.append("uid 65534 status: rc %d %r %r" % (rc, out, err))
if not any("uid 65534" in l and "refused: status" in l for l in lines): f.append("status refusal not logged: %r" % lines)
time.sleep(0.3)
if daemon_log().count("new reference requested (control socket)") != refs0: f.append("a reference was taken anyway")
result("uid 65534 outside the groups: reference and status refused, logged with uid and pid", f)

f = []
rc, out, err, lines = ask_logged("reference", as_user([dg.gr_gid]))
if rc != 1 or "not permitted" not in err: f.append("display group reference: rc %d %r %r" % (rc, out, err))
rc, out, err, lines = ask_logged("status", as_user([dg.gr_gid]))
if rc or not out: f.append("display group status: rc %d %r %r" % (rc, out, err))
if not any("status from uid 65534" in l for l in lines): f.append("status not logged: %r" % lines)
result("uid 65534 in [sink] group: status answered, reference refused", f)

f = []
rc, out, err, lines = ask_logged("reference", as_user([cg.gr_gid]))
if rc or out != "ok: new reference requested": f.append("control group reference: rc %d %r %r" % (rc, out, err))
if not any("reference from uid 65534" in l and "accepted" in l for l in lines): f.append("not logged: %r" % lines)
time.sleep(0.3)
if daemon_log().count("new reference requested (control socket)") != refs0 + 1: f.append("no reference taken: " + daemon_log()[-300:])
result("uid 65534 in [run] control_group: reference accepted and logged", f)

# 100 idle connections held by a child (another uid, then root as the asking client). Timed twice:
# the daemon's answer on the socket (connect to reply, as stillheart ctl speaks), and `stillheart
# ctl status` from spawn to exit less the program's own start-up (`stillheart ctl --help`), each
# the least of three (under ASan on a loaded machine the start-up alone takes 0.1 s)
HOLD = r'''
import socket, sys, time
s = []
for i in range(100):
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); c.settimeout(5); c.connect(sys.argv[1]); s.append(c)
print("held", flush=True); time.sleep(30)
'''
def answer_ms():
    t0 = time.monotonic()
    # a blocking connect, as stillheart ctl's: it waits for room in the listening queue
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); c.connect(ctl); c.settimeout(5); c.sendall(b"status\n")
    out = b""
    while True:
        b = c.recv(256)
        if not b: break
        out += b
    c.close()
    return (time.monotonic() - t0) * 1000, out.decode().strip()
def startup_ms():
    best = None
    for i in range(3):
        t0 = time.monotonic(); subprocess.run([exe, "ctl", "--help"], capture_output=True); dt = (time.monotonic() - t0) * 1000
        best = dt if best is None or dt < best else best
    return best
# The issue's 100 ms is the host's; under qemu-aarch64 (SH_TEST_EMULATED) every instruction costs
# about ten times as much: the daemon's answer there is bounded by 500 ms, still far under a
# client's 1 s idle limit that idle connections get (and the client's own time is printed).
LIMIT = 500 if os.environ.get("SH_TEST_EMULATED") else 100
for who, name in ((as_user([]), "uid 65534"), ([], "root, the asking uid itself")):
    f = []
    holder = subprocess.Popen(who + [sys.executable, "-c", HOLD, ctl], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if holder.stdout.readline().strip() != "held": f.append("the holder could not open 100 connections: " + holder.stderr.read()[-300:])
    sock_ms, out = answer_ms()
    if sock_ms >= LIMIT or not out.startswith("frame "): f.append("socket answer %r after %.1f ms" % (out, sock_ms))
    start = startup_ms()
    dt = None
    for i in range(3):  # the least of three, as the start-up: a load spike on a shared machine is not the daemon's
        t0 = time.monotonic(); rc, out, err = ask("status"); t = (time.monotonic() - t0) * 1000
        dt = t if dt is None or t < dt else dt
        if rc or not out.startswith("frame "): f.append("stillheart ctl status: rc %d %r %r" % (rc, out, err))
    print("100 idle connections from %s: the daemon answered in %.1f ms; stillheart ctl status took %.1f ms, "
          "%.1f ms of them its start-up" % (name, sock_ms, dt, start))
    # Under emulation the client's own time is printed, not bounded: a fresh qemu-aarch64 process
    # starts in 0.7-0.8 s, and two of them differ by as much (issue 21's loop at 6a5a3e4: 808 ms
    # for --help, 1802 ms for status, the daemon's answer 3.0 ms). The daemon's answer, timed
    # above on the socket by this native script, is what stays bounded there.
    if dt - start >= LIMIT and not os.environ.get("SH_TEST_EMULATED"):
        f.append("stillheart ctl status answered %.1f ms after its start-up, over %d ms" % (dt - start, LIMIT))
    holder.kill(); holder.wait()
    result("100 idle connections from %s: status answered within 100 ms" % name, f)

# a flood: uid 65534 opens connections as fast as it can for 2 s and holds them; status from
# root is still answered every time (the slowest printed, not bounded: the flooder takes a core)
FLOOD = r'''
import socket, sys, time
held, end = [], time.monotonic() + 2
print("flooding", flush=True)
while time.monotonic() < end:
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); c.settimeout(1)
    try: c.connect(sys.argv[1]); held.append(c)
    except OSError: c.close()
    if len(held) > 900: held.pop(0).close()
'''
f = []
flood = subprocess.Popen(as_user([]) + [sys.executable, "-c", FLOOD, ctl], stdout=subprocess.PIPE, text=True)
flood.stdout.readline(); time.sleep(0.3)
slowest = 0
for i in range(10):
    ms, out = answer_ms()
    slowest = max(slowest, ms)
    if not out.startswith("frame "): f.append("status %d under the flood: %r" % (i, out))
    time.sleep(0.1)
flood.wait()
print("status under a connection flood from uid 65534: 10 of 10 asked, the slowest answer %.1f ms" % slowest)
result("a connection flood from another uid: every status answered", f)

f = []
c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM); c.settimeout(5); c.connect(ctl); c.sendall(b"stat")
t0 = time.monotonic()
try: got = c.recv(100)
except socket.timeout: got = None
dt = time.monotonic() - t0
if got != b"" or dt > 3: f.append("a client that never finished its line was not dropped (%r after %.2f s)" % (got, dt))
time.sleep(1.1)
if "sent no command within 1000 ms" not in daemon_log(): f.append("the drops were not logged: " + daemon_log()[-300:])
result("a silent client is dropped (%.2f s) and the drops logged" % dt, f)

# a reload applies new groups to the running socket; a group that does not exist is refused
def reload(mark):
    d.send_signal(1)  # SIGHUP
    for i in range(100):
        text = daemon_log()[mark:]
        if "config reloaded" in text or "reload refused" in text: return text
        time.sleep(0.05)
    return daemon_log()[mark:]
f = []
write_ini(dg.gr_name, dg.gr_name)
text = reload(len(daemon_log()))
if "control-group" not in text or "-> " + dg.gr_name not in text: f.append("reload: " + text[-300:])
rc, out, err, lines = ask_logged("reference", as_user([dg.gr_gid]))
if rc or out != "ok: new reference requested": f.append("new control group's reference: rc %d %r %r" % (rc, out, err))
rc, out, err, lines = ask_logged("reference", as_user([cg.gr_gid]))
if rc != 1 or "not permitted" not in err: f.append("old control group's reference: rc %d %r %r" % (rc, out, err))
write_ini("no-such-group-sh", dg.gr_name)
text = reload(len(daemon_log()))
if "reload refused" not in text or "no group 'no-such-group-sh'" not in text: f.append("unknown group reload: " + text[-300:])
rc, out, err, lines = ask_logged("reference", as_user([dg.gr_gid]))
if rc or out != "ok: new reference requested": f.append("after the refused reload: rc %d %r %r" % (rc, out, err))
result("reload: new groups applied to the running socket, an unknown group refused and the running ones kept", f)

f = []
p = subprocess.run([exe, "run", "--source", "y4m:" + T + "/in.y4m", "--sink", "none", "--control", ctl, "--quiet"],
                   capture_output=True, text=True, timeout=2 * CLIENT_S)
if p.returncode == 0 or "in use by a running daemon" not in p.stderr: f.append("second daemon: rc %d %r" % (p.returncode, p.stderr[-200:]))
rc, out, err = ask("status")
if rc or not out.startswith("frame "): f.append("the first no longer answers: rc %d %r %r" % (rc, out, err))
result("a second daemon on the same socket path is refused, the first answers on", f)

d.terminate()
try: rc = d.wait(timeout=5)
except subprocess.TimeoutExpired: d.kill(); rc = d.wait()
result("daemon exits 0 on SIGTERM, socket removed", [] if rc == 0 and not os.path.exists(ctl) else ["exit %s, socket left %s" % (rc, os.path.exists(ctl))])
print("[==========] %d test(s) run." % (passed + failed))
print("[  PASSED  ] %d test(s)." % passed)
if failed: print("[  FAILED  ] %d test(s)." % failed); sys.exit(1)
PY
