#!/bin/sh
# make vmtest, the display part: stillheart-show on the kernel's own KMS driver in a QEMU guest.
#   sh tests/vm/show.sh [BUILD]     BUILD holds stillheart-show and show-vmwriter (default: build)
# The guest gets QEMU's bochs-display (the bochs DRM driver, a module of Debian's kernel) at
# 640x480, a writer publishing a known frame (tools/show/vmwriter.c) and stillheart-show; the host
# (tests/vm/show_check.py) reads back what is on the screen with QEMU's screendump and compares
# it with the frame: the picture region, the letterbox bars, the status frame and badge, the
# reason line, NO SIGNAL before the first frame and within a second of the writer stopping or
# being killed, the picture back when a writer returns, overlay off leaving the picture
# untouched; then the same with the daemon (stillheart run replaying that frame, published raw):
# the picture and its reason, NO SIGNAL a second after the daemon stopped, the picture back when
# it is started again. In the guest:
# the refusals (DRM master held by the running instance, no such connector, mode, device) and
# --stats' latency line. Then, on vkms (the kernel's virtual KMS driver, built by tests/vm/run.sh,
# whose flips complete at the vblanks of a timer at the mode's refresh, as on a monitor; bochs
# completes them at once), a writer at 60 frames/s and stillheart-show --trace: the host checks
# that every flip landed on a vblank, at most one per vblank, at the first vblank after it was
# asked for, and that publish-to-flip is publish-to-present plus at most one refresh period
# (docs/display.md, "Latency"). Uses the kernel tests/vm/run.sh caches (SH_VM_CACHE); without it,
# and without qemu, it prints "vmtest: SKIP" and a skipped summary, as run.sh does.
set -eu
BUILD="${1:-build}"
CACHE="${SH_VM_CACHE:-/var/cache/stillheart/vm}"
KVER="${SH_VM_KVER:-6.12.95+deb12-amd64}"
TIMEOUT="${SH_VM_TIMEOUT:-300}"
SHOW="$BUILD/stillheart-show"
WRITER="$BUILD/show-vmwriter"
for b in "$SHOW" "$WRITER" "$BUILD/stillheart"; do [ -x "$b" ] || { echo "vmtest: $b missing (make $b)" >&2; exit 2; }; done
skip() {
    echo "vmtest: SKIP: $*"
    echo "vmtest: skipped (0 passed, 0 failed): $*"
    exit 0
}
KDIR="$CACHE/k/$KVER"
[ -f "$KDIR/boot/vmlinuz-$KVER" ] || skip "no kernel in $KDIR (tests/vm/run.sh fetches it)"
command -v qemu-system-x86_64 >/dev/null 2>&1 || skip "no qemu-system-x86_64 (tests/vm/run.sh installs it)"
command -v python3 >/dev/null 2>&1 || skip "no python3"
BUSYBOX=$(command -v busybox)

WORK=$(mktemp -d); trap 'rm -rf "$WORK"' EXIT
R="$WORK/root"
mkdir -p "$R/bin" "$R/proc" "$R/sys" "$R/dev" "$R/tmp" "$R/mods"
cp "$BUSYBOX" "$R/bin/busybox"
for a in sh mount insmod poweroff sleep ls cat echo mkdir kill grep stty tr head readlink sed; do ln -s busybox "$R/bin/$a"; done
. "$(dirname "$0")/initramfs.sh"
vm_modules "$R" "$KDIR" "$KVER" bochs || skip "no bochs module in $KDIR"
# vkms after the bochs checks (bochs stays card0): the modules it needs that bochs did not load,
# in order, into /late; without the module (a cache made before it) the vblank check says so
if [ -f "$CACHE/mod/$KVER/vkms.ko" ]; then
    mkdir -p "$R/late"
    n=0
    for m in $(for d in drm_shmem_helper drm_kms_helper; do /sbin/modprobe -d "$KDIR" -S "$KVER" --show-depends $d; done |
               awk '$1 == "insmod" {print $2}'); do
        b=$(basename "${m%.xz}")
        ls "$R/mods" "$R/late" | grep -q -- "-$b\$" && continue
        n=$((n + 1))
        case "$m" in *.xz) xz -dc "$m" > "$R/late/$(printf %02d $n)-$b" ;; *) cp "$m" "$R/late/$(printf %02d $n)-$b" ;; esac
    done
    cp "$CACHE/mod/$KVER/vkms.ko" "$R/late/99-vkms.ko"
