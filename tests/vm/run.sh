#!/bin/sh
# make vmtest: stillheart's capture code against the kernel's own test drivers (vivid, vimc,
# gpio-sim) in a QEMU guest, no hardware needed (../shared/vm-drivers.md has the background).
#   sh tests/vm/run.sh [BUILD]      BUILD holds stillheart-vmprobe (default: build)
# Downloads Debian 12's backports kernel once (pinned: SH_VM_KVER) into SH_VM_CACHE
# (/var/cache/stillheart/vm), builds a busybox initramfs with the probe, its shared libraries,
# libcamera's IPA modules, vivid (two instances), vimc and gpio-sim (these two built out of tree
# from linux-source), v4l2loopback (built out of tree from Debian's v4l2loopback-dkms source, the
# backports suite's, for the daemon's [sink] v4l2), boots it under TCG and reads "VMTEST
# PASS/FAIL" lines off the serial console. It also builds vkms out of tree (cached), which the
# display guest (tests/vm/show.sh) loads for its vblank timing.
# Host packages: qemu-system-x86 busybox-static kmod cpio xz-utils, libcamera-ipa when the probe
# links libcamera (installed when missing); gstreamer1.0-tools and gstreamer1.0-plugins-good for
# the GStreamer check on the loopback device (scripts/install-deps.sh --vm; without them it is not run).
# What cannot be fetched (no network, no mirror, no root for apt) is not a failure of stillheart:
# the script then prints "vmtest: SKIP: why" and a "vmtest: skipped" summary and exits 0. A check
# that fails in the guest, a module that does not build or a guest that does not finish fails.
set -eu
BUILD="${1:-build}"
CACHE="${SH_VM_CACHE:-/var/cache/stillheart/vm}"
KVER="${SH_VM_KVER:-6.12.95+deb12-amd64}"   # headers exist only for the newest
MIRROR="${SH_VM_MIRROR:-http://deb.debian.org/debian}"
TIMEOUT="${SH_VM_TIMEOUT:-240}"
PROBE="$BUILD/stillheart-vmprobe"
[ -x "$PROBE" ] || { echo "vmtest: $PROBE missing (make $PROBE)" >&2; exit 2; }
skip() {
    echo "vmtest: SKIP: $*"
    echo "vmtest: skipped (0 passed, 0 failed): $*"
    exit 0
}

SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
need=""
for t in qemu-system-x86_64:qemu-system-x86 busybox:busybox-static depmod:kmod cpio:cpio xz:xz-utils; do
    command -v "${t%%:*}" >/dev/null 2>&1 || [ -x "/usr/sbin/${t%%:*}" ] || need="$need ${t#*:}"
done
if ldd "$PROBE" | grep -q libcamera && [ ! -d /usr/lib/x86_64-linux-gnu/libcamera ]; then
    need="$need libcamera-ipa"
fi
if [ -n "$need" ]; then
    echo "vmtest: installing$need" >&2
    $SUDO apt-get install -y -q --no-install-recommends $need >&2 ||
        skip "cannot install the host packages$need (no network or no root?)"
fi
BUSYBOX=$(command -v busybox)
case "$(file -L "$BUSYBOX" 2>/dev/null)" in *dynamically*) echo "vmtest: $BUSYBOX is not static (busybox-static)" >&2; exit 2;; esac

# ---- the kernel and the modules Debian does not ship (cached) ----
KDIR="$CACHE/k/$KVER"
KBASE="${KVER%-amd64}"            # 6.12.95+deb12
MODS="$CACHE/mod/$KVER"
ready() { [ -f "$KDIR/boot/vmlinuz-$KVER" ] && [ -f "$MODS/gpio-sim.ko" ] && [ -f "$MODS/vimc.ko" ]; }
if ! ready; then
    mkdir -p "$CACHE" 2>/dev/null || skip "cannot create the cache $CACHE (SH_VM_CACHE)"
    # two suites at once (make check in two build folders) fill the cache one after the other
    exec 9> "$CACHE/.lock"
    flock 9
fi
if ! ready; then
    mkdir -p "$CACHE/apt/state/lists/partial" "$CACHE/apt/cache/archives/partial" "$CACHE/apt/etc" "$CACHE/deb"
    echo "deb $MIRROR bookworm-backports main" > "$CACHE/apt/etc/sources.list"
    cat > "$CACHE/apt/apt.conf" <<CONF
