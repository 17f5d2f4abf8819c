#!/bin/sh
# The include and link rules of docs/architecture.md ("What may include what"), run by make check:
#   1. the engine includes no capture, display, config, systemd or logging header;
#   2. capture includes no engine header but core's and image's (it knows no tracking);
#   3. no library module includes the programs' logging header (the library never prints), and
#      none includes the daemon's (src/daemon sits above every module, below the programs);
#   4. the daemon module includes nothing of the programs (src/app);
#   5. the daemon (BUILD/stillheart) links no OpenCV and no OSMesa.
# Each broken rule is one line naming the file (and line) and what it includes or links; the
# exit status is 1 when any rule is broken.
#   scripts/check-includes.sh [--root DIR] [--build DIR | --binary FILE | --no-link]
#   scripts/check-includes.sh --self-test    plants violations in a scratch tree, expects each caught
set -u

# The module lists are the ones docs/architecture.md states; a module folder in src/ that is in
# none of them (a new one) is reported, so that it gets a place in the doc and here.
ENGINE="core image linalg interp hull warp warp3d modelcache metrics camera calib track detect flow landmarks"
FORMATS="y4m png imageio points"
CAPTURE="source pixconv sync record"
OUTPUT="display screen kms"
DAEMON="config notify log cli daemon app"
# What the engine may not include, and what capture may not include besides.
ENGINE_DENY="$CAPTURE $OUTPUT config notify log cli daemon app"
CAPTURE_DENY="interp hull warp warp3d metrics camera calib track detect linalg $OUTPUT config notify log cli daemon app"
LIBRARY_DENY="log cli daemon app"
DAEMON_DENY="app"

root=.
build=build
binary=
link=1
self_test=0
while [ $# -gt 0 ]; do
    case "$1" in
        --root) root=$2; shift ;;
        --build) build=$2; shift ;;
        --binary) binary=$2; shift ;;
        --no-link) link=0 ;;
        --self-test) self_test=1 ;;
        *) echo "usage: $0 [--root DIR] [--build DIR | --binary FILE | --no-link] | --self-test" >&2; exit 2 ;;
    esac
    shift
done

in_list() { # in_list WORD LIST...
    w=$1; shift
    for x in "$@"; do [ "$x" = "$w" ] && return 0; done
    return 1
}

