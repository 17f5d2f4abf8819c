#!/bin/sh
# Runs the test binaries of BUILD in lanes side by side: each of the named heavy tests in a lane
# of its own, all the others one after another in one lane; each lane is tests/run-tests.sh on a
# folder of links. Prints the lanes' output and the same summary line as run-tests.sh.
#   tools/cross/run-lanes.sh BUILD [HEAVY_TEST_NAME...]
# Under qemu-aarch64 the phantom tests take minutes each; side by side the suite takes about as
# long as the slowest of them.
set -u
build=$(cd "$1" && pwd); shift
lanes="$build/.lanes"
rm -rf "$lanes"; mkdir -p "$lanes/main/tests"
for t in "$build"/tests/test_*; do
    [ -x "$t" ] || continue
    name=$(basename "$t"); lane=main
    for h in "$@"; do [ "$h" = "$name" ] && lane=$name; done
    mkdir -p "$lanes/$lane/tests"
    ln -s "$t" "$lanes/$lane/tests/$name"
done
for d in "$lanes"/*/; do
    # test_render tests the build's own renderer, never the fixture one (qemu-wrap.sh)
    case "$d" in */test_render/) fixture= ;; *) fixture=${SH_TEST_RENDER:-} ;; esac
    # SH_TEST_EMULATED: a test may leave out repeats of what the host suite covers (test_track_cli)
    SH_TEST_EMULATED=1 SH_TEST_RENDER=$fixture sh tests/run-tests.sh "$d" > "$d/log" 2>&1 &
done
wait
passed=0; failed=0; crashed=""
for d in "$lanes"/main/ "$lanes"/*/; do
    case "$d" in "$lanes/main/") [ -n "${seen_main:-}" ] && continue; seen_main=1 ;; esac
    last=$(tail -n 1 "$d/log")
    sed '$d' "$d/log" | grep -v -e '^crashed or exited non-zero:' -e '^failed tests:'
    c=$(grep '^crashed or exited non-zero:' "$d/log" | sed 's/^crashed or exited non-zero://')
    crashed="$crashed$c"
    names="${names:-}$(sed -n 's/^failed tests://p' "$d/log")"
    p=$(printf '%s\n' "$last" | sed -n 's/^\([0-9]*\) passed, \([0-9]*\) failed$/\1/p')
    f=$(printf '%s\n' "$last" | sed -n 's/^\([0-9]*\) passed, \([0-9]*\) failed$/\2/p')
    [ -z "$p" ] && { echo "$d: no summary line"; f=1; p=0; }
    passed=$((passed + p)); failed=$((failed + f))
done
[ -n "${names:-}" ] && echo "failed tests:$names"
[ -n "$crashed" ] && echo "crashed or exited non-zero:$crashed"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
