#!/bin/sh
# Runs every cmocka test binary in the given build folders and closes with one summary line
# ("N passed, N failed") that counts test cases, not binaries. Each binary's time follows its
# output ("-- BINARY: S s"). As many workers as folders (the plain and the ASan build: 2) take the
# binaries of all the folders from one list, interleaved, each the next one nobody has taken
# (claimed by mkdir, which is atomic), so that the one whose binaries are slower (ASan: about 480
# s against 340 on this 2-core VM, 2026-12-05) does not finish alone while the other core idles;
# the tests make their own temporary names (mkdtemp, the process id), as the aarch64 lanes
# already need. The output is printed folder by folder, in each folder's order, once all are done.
work=$(mktemp -d /tmp/sh-run-tests.XXXXXX)
trap 'rm -rf "$work"' EXIT
# the list: "FOLDER_NUMBER BINARY" lines, the folders' binaries interleaved
n=$#
d=0
for dir in "$@"; do
    d=$((d + 1))
    k=0
    for t in "$dir"/tests/test_*; do
        [ -x "$t" ] || continue
        k=$((k + 1))
        echo "$k $d $t"
    done
done | sort -n -k1,1 -k2,2 | cut -d' ' -f2- > "$work/list"
# run_item I FOLDER_NUMBER BINARY: its output in $work/I.log, its counts in $work/I.sum, the failed
# cases by name in $work/I.names
run_item() {
    t=$3
    {
        echo "== $t"
        t0=$(date +%s.%N)
        out=$("$t" 2>&1 </dev/null); rc=$?
        printf '%s\n' "$out"
        echo "-- $t: $(echo "$t0 $(date +%s.%N)" | awk '{printf "%.1f", $2 - $1}') s"
    } > "$work/$1.log" 2>&1
    p=$(printf '%s\n' "$out" | sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' | tail -1)
    f=$(printf '%s\n' "$out" | sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' | tail -1)
    c=""
    if [ "$rc" -ne 0 ] && [ -z "$f" ]; then f=1; c=" $t"; fi
    echo "${p:-0} ${f:-0}$c" > "$work/$1.sum"
    # the failed cases by name, for the closing lines (CI shows only the end of the output)
    dir=$(dirname "$(dirname "$t")")
    printf '%s\n' "$out" | sed -n "s|^\[  FAILED  \] \(test_[A-Za-z0-9_]*\)\$| $(basename "$dir")/$(basename "$t"):\1|p" | sort -u | tr -d '\n' > "$work/$1.names"
}
worker() {
    i=0
    while read -r folder t; do
        i=$((i + 1))
        mkdir "$work/claim.$i" 2>/dev/null || continue
        run_item $i "$folder" "$t"
    done < "$work/list"
}
w=0
while [ $w -lt $n ]; do
    w=$((w + 1))
    worker &
done
wait
passed=0; failed=0; crashed=""
d=0
while [ $d -lt $n ]; do
    d=$((d + 1))
    i=0
    while read -r folder t; do
        i=$((i + 1))
        [ "$folder" = $d ] || continue
        cat "$work/$i.log" 2>/dev/null
        read -r p f c < "$work/$i.sum" || { p=0; f=1; c="$t(no summary)"; }
        [ -s "$work/$i.names" ] && names="${names:-}$(cat "$work/$i.names")"
        passed=$((passed + p)); failed=$((failed + f)); [ -n "${c:-}" ] && crashed="$crashed $c"
    done < "$work/list"
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
# why they failed: cmocka's messages of the failed cases (CI shows only the end of the output, and
# the aarch64 lanes' lines are printed long before it)
if [ -n "${names:-}" ]; then
    cat "$work"/*.log ${ARM64_OUT:+"$ARM64_OUT"} 2>/dev/null | grep -E '^\[ +(ERROR|LINE) +\] --- ' | head -n 20 |
        sed 's/^/failure: /'
fi
# make check's phases (CHECK_TIMES: "NAME SECONDS" lines, the seconds since check began; this
# script's own end added), for a run whose time is near the CI's limit
if [ -n "${CHECK_TIMES:-}" ] && [ -r "$CHECK_TIMES" ]; then
    start=$(sed -n 's/^start //p' "$CHECK_TIMES")
    [ -n "$start" ] && echo "suites $(($(date +%s) - start))" >> "$CHECK_TIMES"
    echo "check phases, seconds after the start: $(grep -v '^start ' "$CHECK_TIMES" | tr '\n' ',' | sed 's/,$//; s/,/, /g')"
fi
[ -n "${names:-}" ] && echo "failed tests:$names"
[ -n "$crashed" ] && echo "crashed or exited non-zero:$crashed"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