# includes FILE: "LINE MODULE HEADER" for each #include of a stillheart header or of another
# module's folder (../warp/warp_internal.h); a header of the file's own folder is its module's.
includes() {
    awk -v own="$2" '
        /^[ \t]*#[ \t]*include[ \t]*["<]/ {
            h = $0
            sub(/^[ \t]*#[ \t]*include[ \t]*["<]/, "", h)
            sub(/[">].*$/, "", h)
            m = ""
            if (h ~ /^stillheart\//) { m = h; sub(/^stillheart\//, "", m); sub(/\.h$/, "", m) }
            else if (h ~ /^\.\.\/[^\/]+\//) { m = h; sub(/^\.\.\//, "", m); sub(/\/.*$/, "", m) }
            else if (h !~ /\//) m = own
            if (m != "") print FNR, m, h
        }' "$1"
}

bad=0
violation() {
    echo "check-includes: $*"
    bad=1
}

check_tree() {
    for dir in "$root"/src/*/; do
        [ -d "$dir" ] || continue
        mod=$(basename "$dir")
        if in_list "$mod" $ENGINE; then deny="$ENGINE_DENY"; role="the engine"
        elif in_list "$mod" $CAPTURE; then deny="$CAPTURE_DENY"; role="capture"
        elif in_list "$mod" $FORMATS $OUTPUT config notify; then deny="$LIBRARY_DENY"; role="the library"
        elif [ "$mod" = daemon ]; then deny="$DAEMON_DENY"; role="the daemon"
        elif in_list "$mod" log cli app; then continue
        else violation "src/$mod/: a module in none of the lists of docs/architecture.md (and of $0)"; continue
        fi
        for f in "$dir"*.c "$dir"*.cpp "$dir"*.h "$root/include/stillheart/$mod.h"; do
            [ -f "$f" ] || continue
            rel=${f#"$root"/}
            includes "$f" "$mod" | while read -r line m h; do
                [ "$m" = "$mod" ] && continue
                if in_list "$m" $deny; then
                    echo "check-includes: $rel:$line: $role ($mod) includes $h ($m): docs/architecture.md, \"What may include what\""
                fi
            done
        done
    done > "$tmp/tree.out"
    if [ -s "$tmp/tree.out" ]; then cat "$tmp/tree.out"; bad=1; fi
}

check_link() {
    bin=${binary:-$build/stillheart}
    if [ ! -f "$bin" ]; then violation "$bin: not built (make first, or --build DIR / --no-link)"; return; fi
    if ! readelf -d "$bin" > "$tmp/dyn" 2>&1; then violation "$bin: readelf cannot read it"; return; fi
    grep 'NEEDED' "$tmp/dyn" | grep -iE 'opencv|osmesa' | sed 's/.*\[\(.*\)\]/\1/' | while read -r lib; do
        echo "check-includes: $bin links $lib: the daemon links no OpenCV or OSMesa (docs/architecture.md)"
    done > "$tmp/link.out"
    # a static copy would show as symbols instead: OpenCV's namespace, OSMesa's entry points
    nm --defined-only "$bin" 2>/dev/null | awk '{print $NF}' | grep -E '^(_ZN2cv|_ZNK2cv|OSMesa)' | head -3 | while read -r sym; do
        echo "check-includes: $bin holds $sym: the daemon links no OpenCV or OSMesa (docs/architecture.md)"
    done >> "$tmp/link.out"
    if [ -s "$tmp/link.out" ]; then cat "$tmp/link.out"; bad=1; fi
}

tmp=$(mktemp -d /tmp/sh-check-includes.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

if [ "$self_test" = 1 ]; then
    # A scratch tree: each planted include must be reported (file, line, header), the allowed
    # ones must not, and an unlisted module must be named.
    s=$tmp/scratch
    mkdir -p "$s/src/warp" "$s/src/source" "$s/src/png" "$s/src/app" "$s/src/daemon" "$s/src/newmod" "$s/include/stillheart"
    printf '#include <math.h>\n#include "stillheart/warp.h"\n#include "stillheart/display.h"\n' > "$s/src/warp/a.c"
    printf '#include "stillheart/core.h"\n#include "../source/source_internal.h"\n' > "$s/src/warp/b.c"
    printf '#include "stillheart/y4m.h"\n#include "stillheart/track.h"\n' > "$s/src/source/s.c"
    printf '#include "stillheart/image.h"\n#include <stillheart/log.h>\n' > "$s/src/png/p.c"
    printf '#include "stillheart/config.h"\n#include "stillheart/log.h"\n#include "stillheart/daemon.h"\n' > "$s/src/app/ok.c"
    printf '#include "stillheart/track.h"\n#include "stillheart/log.h"\n#include "../app/app.h"\n' > "$s/src/daemon/d.c"
    printf '#include "stillheart/daemon.h"\n' > "$s/src/warp/c.c"
    printf '#include "stillheart/image.h"\n#include "stillheart/config.h"\n' > "$s/include/stillheart/hull.h"
    mkdir -p "$s/src/hull"
    printf 'int x;\n' > "$s/src/newmod/n.c"
    out=$(sh "$0" --root "$s" --no-link); rc=$?
    want="check-includes: include/stillheart/hull.h:2: the engine (hull) includes stillheart/config.h (config)
check-includes: src/daemon/d.c:3: the daemon (daemon) includes ../app/app.h (app)
check-includes: src/newmod/: a module in none of the lists of docs/architecture.md
check-includes: src/png/p.c:2: the library (png) includes stillheart/log.h (log)
check-includes: src/source/s.c:2: capture (source) includes stillheart/track.h (track)
check-includes: src/warp/a.c:3: the engine (warp) includes stillheart/display.h (display)
check-includes: src/warp/b.c:2: the engine (warp) includes ../source/source_internal.h (source)
check-includes: src/warp/c.c:1: the engine (warp) includes stillheart/daemon.h (daemon)"
    got=$(printf '%s\n' "$out" | sed 's/: docs\/architecture.md.*//; s/ (and of .*//' | sort)
    if [ "$rc" -ne 1 ] || [ "$got" != "$want" ]; then
        echo "check-includes self-test: FAILED (rc $rc); the checker said:"; printf '%s\n' "$out"
        exit 1
    fi
    # the link rule against a program that does link them, when this build has one
    mkdir -p "$tmp/empty"
    for p in "$build/stillheart-render" "$build/stillheart-calib"; do
        [ -f "$p" ] || continue
        out=$(sh "$0" --root "$tmp/empty" --binary "$p" 2>&1 | grep -c 'links\|holds')
        if [ "$out" -lt 1 ]; then echo "check-includes self-test: FAILED: $p's OSMesa/OpenCV not seen"; exit 1; fi
    done
    echo "check-includes self-test: every planted include and link caught"
    exit 0
fi

check_tree
[ "$link" = 1 ] && check_link
[ "$bad" = 0 ] && echo "check-includes: the engine, capture and library include rules and the daemon's links hold"
exit "$bad"
