#!/bin/sh
# Without binfmt_misc, an aarch64 program cannot be exec'd on this host, and the tests exec the
# build's own programs (system(): the host's /bin/sh runs them). So every aarch64 program of the
# build folder (stillheart*, tests/test_*, and the helpers tests run: tools/eval/table2-plot)
# moves to BUILD/.qemu/ and leaves in its place a script that runs it under qemu-aarch64, with
# argv[0] kept (tests find their siblings by it).
#   tools/cross/qemu-wrap.sh BUILD
# Idempotent: a relinked program (an ELF again) is moved anew; wrappers are rewritten.
set -eu
build=$(cd "$1" && pwd)
qemu=${QEMU_AARCH64:-qemu-aarch64}
for f in "$build"/stillheart* "$build"/tests/test_* "$build"/tools/eval/table2-plot; do
    [ -f "$f" ] || continue
    case "$f" in *.a|*.o|*.d) continue ;; esac
    rel=${f#"$build"/}
    if [ "$(head -c 4 "$f" | od -An -c | tr -d ' ')" = '177ELF' ]; then
        mkdir -p "$build/.qemu/$(dirname "$rel")"
        mv -f "$f" "$build/.qemu/$rel"
    fi
    [ -f "$build/.qemu/$rel" ] || continue
    # argv[0]: the wrapper's own path, links resolved (tools/cross/run-lanes.sh runs links).
    # The phantom renderer makes the other tests' fixtures: with SH_TEST_RENDER set (to the host
    # build's renderer, tools/cross/run-lanes.sh) they come from it, 25x faster than OSMesa under
    # emulation; test_render's lane leaves it unset and tests the aarch64 renderer itself.
    fixture=""
    [ "$rel" = stillheart-render ] && fixture='[ -n "${SH_TEST_RENDER:-}" ] && exec "$SH_TEST_RENDER" "$@"\n'
    printf "#!/bin/sh\n$fixture"'exec %s -L "${QEMU_LD_PREFIX:-/}" -0 "$(readlink -f "$0")" "%s" "$@"\n' \
        "$qemu" "$build/.qemu/$rel" > "$f"
    chmod 0755 "$f"
done
