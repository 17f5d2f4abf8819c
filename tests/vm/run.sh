#!/bin/sh
# make vmtest: stillheart's capture code against the kernel's own V4L2 test driver (vivid) in a
# QEMU guest, no hardware needed (../shared/vm-drivers.md has the background).
#   sh tests/vm/run.sh [BUILD]      BUILD holds stillheart-vmprobe (default: build)
# Downloads Debian 12's backports kernel once (pinned: SH_VM_KVER) into SH_VM_CACHE
# (/var/cache/stillheart/vm), builds a busybox initramfs with the probe, its shared libraries and
# the vivid modules, boots it under TCG and reads "VMTEST PASS/FAIL" lines off the serial console.
# Host packages: qemu-system-x86 busybox-static kmod cpio xz-utils (installed when missing).
set -eu
BUILD="${1:-build}"
CACHE="${SH_VM_CACHE:-/var/cache/stillheart/vm}"
KVER="${SH_VM_KVER:-6.12.57+deb12-amd64}"
MIRROR="${SH_VM_MIRROR:-http://deb.debian.org/debian}"
TIMEOUT="${SH_VM_TIMEOUT:-240}"
PROBE="$BUILD/stillheart-vmprobe"
[ -x "$PROBE" ] || { echo "vmtest: $PROBE missing (make $PROBE)" >&2; exit 2; }

SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
need=""
for t in qemu-system-x86_64:qemu-system-x86 busybox:busybox-static depmod:kmod cpio:cpio xz:xz-utils; do
    command -v "${t%%:*}" >/dev/null 2>&1 || [ -x "/usr/sbin/${t%%:*}" ] || need="$need ${t#*:}"
done
if [ -n "$need" ]; then
    echo "vmtest: installing$need" >&2
    $SUDO apt-get install -y -q --no-install-recommends $need >&2
fi
BUSYBOX=$(command -v busybox)
case "$(file -L "$BUSYBOX" 2>/dev/null)" in *dynamically*) echo "vmtest: $BUSYBOX is not static (busybox-static)" >&2; exit 2;; esac

# ---- the kernel (cached) ----
KDIR="$CACHE/k/$KVER"
if [ ! -f "$KDIR/boot/vmlinuz-$KVER" ]; then
    mkdir -p "$CACHE/apt/state/lists/partial" "$CACHE/apt/cache/archives/partial" "$CACHE/apt/etc" "$CACHE/deb"
    echo "deb $MIRROR bookworm-backports main" > "$CACHE/apt/etc/sources.list"
    cat > "$CACHE/apt/apt.conf" <<CONF
Dir::State "$CACHE/apt/state";
Dir::State::status "/var/lib/dpkg/status";
Dir::Cache "$CACHE/apt/cache";
Dir::Etc::SourceList "$CACHE/apt/etc/sources.list";
Dir::Etc::SourceParts "$CACHE/apt/etc";
CONF
    APT_CONFIG="$CACHE/apt/apt.conf" apt-get update -q >&2
    chmod 777 "$CACHE/deb"
    (cd "$CACHE/deb" && APT_CONFIG="$CACHE/apt/apt.conf" apt-get download -q "linux-image-$KVER" >&2)
    mkdir -p "$KDIR"
    dpkg -x "$CACHE"/deb/linux-image-"$KVER"_*.deb "$KDIR"
    depmod -b "$KDIR" "$KVER"
fi

# ---- the initramfs ----
WORK=$(mktemp -d); trap 'rm -rf "$WORK"' EXIT
R="$WORK/root"
mkdir -p "$R/bin" "$R/sbin" "$R/proc" "$R/sys" "$R/dev" "$R/tmp" "$R/mods"
cp "$BUSYBOX" "$R/bin/busybox"
for a in sh mount insmod poweroff sleep ls cat echo; do ln -s busybox "$R/bin/$a"; done
i=0
for m in $(/sbin/modprobe -d "$KDIR" -S "$KVER" --show-depends vivid | awk '$1 == "insmod" {print $2}'); do
    i=$((i + 1))
    case "$m" in
        *.xz) xz -dc "$m" > "$R/mods/$(printf %02d $i)-$(basename "${m%.xz}")" ;;
        *) cp "$m" "$R/mods/$(printf %02d $i)-$(basename "$m")" ;;
    esac
done
cp "$PROBE" "$R/bin/stillheart-vmprobe"
for lib in $(ldd "$PROBE" | awk '/=>/ {print $3} /^\t\// {print $1}'); do
    mkdir -p "$R$(dirname "$lib")"; cp -L "$lib" "$R$lib"
done
# ld.so may be asked for by its /lib64 name
mkdir -p "$R/lib64"; [ -e "$R/lib64/ld-linux-x86-64.so.2" ] || cp -L /lib64/ld-linux-x86-64.so.2 "$R/lib64/"
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
/bin/stillheart-vmprobe sets /dev/video0 /dev/video1
/bin/stillheart-vmprobe loss /dev/video0 vivid.0
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