Dir::State "$CACHE/apt/state";
Dir::State::status "/var/lib/dpkg/status";
Dir::Cache "$CACHE/apt/cache";
Dir::Etc::SourceList "$CACHE/apt/etc/sources.list";
Dir::Etc::SourceParts "$CACHE/apt/etc";
CONF
    # apt-get update reports an unreachable mirror as a warning only: the lists must be there
    rm -f "$CACHE"/apt/state/lists/*_Packages*
    APT_CONFIG="$CACHE/apt/apt.conf" apt-get update -q >&2 && ls "$CACHE"/apt/state/lists/*_Packages* >/dev/null 2>&1 ||
        skip "cannot download the package lists from $MIRROR (no network?)"
    chmod 777 "$CACHE/deb"
    (cd "$CACHE/deb" && APT_CONFIG="$CACHE/apt/apt.conf" apt-get download -q "linux-image-$KVER" \
        "linux-headers-$KVER" "linux-headers-$KBASE-common" "linux-kbuild-$KBASE" linux-source-6.12 >&2) ||
        skip "cannot download linux-image-$KVER and its headers and source from $MIRROR (no network?)"
    rm -rf "$KDIR" "$CACHE/hdr" "$CACHE/src" "$MODS"; mkdir -p "$KDIR" "$CACHE/hdr" "$CACHE/src" "$MODS"
    dpkg -x "$CACHE"/deb/linux-image-"$KVER"_*.deb "$KDIR"
    depmod -b "$KDIR" "$KVER"
    for d in "linux-headers-$KVER" "linux-headers-$KBASE-common" "linux-kbuild-$KBASE"; do
        dpkg -x "$CACHE"/deb/"$d"_*.deb "$CACHE/hdr"
    done
    H="$CACHE/hdr/usr/src/linux-headers-$KVER"
    sed -i "s|include /usr/src/|include $CACHE/hdr/usr/src/|" "$H/Makefile"
    dpkg-deb --fsys-tarfile "$CACHE"/deb/linux-source-6.12_*.deb | tar -xO ./usr/src/linux-source-6.12.tar.xz |
        tar -xJ -C "$CACHE/src" linux-source-6.12/drivers/gpio/gpio-sim.c linux-source-6.12/kernel/irq/irq_sim.c \
            linux-source-6.12/drivers/media/test-drivers/vimc
    # gpio-sim with the irq simulator in one module; irq_to_desc is not exported to modules
    B="$CACHE/build-gpio-sim"; rm -rf "$B"; mkdir -p "$B"
    cp "$CACHE/src/linux-source-6.12/drivers/gpio/gpio-sim.c" "$B/gpio-sim-main.c"
    sed 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' \
        "$CACHE/src/linux-source-6.12/kernel/irq/irq_sim.c" > "$B/irq_sim.c"
    printf 'obj-m := gpio-sim.o\ngpio-sim-y := gpio-sim-main.o irq_sim.o\n' > "$B/Kbuild"
    make -s -C "$H" M="$B" CONFIG_DEBUG_INFO_BTF_MODULES= modules >&2
    cp "$B/gpio-sim.ko" "$MODS/"
    # vimc: its own sources, one module
    B="$CACHE/build-vimc"; rm -rf "$B"; mkdir -p "$B"
    cp "$CACHE"/src/linux-source-6.12/drivers/media/test-drivers/vimc/*.[ch] "$B/"
    printf 'obj-m := vimc.o\nvimc-y := %s\n' "$(cd "$B" && ls *.c | sed 's/\.c$/.o/' | tr '\n' ' ')" > "$B/Kbuild"
    make -s -C "$H" M="$B" CONFIG_DEBUG_INFO_BTF_MODULES= modules >&2
    cp "$B/vimc.ko" "$MODS/"
fi
# v4l2loopback is in no Debian kernel: its DKMS source package (backports: one that builds on
# 6.12), built against the same headers. Cached apart, so a cache made before it is kept.
if [ ! -f "$MODS/v4l2loopback.ko" ]; then
    exec 9> "$CACHE/.lock"
    flock 9
    rm -f "$CACHE"/deb/v4l2loopback-dkms_*.deb
    if (cd "$CACHE/deb" && APT_CONFIG="$CACHE/apt/apt.conf" apt-get download -q v4l2loopback-dkms >&2); then
        B="$CACHE/build-v4l2loopback"; rm -rf "$B"; mkdir -p "$B"
        dpkg -x "$CACHE"/deb/v4l2loopback-dkms_*.deb "$B/x"
        cp "$B"/x/usr/src/v4l2loopback-*/v4l2loopback*.[ch] "$B/"
        printf 'obj-m := v4l2loopback.o\n' > "$B/Kbuild"
        make -s -C "$CACHE/hdr/usr/src/linux-headers-$KVER" M="$B" CONFIG_DEBUG_INFO_BTF_MODULES= modules >&2
        cp "$B/v4l2loopback.ko" "$MODS/"
    else
        echo "vmtest: v4l2loopback-dkms cannot be downloaded from $MIRROR: the [sink] v4l2 checks do not run" >&2
    fi
