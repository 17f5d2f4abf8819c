#!/bin/sh
# make deb-test: the packages of `make deb` installed into a fresh Debian 12 root (debootstrap
# minbase, cached as a tarball), dependencies resolved from the archive as on a real box:
# the user and its groups, the conffile, the unit accepted by systemd-analyze verify, the
# program running from the root's own libraries, the unedited service failing once (not in a
# restart loop); then the arm64 package in the same root,
# run under qemu-aarch64 against that root. Needs root (chroot) and network on the first run.
set -eu
DEB_OUT=${1:-build-deb}
CACHE=${SH_DEB_CACHE:-/var/cache/stillheart/deb-root}
MIRROR=${SH_DEB_MIRROR:-http://deb.debian.org/debian}
ver=$(dpkg-parsechangelog -S Version)
fail=0
check() { # check NAME COMMAND...: one PASS/FAIL line per check
    name=$1; shift
    if "$@" > /tmp/deb-test.$$ 2>&1; then echo "deb-test PASS $name"
    else echo "deb-test FAIL $name"; sed 's/^/    /' /tmp/deb-test.$$ | tail -20; fail=1; fi
}

[ "$(id -u)" = 0 ] || { echo "deb-test: needs root (chroot); run it as root or with sudo" >&2; exit 2; }
for a in amd64 arm64; do
    [ -f "$DEB_OUT/stillheart_${ver}_$a.deb" ] || { echo "deb-test: $DEB_OUT/stillheart_${ver}_$a.deb missing: run make deb" >&2; exit 2; }
done
command -v debootstrap >/dev/null || apt-get install -y -qq debootstrap >/dev/null

mkdir -p "$CACHE"
if [ ! -s "$CACHE/bookworm-minbase.tar" ]; then
    echo "deb-test: debootstrap --variant=minbase bookworm (once; cached in $CACHE)"
    tmp=$(mktemp -d)
    debootstrap --variant=minbase bookworm "$tmp" "$MIRROR" > "$CACHE/debootstrap.log" 2>&1 ||
        { tail -20 "$CACHE/debootstrap.log"; rm -rf "$tmp"; exit 1; }
    tar -C "$tmp" -cf "$CACHE/bookworm-minbase.tar" .
    rm -rf "$tmp"
fi

root=$(mktemp -d /tmp/deb-root.XXXXXX)
cleanup() { umount "$root/proc" 2>/dev/null || true; rm -rf "$root" /tmp/deb-test.$$; }
trap cleanup EXIT
tar -C "$root" -xf "$CACHE/bookworm-minbase.tar"
chmod 755 "$root" # the tarball's "." is debootstrap's mktemp folder (0700): "/" closed to the service's user
cp /etc/resolv.conf "$root/etc/resolv.conf"
mount -t proc proc "$root/proc"
cp "$DEB_OUT"/stillheart_"${ver}"_*.deb "$DEB_OUT"/stillheart-tools_"${ver}"_amd64.deb "$root/tmp/"
in_root() { chroot "$root" env DEBIAN_FRONTEND=noninteractive PATH=/usr/sbin:/usr/bin:/sbin:/bin "$@"; }
# The unedited package's service ends in one clear failure, not a restart loop. The root has no
# running systemd (a chroot, not a booted container), so the start is played, not made: the
# unit's own ExecStart, run as the unit's User=/Group=, must exit with one line saying "not
# configured", and with a status the unit lists in RestartPreventExitStatus= (Restart=on-failure
# would restart any other failure).
service_fails_once() { # service_fails_once UNIT RUNNER...: RUNNER runs a command as the service
    unit=$1; shift
    cmd=$(sed -n 's/^ExecStart=//p' "$unit")
    out=$("$@" $cmd 2>&1); rc=$?
    echo "exit $rc: $out"
    [ "$rc" -ne 0 ] && [ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] && echo "$out" | grep -q "not configured" ||
        { echo "want one line saying 'not configured' and a failure status"; return 1; }
    grep -qx 'Restart=on-failure' "$unit" || { echo "the unit's Restart= changed: recheck this test"; return 1; }
    sed -n 's/^RestartPreventExitStatus=//p' "$unit" | tr ' ' '\n' | grep -qx "$rc" ||
        { echo "exit $rc is not in RestartPreventExitStatus=: systemd would restart it every RestartSec"; return 1; }
}

check "apt-get update in the fresh root" in_root apt-get update -qq
check "install stillheart + stillheart-tools (amd64), deps from the archive" \
    in_root apt-get install -y -qq "/tmp/stillheart_${ver}_amd64.deb" "/tmp/stillheart-tools_${ver}_amd64.deb"
check "system user stillheart, member of video" sh -c "chroot '$root' id -nG stillheart | tr ' ' '\n' | grep -qx video"
check "no login shell for stillheart" sh -c "chroot '$root' getent passwd stillheart | grep -q nologin"
check "example config is a conffile" grep -qx /etc/stillheart/stillheart.ini "$root/var/lib/dpkg/info/stillheart.conffiles"
check "udev rules installed" test -s "$root/lib/udev/rules.d/99-stillheart.rules"
check "a man page for each program and the config file" sh -c "for p in \$(cd '$root/usr/bin' && ls stillheart*); do \
    test -s '$root/usr/share/man/man1/'\$p.1.gz || { echo \"no man page for \$p\"; exit 1; }; done; \
    test -s '$root/usr/share/man/man5/stillheart.ini.5.gz'"
check "unit not enabled by installation" sh -c "! ls '$root'/etc/systemd/system/*/stillheart.service 2>/dev/null | grep -q ."
check "stillheart --help from the root's libraries" in_root stillheart --help
check "stillheart-render --help (tools package)" in_root stillheart-render --help
# The unit against the root's own files: ExecStart exists there, User/Group resolve there.
# minbase has no init; a box runs systemd and udev (the unit orders itself after udev settle).
check "install systemd, udev, procps into the root" in_root apt-get install -y -qq systemd udev procps
check "systemd-analyze verify accepts the installed unit" \
    systemd-analyze verify --root="$root" /lib/systemd/system/stillheart.service
check "the unedited service: one line 'not configured', an exit status the unit does not restart on" \
    service_fails_once "$root/lib/systemd/system/stillheart.service" \
    chroot "$root" setpriv --reuid=stillheart --regid=video --init-groups
check "reinstall keeps the user" sh -c "chroot '$root' env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --reinstall /tmp/stillheart_${ver}_amd64.deb >/dev/null && chroot '$root' id stillheart"

# arm64 in the same root (the amd64 package removed: the two are not co-installable).
check "remove the amd64 packages" in_root apt-get remove -y -qq stillheart stillheart-tools
in_root dpkg --add-architecture arm64
check "apt-get update with arm64" in_root apt-get update -qq
check "install stillheart (arm64), deps from the archive" in_root apt-get install -y -qq "/tmp/stillheart_${ver}_arm64.deb"
check "arm64 stillheart --help under qemu-aarch64 against the root" \
    qemu-aarch64 -L "$root" "$root/usr/bin/stillheart" --help
check "arm64: system user in video" sh -c "chroot '$root' id -nG stillheart | tr ' ' '\n' | grep -qx video"

[ "$fail" = 0 ] && echo "deb-test: all checks passed" || { echo "deb-test: FAILED"; exit 1; }
