#!/bin/sh
# build/tests/test_daemon N times in a row on the host with two busy loops beside it (issue 21:
# "so does test_daemon on the host under two busy loops"), as `make test-daemon-load-loop
# [LOAD_LOOP=10]` runs it: one line per run on stdout ("run K rc=R S s: N passed HH:MM"), each
# run's whole output in build/load-loop/run-K.log. Two shells spinning at the same priority take
# as much CPU as the test's daemons on a 2-core machine, so every wait and real-time schedule in
# the test runs at about half speed. Stops at the first failing run, so the count it ends with is
# the number in a row.
n=${1:-10}
build=${BUILD:-build}
logs=$build/load-loop
mkdir -p "$logs"
[ -x "$build/tests/test_daemon" ] || { echo "daemon-load-loop: $build/tests/test_daemon missing (make tests)" >&2; exit 2; }
sh -c 'while :; do :; done' & b1=$!
sh -c 'while :; do :; done' & b2=$!
trap 'kill $b1 $b2 2>/dev/null' EXIT INT TERM
i=0
while [ "$i" -lt "$n" ]; do
    i=$((i + 1))
    s=$(date +%s)
    "$build/tests/test_daemon" > "$logs/run-$i.log" 2>&1; rc=$?
    echo "run $i rc=$rc $(( $(date +%s) - s )) s: $(grep -E '^\[  PASSED  \] [0-9]+' "$logs/run-$i.log" | tail -1 | tr -s ' ') $(date -u +%H:%M)"
    [ "$rc" -eq 0 ] || { echo "daemon-load-loop: run $i failed ($logs/run-$i.log); $((i - 1)) in a row"; exit 1; }
done
echo "daemon-load-loop: $n of $n in a row under two busy loops"