fi

# vkms, the kernel's virtual KMS driver, for the display's vblank timing (tests/vm/show.sh: the
# bochs driver sends a flip's event as soon as it is committed, vkms at the next vblank of an
# hrtimer at the mode's refresh, as a monitor does). Debian builds it not: its sources from
# linux-source, one module, cached apart as v4l2loopback is.
if [ ! -f "$MODS/vkms.ko" ] && [ -f "$CACHE/deb/linux-source-6.12_"*.deb ] 2>/dev/null; then
    exec 9> "$CACHE/.lock"
    flock 9
    if [ ! -f "$MODS/vkms.ko" ]; then
        B="$CACHE/build-vkms"; rm -rf "$B" "$CACHE/src/linux-source-6.12/drivers/gpu/drm/vkms"; mkdir -p "$B"
        dpkg-deb --fsys-tarfile "$CACHE"/deb/linux-source-6.12_*.deb | tar -xO ./usr/src/linux-source-6.12.tar.xz |
            tar -xJ -C "$CACHE/src" linux-source-6.12/drivers/gpu/drm/vkms
        cp "$CACHE"/src/linux-source-6.12/drivers/gpu/drm/vkms/*.[ch] "$B/"
        printf 'obj-m := vkms.o\nvkms-y := %s\n' "$(cd "$B" && ls *.c | sed 's/\.c$/.o/' | tr '\n' ' ')" > "$B/Kbuild"
        make -s -C "$CACHE/hdr/usr/src/linux-headers-$KVER" M="$B" CONFIG_DRM_VKMS=m CONFIG_DEBUG_INFO_BTF_MODULES= modules >&2
        cp "$B/vkms.ko" "$MODS/"
    fi
fi

# ---- the initramfs ----
WORK=$(mktemp -d); trap 'rm -rf "$WORK"' EXIT
R="$WORK/root"
mkdir -p "$R/bin" "$R/sbin" "$R/proc" "$R/sys" "$R/dev" "$R/tmp" "$R/mods"
cp "$BUSYBOX" "$R/bin/busybox"
for a in sh mount insmod poweroff sleep ls cat echo mkdir; do ln -s busybox "$R/bin/$a"; done
. "$(dirname "$0")/initramfs.sh"
vm_modules "$R" "$KDIR" "$KVER" vivid
for m in $(/sbin/modprobe -d "$KDIR" -S "$KVER" --show-depends configfs | awk '$1 == "insmod" {print $2}'); do
    xz -dc "$m" > "$R/mods/00-configfs.ko"
done
cp "$MODS/gpio-sim.ko" "$R/mods/99-gpio-sim.ko"
cp "$MODS/vimc.ko" "$R/mods/98-vimc.ko"
# loaded by the init with its parameters, after the others (it needs videodev)
[ -f "$MODS/v4l2loopback.ko" ] && mkdir -p "$R/late" && cp "$MODS/v4l2loopback.ko" "$R/late/"
# the loopback check's input, made here (emulation is slow): a 320x180 phantom, its points,
# stillheart warp's output of it, and the same frames at 10 and 2 fps for the real-time runs
if [ -x "$BUILD/stillheart-render" ]; then
    mkdir -p "$R/data"
    "$BUILD/stillheart-render" --preset exvivo --frames 30 --cameras 1 --width 320 --height 180 --out "$WORK/ph" >/dev/null 2>&1
    cp "$WORK/ph/cam0.y4m" "$R/data/in.y4m"
    "$BUILD/stillheart" track --ids 0-15 "$R/data/in.y4m" > "$R/data/points.csv" 2>/dev/null
    "$BUILD/stillheart" warp --method tps --threads 2 --points "$R/data/points.csv" "$R/data/in.y4m" "$R/data/warp.y4m" --quiet
    { head -1 "$R/data/in.y4m" | sed 's/ F[0-9]*:[0-9]*/ F10:1/'; tail -n +2 "$R/data/in.y4m"; } > "$R/data/slow.y4m"
    { head -1 "$R/data/in.y4m" | sed 's/ F[0-9]*:[0-9]*/ F2:1/'; tail -n +2 "$R/data/in.y4m"; } > "$R/data/gst.y4m"
