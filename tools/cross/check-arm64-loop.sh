#!/bin/sh
# make check-arm64 N times in a row (issue 21: "ten times in a row on this 2-core machine"), as
# `make check-arm64-loop [ARM64_LOOP=10]` runs it: one line per run on stdout ("run K rc=R S s:
# N passed, N failed HH:MM"), each run's whole output in build-arm64/loop/run-K.log. Stops at the
# first failing run, so the count it ends with is the number in a row. Run it with nothing else
# on the machine: the issue's question is whether the suite holds on a quiet box, and other
# jobs' load (or their tests sharing /tmp and /dev/shm) is a different question. Each run builds
# from the tree it is started in: run it in a worktree at a fixed commit (git worktree add
# ../loop HEAD) when you go on editing, or a later run tests your edits, not the commit.
n=${1:-10}
logs=build-arm64/loop
mkdir -p "$logs"
i=0
while [ "$i" -lt "$n" ]; do
    i=$((i + 1))
    s=$(date +%s)
    make --no-print-directory check-arm64 > "$logs/run-$i.log" 2>&1; rc=$?
    echo "run $i rc=$rc $(( $(date +%s) - s )) s: $(grep -E '^[0-9]+ passed, [0-9]+ failed' "$logs/run-$i.log" | tail -1) $(date -u +%H:%M)"
    [ "$rc" -eq 0 ] || { echo "check-arm64-loop: run $i failed ($logs/run-$i.log); $((i - 1)) in a row"; exit 1; }
done
echo "check-arm64-loop: $n of $n in a row"
