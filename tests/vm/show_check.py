#!/usr/bin/env python3
"""make vmtest, the display part (tests/vm/show.sh): boots the guest with QEMU's bochs-display
(the kernel's bochs DRM driver), answers the guest's "VMSHOW DUMP NAME" lines by taking QEMU's
screendump through the monitor and acknowledging on the guest's second serial port, so that the
guest goes on; the screens are judged once the guest is done, and so is the trace of the vkms run
("VMSHOW TRACE" lines: stillheart-show --trace on the kernel's virtual KMS driver, whose flips
complete at the vblanks of a timer at the mode's refresh). Prints "VMTEST PASS|FAIL name: ..."
lines (the guest's own too) and "vmtest: N passed, N failed".

The expected picture is computed here from the pattern tools/show/vmwriter.c documents, with
BT.601 limited range in floating point and the nearest-neighbour rule of screen.h, independently
of the C code; the overlay's geometry (border, badge, reason band) from the rules screen.h states.

  show_check.py WORK KERNEL INITRD TIMEOUT_S"""
import os
import socket
import subprocess
import sys
import time

W, H = 640, 480            # the mode the guest asks for
FW, FH = 320, 180          # vmwriter's frame
GREEN, AMBER, RED = (0, 200, 0), (255, 176, 0), (224, 0, 0)
TOL = 2                    # per channel: fixed point against floating point, rounding

DAEMON_REASON = "no reference yet (0 markers)"  # the daemon's reason for a frame without markers