fi
# GStreamer's v4l2src for the README's pipeline on the loopback device: gst-launch-1.0 and the two
# plugins it needs (scripts/install-deps.sh --vm installs them; without them that check says so)
GSTDIR=/usr/lib/x86_64-linux-gnu/gstreamer-1.0
GST=""
if command -v gst-launch-1.0 >/dev/null 2>&1 && [ -f "$GSTDIR/libgstvideo4linux2.so" ]; then
    mkdir -p "$R/gst"
    cp "$(command -v gst-launch-1.0)" "$R/bin/gst-launch-1.0"
    cp "$GSTDIR/libgstvideo4linux2.so" "$GSTDIR/libgstcoreelements.so" "$R/gst/"
    GST="$R/bin/gst-launch-1.0 $R/gst/libgstvideo4linux2.so $R/gst/libgstcoreelements.so"
fi
# libcamera's IPA modules and data (the vimc pipeline handler loads ipa_vimc)
LCDIR=/usr/lib/x86_64-linux-gnu/libcamera
if [ -d "$LCDIR" ]; then
    mkdir -p "$R$LCDIR"; cp -a "$LCDIR"/. "$R$LCDIR/"
    for lib in $(ldd "$LCDIR"/*.so "$LCDIR"/*_proxy 2>/dev/null | awk '/=>/ {print $3}' | sort -u); do
        mkdir -p "$R$(dirname "$lib")"; cp -L "$lib" "$R$lib"
    done
fi
[ -d /usr/share/libcamera ] && mkdir -p "$R/usr/share" && cp -a /usr/share/libcamera "$R/usr/share/"
cp "$PROBE" "$R/bin/stillheart-vmprobe"
[ -x "$BUILD/stillheart" ] && cp "$BUILD/stillheart" "$R/bin/stillheart"
[ -x "$BUILD/stillheart-cat" ] && cp "$BUILD/stillheart-cat" "$R/bin/stillheart-cat"
vm_libs "$R" "$PROBE" "$BUILD/stillheart" "$BUILD/stillheart-cat" $GST
cat > "$R/init" <<'INIT'
#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in /mods/*.ko; do
    case "$m" in
        *vivid.ko) insmod "$m" n_devs=2 node_types=0x1,0x1 || echo "VMTEST FAIL insmod $m" ;;
        *) insmod "$m" || echo "VMTEST FAIL insmod $m" ;;
    esac
done
sleep 1
echo "VMTEST INFO devices: $(ls /dev | grep video | tr '\n' ' ')"
/bin/stillheart-vmprobe formats /dev/video0
/bin/stillheart-vmprobe controls /dev/video0
/bin/stillheart-vmprobe errors /dev/video0
/bin/stillheart-vmprobe sets /dev/video0 /dev/video1
/bin/stillheart-vmprobe loss /dev/video0 vivid.0
# libcamera enumerates through udev: a database entry per video, subdev and media node
mkdir -p /run/udev/data
for d in /sys/class/video4linux/* /sys/bus/media/devices/*; do
    [ -f "$d/dev" ] && echo "I:1" > "/run/udev/data/c$(cat "$d/dev")"
done
LIBCAMERA_LOG_LEVELS='*:ERROR' /bin/stillheart-vmprobe libcamera "Sensor B" 636x480   # vimc: widths in steps of 12
LIBCAMERA_LOG_LEVELS='*:ERROR' /bin/stillheart-vmprobe libcamera-controls "Sensor B" 636x480
LIBCAMERA_LOG_LEVELS='*:FATAL' /bin/stillheart-vmprobe libcamera-loss "Sensor B" 636x480 "$(ls /sys/bus/platform/drivers/vimc | grep '^vimc')"
mount -t configfs none /sys/kernel/config
G=/sys/kernel/config/gpio-sim/stillheart
mkdir $G $G/bank0 && echo 4 > $G/bank0/num_lines && echo 1 > $G/live
CHIP=$(cat $G/bank0/chip_name); DEV=$(cat $G/dev_name)
echo "VMTEST INFO gpio-sim: $CHIP on $DEV"
/bin/stillheart-vmprobe gpio "$CHIP" "/sys/devices/platform/$DEV/$CHIP"
# stillheart record: two vivid cameras, sets on the trigger pulses it drives on gpio-sim line 2
if /bin/stillheart record --source v4l2:/dev/video0 --source v4l2:/dev/video1 --format YUYV --size 320x180 \
        --fps 30 --trigger-out "$CHIP:2" --tolerance-ms 16 --frames 10 /tmp/rec > /tmp/rec.log 2>&1 &&
   grep -q "10 frames recorded" /tmp/rec.log && grep -q "trigger edges driven" /tmp/rec.log &&
   /bin/stillheart record --to-y4m /tmp/rec /tmp/cam1.y4m --camera 1 >> /tmp/rec.log 2>&1 &&
   grep -q "10 frames of camera 1" /tmp/rec.log; then
    echo "VMTEST PASS record: $(grep -E 'sets|trigger' /tmp/rec.log | tr '\n' ' ')"
else
    echo "VMTEST FAIL record: $(tr '\n' ' ' < /tmp/rec.log)"
fi
# stillheart run itself on the two vivid cameras (trigger on gpio-sim line 3): camera 1 silenced,
# then vivid (both cameras) unbound and bound again; its display segment lives in /dev/shm
mkdir -p /dev/shm && mount -t tmpfs shm /dev/shm
/bin/stillheart-vmprobe run /dev/video0 /dev/video1 vivid.0 "$CHIP" 3 300
# [sink] v4l2 on v4l2loopback (/dev/video10), as OBS wants it loaded (exclusive_caps=1); its
# size limits make the format refusal (tools/capture/vmprobe_loop.c)
if [ -f /late/v4l2loopback.ko ] && [ -d /data ]; then
    insmod /late/v4l2loopback.ko devices=1 video_nr=10 exclusive_caps=1 max_width=320 max_height=180 \
        max_buffers=8 card_label=stillheart || echo "VMTEST FAIL insmod v4l2loopback"
    /bin/stillheart-vmprobe loopback /dev/video10 /dev/video0 /data
fi
echo "VMTEST-DONE"
poweroff -f
INIT
chmod +x "$R/init"
(cd "$R" && find . | cpio -o -H newc --quiet | gzip -1) > "$WORK/initrd.gz"

# ---- boot ----
LOG="$BUILD/vmtest.log"
echo "vmtest: booting $KVER under TCG (log: $LOG)" >&2
timeout "$TIMEOUT" qemu-system-x86_64 -accel tcg -cpu max -smp 1 -m 1024 \
    -kernel "$KDIR/boot/vmlinuz-$KVER" -initrd "$WORK/initrd.gz" \
    -append 'console=ttyS0 quiet panic=-1' -nographic -no-reboot > "$LOG" 2>&1 || true
tr -d '\r' < "$LOG" | grep '^VMTEST' || true
pass=$(tr -d '\r' < "$LOG" | grep -c '^VMTEST PASS' || true)
fail=$(tr -d '\r' < "$LOG" | grep -c '^VMTEST FAIL' || true)
if ! tr -d '\r' < "$LOG" | grep -q '^VMTEST-DONE'; then
    echo "vmtest: the guest did not finish (timeout $TIMEOUT s or a crash): see $LOG" >&2
    exit 1
fi
echo "vmtest: $pass passed, $fail failed"
[ "$fail" -eq 0 ] && [ "$pass" -gt 0 ]