fi
cp "$SHOW" "$R/bin/stillheart-show"
cp "$WRITER" "$R/bin/show-vmwriter"
cp "$BUILD/stillheart" "$R/bin/stillheart"
vm_libs "$R" "$SHOW" "$WRITER" "$BUILD/stillheart"
# the daemon's input: vmwriter's frame 60 times (6 s at 10 fps), which it publishes raw
python3 "$(dirname "$0")/show_check.py" --y4m 60 > "$R/pattern.y4m"
cat > "$R/init" <<'INIT'
#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
mkdir -p /dev/shm && mount -t tmpfs shm /dev/shm
for m in /mods/*.ko; do insmod "$m" || echo "VMTEST FAIL insmod $m"; done
sleep 1
echo "VMTEST INFO dri: $(ls /dev/dri | tr '\n' ' ')"
# the host acknowledges each screendump on the second serial port
stty -F /dev/ttyS1 raw -echo
exec 3< /dev/ttyS1
dump() { echo "VMSHOW DUMP $1"; read -r ack <&3; }
pass() { echo "VMTEST PASS $1: $2"; }
fail() { echo "VMTEST FAIL $1: $2"; }
N=/vmshow
D=/dev/dri/card0
stillheart-show --device $D --mode 640x480 --name $N --stats > /tmp/show1.log 2>&1 &
S=$!
sleep 2
dump show-nosignal-start
show-vmwriter $N 6 stabilized 2> /tmp/w1.log &
W=$!
sleep 3
dump show-full-stabilized
# a second display on the same device while the first holds DRM master
stillheart-show --device $D --name $N > /tmp/second.log 2>&1; rc=$?
if [ $rc = 1 ] && grep -q "DRM master is held by another process: $S (stillheart-show)" /tmp/second.log; then
    pass show-master-held "$(cat /tmp/second.log)"
else fail show-master-held "exit $rc: $(tr '\n' ' ' < /tmp/second.log)"; fi
wait $W
sleep 1
dump show-nosignal-stop
# the writer returns: the picture comes back, now raw with its reason
show-vmwriter $N 120 raw "markers lost: 5 of 16 visible" 2> /tmp/w2.log &
W=$!
sleep 3
dump show-full-raw
# a writer that dies (its segment neither closed nor retired: only stale)
kill -9 $W; wait $W
sleep 1
dump show-nosignal-killed
kill $S; wait $S; rc=$?
st=$(grep 'stats (end)' /tmp/show1.log)
if [ $rc = 0 ] && echo "$st" | grep -q 'capture-to-scanout median [0-9.]* p99 [0-9.]* max [0-9.]* ms (n [1-9]'; then
    pass show-stats "$st"
else fail show-stats "exit $rc: $(tr '\n' ' ' < /tmp/show1.log)"; fi
echo "VMTEST INFO show log: $(tr '\n' '|' < /tmp/show1.log)"
for ov in minimal off; do
    stillheart-show --device $D --mode 640x480 --name $N --overlay $ov > /tmp/show-$ov.log 2>&1 &
    S=$!
    show-vmwriter $N 4 degraded "short dropout" 2> /dev/null &
    W=$!
    sleep 3
    [ $ov = minimal ] && dump show-minimal-degraded || dump show-off
    wait $W
    kill $S; wait $S
done
# the daemon itself: a replay of the pattern (no markers: published raw, "no reference yet"),
# stopped, and started again
stillheart-show --device $D --mode 640x480 --name $N > /tmp/show-d.log 2>&1 &
S=$!
run_daemon() {
    stillheart run --group= --source y4m:/pattern.y4m --realtime=1 --sink shm:$N --quiet > /tmp/d.log 2>&1 &
    W=$!
}
run_daemon
sleep 3
dump show-daemon-raw
kill $W; wait $W
sleep 1
dump show-daemon-stopped
run_daemon
sleep 3
dump show-daemon-back
kill $W; wait $W
kill $S; wait $S
echo "VMTEST INFO show with the daemon: $(tr '\n' '|' < /tmp/show-d.log)"
# refusals, each naming what it did not find
stillheart-show --device $D --connector HDMI-A-9 > /tmp/r.log 2>&1; rc=$?
if [ $rc = 1 ] && grep -q "no connector 'HDMI-A-9' (there are: Virtual-1 (connected))" /tmp/r.log; then
    pass show-no-connector "$(cat /tmp/r.log)"; else fail show-no-connector "exit $rc: $(cat /tmp/r.log)"; fi
stillheart-show --device $D --mode 123x45 > /tmp/r.log 2>&1; rc=$?
if [ $rc = 1 ] && grep -q "connector Virtual-1 does not offer the mode 123x45 (it offers: .*640x480@" /tmp/r.log; then
    pass show-no-mode "$(head -c 160 /tmp/r.log)..."; else fail show-no-mode "exit $rc: $(cat /tmp/r.log)"; fi
stillheart-show --device /dev/dri/card9 > /tmp/r.log 2>&1; rc=$?
if [ $rc = 1 ] && grep -q "/dev/dri/card9: No such file or directory (no such device" /tmp/r.log; then
    pass show-no-device "$(cat /tmp/r.log)"; else fail show-no-device "exit $rc: $(cat /tmp/r.log)"; fi
# vblank timing on vkms: 10 s of a 60 fps writer, every frame shown traced (the host judges it)
if [ -d /late ]; then
    for m in /late/*.ko; do insmod "$m" || echo "VMTEST FAIL insmod $m"; done
    sleep 1
    V=""
    for c in /sys/class/drm/card[0-9]*; do
        case "$(readlink "$c/device")" in *vkms*) V=/dev/dri/${c##*/} ;; esac
    done
    if [ -n "$V" ]; then
        stillheart-show --device $V --mode 640x480 --name /vmlat --stats --trace /tmp/lat.csv > /tmp/lat.log 2>&1 &
        S=$!
        sleep 2
        show-vmwriter /vmlat 10 stabilized "" 60 2> /tmp/wl.log
        sleep 1
        kill $S; wait $S
        echo "VMTEST INFO vkms ($V): $(tr '\n' '|' < /tmp/lat.log) writer: $(cat /tmp/wl.log)"
        echo "VMSHOW MODE $(grep -o 'Virtual-[0-9]* [0-9]*x[0-9]*@[0-9.]*' /tmp/lat.log | head -1)"
        sed 's/^/VMSHOW TRACE /' /tmp/lat.csv
    else
        fail show-vblank "vkms loaded but no card of it in /sys/class/drm: $(ls /sys/class/drm | tr '\n' ' ')"
    fi
else
    echo "VMSHOW NOVKMS"
fi
echo "VMTEST-DONE"
poweroff -f
INIT
chmod +x "$R/init"
(cd "$R" && find . | cpio -o -H newc --quiet | gzip -1) > "$WORK/initrd.gz"
echo "vmtest: booting $KVER with bochs-display under TCG (display check)" >&2
rc=0
python3 "$(dirname "$0")/show_check.py" "$WORK" "$KDIR/boot/vmlinuz-$KVER" "$WORK/initrd.gz" "$TIMEOUT" || rc=$?
# the guest's console and the screens, for a look when a check fails
cp "$WORK/serial.log" "$BUILD/vmtest-show.log" 2>/dev/null || true
rm -rf "$BUILD/vmtest-show"; mkdir -p "$BUILD/vmtest-show"; cp "$WORK"/*.ppm "$BUILD/vmtest-show/" 2>/dev/null || true
exit $rc
