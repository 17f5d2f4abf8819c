#!/bin/sh
# Runs every cmocka test binary in the given build folders and closes with one summary line
# ("N passed, N failed") that counts test cases, not binaries. Each binary's time follows its
# output ("-- BINARY: S s"). The folders run side by side (the plain and the ASan build: each
# runs its binaries one after another, so on 2 cores the two together take about as long as the
# ASan one); their output is printed folder by folder once all are done.
work=$(mktemp -d /tmp/sh-run-tests.XXXXXX)
trap 'rm -rf "$work"' EXIT
# run_folder DIR N: DIR's binaries one after another, output in $work/N.log, counts in $work/N.sum
run_folder() {
    p_sum=0; f_sum=0; c_list=""
    for t in "$1"/tests/test_*; do
        [ -x "$t" ] || continue
        echo "== $t"
        t0=$(date +%s.%N)
        out=$("$t" 2>&1); rc=$?
        printf '%s\n' "$out"
        echo "-- $t: $(echo "$t0 $(date +%s.%N)" | awk '{printf "%.1f", $2 - $1}') s"
        p=$(printf '%s\n' "$out" | sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' | tail -1)
        f=$(printf '%s\n' "$out" | sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' | tail -1)
        p_sum=$((p_sum + ${p:-0})); f_sum=$((f_sum + ${f:-0}))
        if [ "$rc" -ne 0 ] && [ -z "$f" ]; then f_sum=$((f_sum + 1)); c_list="$c_list $t"; fi
        # the failed cases by name, for the closing lines (CI shows only the end of the output)
        printf '%s\n' "$out" | sed -n "s|^\[  FAILED  \] \(test_[A-Za-z0-9_]*\)\$| $(basename "$1")/$(basename "$t"):\1|p" | sort -u | tr -d '\n' >> "$work/$2.names"
    done > "$work/$2.log" 2>&1
    echo "$p_sum $f_sum$c_list" > "$work/$2.sum"
}
n=0
for dir in "$@"; do
    n=$((n + 1))
    run_folder "$dir" $n &
done
wait
passed=0; failed=0; crashed=""
i=0
while [ $i -lt $n ]; do
    i=$((i + 1))
    cat "$work/$i.log"
    read -r p f c < "$work/$i.sum" || { p=0; f=1; c="(folder $i: no summary)"; }
    [ -s "$work/$i.names" ] && names="${names:-}$(cat "$work/$i.names")"
    passed=$((passed + p)); failed=$((failed + f)); [ -n "${c:-}" ] && crashed="$crashed $c"
done
# make vmtest's closing lines ("vmtest: N passed, N failed": the capture guest's and the
# display guest's, tests/vm/run.sh and show.sh), added up, when the suite ran it
if [ -n "${VMTEST_OUT:-}" ]; then
    lines=$(grep -E '^vmtest: [0-9]+ passed, [0-9]+ failed' "$VMTEST_OUT" 2>/dev/null || true)
    skipped=$(grep -E '^vmtest: skipped' "$VMTEST_OUT" 2>/dev/null | tail -1)
    if [ -n "$skipped" ]; then
        echo "$skipped"   # nothing could be fetched: not a failure, and said on its own line
    fi
    if [ -n "$lines" ]; then
        for line in $(echo "$lines" | sed 's/^vmtest: \([0-9]*\) passed, \([0-9]*\) failed.*/\1:\2/'); do
            passed=$((passed + ${line%%:*})); failed=$((failed + ${line#*:}))
        done
    elif [ -n "$skipped" ]; then
        :
    else
        failed=$((failed + 1)); crashed="$crashed vmtest(no summary: see $VMTEST_OUT)"
    fi
fi
# make fuzz-check's closing line ("fuzz: N passed, N failed": harnesses that ran without a crash)
if [ -n "${FUZZ_OUT:-}" ]; then
    line=$(grep -E '^fuzz: [0-9]+ passed, [0-9]+ failed' "$FUZZ_OUT" 2>/dev/null | tail -1)
    if [ -n "$line" ]; then
        p=$(echo "$line" | sed 's/^fuzz: \([0-9]*\) passed.*/\1/')
        f=$(echo "$line" | sed 's/.* \([0-9]*\) failed$/\1/')
        passed=$((passed + p)); failed=$((failed + f))
    else
        failed=$((failed + 1)); crashed="$crashed fuzz-check(no summary, the harnesses did not build: see $FUZZ_OUT)"
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
# the aarch64 lanes' failed cases by name (tools/cross/run-lanes.sh prints the same line)
if [ -n "${ARM64_OUT:-}" ]; then
    a=$(sed -n 's/^failed tests://p' "$ARM64_OUT" 2>/dev/null | tr -d '\n')
    [ -n "$a" ] && names="${names:-}$(echo "$a" | sed 's| | arm64:|g')"
fi
[ -n "${names:-}" ] && echo "failed tests:$names"
[ -n "$crashed" ] && echo "crashed or exited non-zero:$crashed"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