def pattern_planes():
    """vmwriter's frame, the pattern its comment states: Y, U, V planes of 320x180 I420."""
    y = bytes(16 + (7 * x + 3 * j) % 220 for j in range(FH) for x in range(FW))
    u = bytes(16 + (5 * i) % 225 for j in range(FH // 2) for i in range(FW // 2))
    v = bytes(16 + (9 * j) % 225 for j in range(FH // 2) for i in range(FW // 2))
    return y + u + v


if sys.argv[1] == "--y4m":  # the daemon's input: that frame N times at 10 fps
    frame = pattern_planes()
    sys.stdout.buffer.write(b"YUV4MPEG2 W%d H%d F10:1 Ip A1:1 C420jpeg\n" % (FW, FH))
    for _ in range(int(sys.argv[2])):
        sys.stdout.buffer.write(b"FRAME\n" + frame)
    sys.exit(0)

work, kernel, initrd, timeout = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
log_path, mon_path, ack_path = (os.path.join(work, n) for n in ("serial.log", "mon.sock", "ack.sock"))
results = []


def result(ok, name, text):
    line = "VMTEST %s %s: %s" % ("PASS" if ok else "FAIL", name, text)
    print(line, flush=True)
    results.append(ok)


def read_ppm(path):
    with open(path, "rb") as f:
        data = f.read()
    parts, pos = [], 0
    while len(parts) < 4:  # P6 W H MAX, whitespace separated
        while data[pos:pos + 1].isspace():
            pos += 1
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        parts.append(data[pos:end])
        pos = end
    pos += 1
    w, h = int(parts[1]), int(parts[2])
    px = data[pos:pos + w * h * 3]
    if parts[0] != b"P6" or len(px) != w * h * 3:
        raise ValueError("%s: not a whole P6 image" % path)
    return w, h, px


def clamp(v):
    return 0 if v < 0 else 255 if v > 255 else int(v + 0.5)


def expected_frame():
    """vmwriter's frame as RGB, BT.601 limited range."""
    out = {}
    for y in range(FH):
        for x in range(FW):
            Y = 16 + (7 * x + 3 * y) % 220
            U = 16 + (5 * (x // 2)) % 225
            V = 16 + (9 * (y // 2)) % 225
            l = (Y - 16) * 255.0 / 219.0
            u = (U - 128) * 255.0 / 224.0
            v = (V - 128) * 255.0 / 224.0
            out[x, y] = (clamp(l + 1.402 * v), clamp(l - 0.344136 * u - 0.714136 * v), clamp(l + 1.772 * u))
    return out


FRAME = expected_frame()
# the picture rectangle: 320x180 on 640x480 is as wide as the screen, bars above and below
PW, PH = W, FH * W // FW
PX, PY = 0, (H - PH) // 2
BORDER = max(2, H // 160)
SCALE = max(1, H // 240)
PAD = 2 * SCALE
BADGE = (PX + BORDER + PAD, PY + BORDER + PAD, 10 * 6 * SCALE + PAD, 7 * SCALE + 2 * PAD)


def pixel(px, x, y):
    i = 3 * (y * W + x)
    return px[i], px[i + 1], px[i + 2]


def inside(r, x, y):
    return r[0] <= x < r[0] + r[2] and r[1] <= y < r[1] + r[3]


def close(a, b):
    return all(abs(p - q) <= TOL for p, q in zip(a, b))


def check_picture(name, px, colour, overlay, reason_chars):
    """The picture region equals the frame (outside the overlay), the bars are black, the
    status frame and badge are where screen.h puts them and in the status colour."""
    band = None
    if reason_chars:
        bh = 7 * SCALE + 2 * PAD
        band = (PX + BORDER, PY + PH - BORDER - bh, reason_chars * 6 * SCALE + 2 * PAD - SCALE, bh)
    bad_bar = bad_pic = bad_frame = 0
    badge_cols, band_cols = set(), set()
    first = None
    for y in range(H):
        for x in range(W):
            p = pixel(px, x, y)
            if not (PX <= x < PX + PW and PY <= y < PY + PH):
                bad_bar += p != (0, 0, 0)
                continue
            edge = min(x - PX, PX + PW - 1 - x, y - PY, PY + PH - 1 - y) < BORDER
            if overlay != "off" and edge:
                bad_frame += p != colour
            elif overlay == "full" and inside(BADGE, x, y):
                badge_cols.add(p)
            elif overlay == "full" and band and inside(band, x, y):
                band_cols.add(p)
            else:
                sx = int((x - PX + 0.5) * FW / PW)
                sy = int((y - PY + 0.5) * FH / PH)
                if not close(p, FRAME[sx, sy]):
                    bad_pic += 1
                    if first is None:
                        first = "(%d,%d) %s, frame (%d,%d) %s" % (x, y, p, sx, sy, FRAME[sx, sy])
    ok = bad_bar == 0 and bad_pic == 0 and bad_frame == 0
    text = "picture %dx%d+%d+%d equals the frame (%d pixels off%s), bars black (%d not), status frame %s (%d not)" % (
        PW, PH, PX, PY, bad_pic, ": " + first if first else "", bad_bar, colour, bad_frame)
    if overlay == "full":
        ok = ok and badge_cols == {colour, (0, 0, 0)}
        text += ", badge %dx%d+%d+%d in %s with black text (colours %d)" % (
            BADGE[2], BADGE[3], BADGE[0], BADGE[1], colour, len(badge_cols))
        if band:
            ok = ok and band_cols == {(0, 0, 0), (255, 255, 255)}
            text += ", reason band white on black (colours %d)" % len(band_cols)
    result(ok, name, text)


def check_no_signal(name, px, since):
    """Black with white text and nothing else: no picture pixel left, text in the middle."""
    other = white = 0
    rows = set()
    for y in range(H):
        for x in range(W):
            p = pixel(px, x, y)
            if p == (255, 255, 255):
                white += 1
                rows.add(y)
            elif p != (0, 0, 0):
                other += 1
    # "NO SIGNAL" at twice the text scale just above the middle, its second line just below
    big = any(H // 2 - 16 * SCALE <= y < H // 2 - 2 * SCALE for y in rows)
    small = any(H // 2 + 2 * SCALE <= y < H // 2 + 9 * SCALE for y in rows)
    ok = other == 0 and big and small and min(rows or [0]) >= H // 2 - 16 * SCALE and max(rows or [H]) < H // 2 + 9 * SCALE
    result(ok, name, "NO SIGNAL (%s): %d white pixels in rows %s..%s, %d of any other colour" % (
        since, white, min(rows or [-1]), max(rows or [-1]), other))


def judge(name, path):
    try:
        w, h, px = read_ppm(path)
    except (OSError, ValueError) as e:
        result(False, name, "screendump: %s" % e)
        return
    if (w, h) != (W, H):
        result(False, name, "the screen is %dx%d, not %dx%d" % (w, h, W, H))
        return
    if name == "show-nosignal-start":
        check_no_signal(name, px, "no frame yet")
    elif name == "show-nosignal-stop":
        check_no_signal(name, px, "1 s after the writer stopped")
    elif name == "show-nosignal-killed":
        check_no_signal(name, px, "1 s after the writer was killed")
    elif name == "show-full-stabilized":
        check_picture(name, px, GREEN, "full", 0)
    elif name == "show-full-raw":
        check_picture(name, px, RED, "full", len("markers lost: 5 of 16 visible"))
    elif name == "show-minimal-degraded":
        check_picture(name, px, AMBER, "minimal", 0)
    elif name == "show-off":
        check_picture(name, px, None, "off", 0)
    elif name in ("show-daemon-raw", "show-daemon-back"):
        check_picture(name, px, RED, "full", len(DAEMON_REASON))
    elif name == "show-daemon-stopped":
        check_no_signal(name, px, "1 s after the daemon stopped")
    else:
        result(False, name, "no such check")


def judge_vblank(mode, lines):
    """The vkms run: flips only on vblanks (the driver's timestamps one refresh period apart, so
    the time from each flip to the next is a whole number of periods), never two on one vblank,
    each at the first vblank after the display asked for it (present to flip at most one period;
    see below for the emulator's stalls),
    and publish-to-flip no more than publish-to-present plus one period, at the 99th percentile:
    the display adds nothing to the wait for the vblank."""
    try:
        refresh = float(mode.split("@")[1])
        rows = [[int(v) for v in l.split(",")] for l in lines if l and not l.startswith("sequence")]
    except (IndexError, ValueError) as e:
        result(False, "show-vblank", "no mode or an unreadable trace (%s): mode %r, %d lines" % (e, mode, len(lines)))
        return
    period = 1e9 / refresh
    if len(rows) < 100:
        result(False, "show-vblank", "%d frames shown in 10 s of a 60 fps writer (want at least 100)" % len(rows))
        return
    flips = [r[5] for r in rows]
    # from flip to flip, not from the first: the mode line's refresh has two decimals
    off_grid = [b for a, b in zip(flips, flips[1:]) if abs((b - a) - round((b - a) / period) * period) > 100e3]
    steps = [round((b - a) / period) for a, b in zip(flips, flips[1:])]
    late = [r for r in rows if not 0 < r[5] - r[4] <= period + 1e6]
    p2f = sorted(r[5] - r[3] for r in rows)
    p2p = sorted(r[4] - r[3] for r in rows)
    p99 = lambda v: v[max(0, -(-99 * len(v) // 100) - 1)]
    # a guest stalled by its host (every instruction emulated, beside the other lanes of make
    # check) can fire a vblank's timer more than a period late, and the flip then lands on the
    # vblank after: at most 2 % of the frames may, the p99 below must hold anyway
    ok = not off_grid and min(steps) >= 1 and len(late) <= len(rows) // 50 and p99(p2f) <= p99(p2p) + period + 1e6
    result(ok, "show-vblank", (
        "%s (period %.3f ms): %d frames shown (sequences %d..%d); flips off the vblank grid: %d; least "
        "vblanks between flips: %d; flips later than one period after present: %d%s; publish-to-present "
        "median %.2f p99 %.2f ms, publish-to-flip median %.2f p99 %.2f ms (at most p99 of the first + "
        "one period + 1 ms)") % (
        mode, period / 1e6, len(rows), rows[0][0], rows[-1][0], len(off_grid), min(steps), len(late),
        " (first: seq %d present-to-flip %.3f ms)" % (late[0][0], (late[0][5] - late[0][4]) / 1e6) if late else "",
        p2p[len(p2p) // 2] / 1e6, p99(p2p) / 1e6, p2f[len(p2f) // 2] / 1e6, p99(p2f) / 1e6))


def connect(path):
    for _ in range(200):
        try:
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(path)
            return s
        except OSError:
            time.sleep(0.05)
    raise RuntimeError("cannot connect to " + path)


def monitor(mon, command):
    mon.sendall((command + "\n").encode())
    buf = b""
    while not buf.endswith(b"(qemu) "):
        chunk = mon.recv(4096)
        if not chunk:
            break
        buf += chunk
    return buf.decode(errors="replace")


def main():
    qemu = subprocess.Popen([
        "qemu-system-x86_64", "-accel", "tcg", "-cpu", "max", "-smp", "1", "-m", "512",
        "-kernel", kernel, "-initrd", initrd, "-append", "console=ttyS0 quiet panic=-1",
        "-display", "none", "-vga", "none", "-device", "bochs-display,xres=%d,yres=%d" % (W, H),
        "-serial", "file:" + log_path,
        "-chardev", "socket,id=ack,path=%s,server=on,wait=off" % ack_path, "-serial", "chardev:ack",
        "-monitor", "unix:%s,server=on,wait=off" % mon_path, "-no-reboot"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=open(os.path.join(work, "qemu.err"), "w"))
    done = False
    dumps = []
    trace, mode, novkms = [], None, False
    try:
        mon, ack = connect(mon_path), connect(ack_path)
        banner = b""
        while not banner.endswith(b"(qemu) "):
            banner += mon.recv(4096)
        end = time.time() + timeout
        seen = 0
        while time.time() < end and qemu.poll() is None:
            time.sleep(0.05)
            try:
                text = open(log_path, "rb").read().decode(errors="replace").replace("\r", "")
            except OSError:
                continue
            lines = text.split("\n")
            complete = lines[:-1]
            for line in complete[seen:]:
                if line.startswith("VMSHOW DUMP "):
                    name = line.split()[2]
                    path = os.path.join(work, name + ".ppm")
                    out = monitor(mon, "screendump " + path)
                    if "rror" in out:
                        result(False, name, "screendump: " + out.strip())
                    else:
                        dumps.append((name, path))
                    # the guest goes on at once: judging takes seconds of Python, and the guest's
                    # programs run on in real time meanwhile
                    ack.sendall(b"ok\n")
                elif line.startswith("VMSHOW TRACE "):
                    trace.append(line[len("VMSHOW TRACE "):].strip())
                elif line.startswith("VMSHOW MODE "):
                    mode = line[len("VMSHOW MODE "):].strip()
                elif line.startswith("VMSHOW NOVKMS"):
                    novkms = True
                elif line.startswith("VMTEST "):
                    print(line, flush=True)
                    if line.startswith(("VMTEST PASS", "VMTEST FAIL")):
                        results.append(line.startswith("VMTEST PASS"))
                elif line.startswith("VMTEST-DONE"):
                    done = True
            seen = len(complete)
            if done:
                break
    finally:
        if qemu.poll() is None:
            try:
                qemu.wait(timeout=20)
            except subprocess.TimeoutExpired:
                qemu.kill()
                qemu.wait()
    for name, path in dumps:
        judge(name, path)
    if novkms:
        print("vmtest: no vkms module in the cache (tests/vm/run.sh builds it): the vblank check did not run")
    elif done and mode is not None:
        judge_vblank(mode, trace)
    elif done:
        result(False, "show-vblank", "the guest gave no vkms mode line")
    if not done:
        print("vmtest: the display guest did not finish (timeout %g s or a crash): see %s" % (timeout, log_path),
              file=sys.stderr)
    passed = sum(1 for r in results if r)
    failed = len(results) - passed + (0 if done else 1)
    print("vmtest: %d passed, %d failed" % (passed, failed))
    return 0 if failed == 0 and passed > 0 else 1


sys.exit(main())
