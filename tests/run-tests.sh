#!/bin/sh
# Runs every cmocka test binary in the given build folders and closes with one summary line
# ("N passed, N failed") that counts test cases, not binaries. Each binary's time follows its
# output ("-- BINARY: S s").
passed=0; failed=0; crashed=""
for dir in "$@"; do
    for t in "$dir"/tests/test_*; do
        [ -x "$t" ] || continue
        echo "== $t"
        t0=$(date +%s.%N)
        out=$("$t" 2>&1); rc=$?
        printf '%s\n' "$out"
        echo "-- $t: $(echo "$t0 $(date +%s.%N)" | awk '{printf "%.1f", $2 - $1}') s"
        p=$(printf '%s\n' "$out" | sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' | tail -1)
        f=$(printf '%s\n' "$out" | sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' | tail -1)
        passed=$((passed + ${p:-0})); failed=$((failed + ${f:-0}))
        if [ "$rc" -ne 0 ] && [ -z "$f" ]; then failed=$((failed + 1)); crashed="$crashed $t"; fi
    done
done
# make vmtest's own closing line ("vmtest: N passed, N failed"), when the suite ran it
if [ -n "${VMTEST_OUT:-}" ]; then
    line=$(grep -E '^vmtest: [0-9]+ passed, [0-9]+ failed' "$VMTEST_OUT" 2>/dev/null | tail -1)
    skipped=$(grep -E '^vmtest: skipped' "$VMTEST_OUT" 2>/dev/null | tail -1)
    if [ -n "$skipped" ]; then
        echo "$skipped"   # nothing could be fetched: not a failure, and said on its own line
    elif [ -n "$line" ]; then
        p=$(echo "$line" | sed 's/^vmtest: \([0-9]*\) passed.*/\1/')
        f=$(echo "$line" | sed 's/.* \([0-9]*\) failed.*/\1/')
        passed=$((passed + p)); failed=$((failed + f))
    else
        failed=$((failed + 1)); crashed="$crashed vmtest(no summary: see $VMTEST_OUT)"
    fi
fi
# make check-arm64's closing line (the same suite on the aarch64 build under qemu-aarch64)
if [ -n "${ARM64_OUT:-}" ]; then
    line=$(grep -E '^[0-9]+ passed, [0-9]+ failed$' "$ARM64_OUT" 2>/dev/null | tail -1)
    if [ -n "$line" ]; then
        echo "arm64: $line"
        p=$(echo "$line" | sed 's/^\([0-9]*\) passed.*/\1/')
        f=$(echo "$line" | sed 's/.* \([0-9]*\) failed$/\1/')
        passed=$((passed + p)); failed=$((failed + f))
    else
        failed=$((failed + 1)); crashed="$crashed check-arm64(no summary: see $ARM64_OUT)"
    fi
fi
[ -n "$crashed" ] && echo "crashed or exited non-zero:$crashed"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
