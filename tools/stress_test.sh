#!/usr/bin/env bash
# Run `make test` several times in a row with CPU-bound processes beside it (issue #13: a limit or a test that
# holds only on an idle machine is not one). Called by `make test-stress`; reports pass/fail per run.
#
#   tools/stress_test.sh [RUNS] [HOGS]        defaults: 3 runs, 2 hogs
#   PYTEST_ARGS="src/hyst_driver" tools/stress_test.sh 1      one run of one package
#   STRESS_LOG_DIR=out/stress tools/stress_test.sh            keep the logs there (default: a fresh temp dir)
#
# The hogs are killed on every way out (normal end, failure, Ctrl-C, kill): trap on EXIT, INT and TERM.
# Exit status: 0 when every run passed, 1 otherwise.
set -uo pipefail
runs=${1:-3}
hogs=${2:-2}
cd "$(dirname "$0")/.."
logdir=${STRESS_LOG_DIR:-$(mktemp -d "${TMPDIR:-/tmp}/hyst_stress.XXXXXX")}
mkdir -p "$logdir"

hog_pids=()
run_pid=
stop_hogs() {
    if [ ${#hog_pids[@]} -gt 0 ]; then
        kill "${hog_pids[@]}" 2>/dev/null
        wait "${hog_pids[@]}" 2>/dev/null
        hog_pids=()
    fi
}
trap stop_hogs EXIT
# make runs in the background and is waited for, so a signal is handled at once (bash defers traps while a
# foreground child runs); the EXIT trap then stops the hogs.
trap 'echo "stress: interrupted" >&2; [ -n "$run_pid" ] && kill "$run_pid" 2>/dev/null; exit 130' INT TERM

for ((i = 0; i < hogs; i++)); do
    bash -c 'while :; do :; done' &
    hog_pids+=($!)
done
echo "stress: $runs x make test${PYTEST_ARGS:+ PYTEST_ARGS=\"$PYTEST_ARGS\"} beside $hogs CPU-bound processes" \
     "(pids ${hog_pids[*]}); logs in $logdir"

failed=0
results=()
for ((r = 1; r <= runs; r++)); do
    log="$logdir/run_$r.log"
    t0=$(date +%s)
    make -s test PYTEST_ARGS="${PYTEST_ARGS:-}" >"$log" 2>&1 &
    run_pid=$!
    wait "$run_pid"
    rc=$?
    run_pid=
    dt=$(($(date +%s) - t0))
    summary=$(grep -E '^(=+ )?[0-9]+ (passed|failed)|(passed|failed|error).* in [0-9.]+s' "$log" | tail -1)
    summary=${summary//=/}
    if [ $rc -eq 0 ]; then verdict=PASS; else verdict=FAIL; failed=$((failed + 1)); fi
    results+=("run $r/$runs: $verdict (exit $rc, ${dt} s, load $(cut -d' ' -f1 /proc/loadavg)):${summary:+ $summary}")
    echo "${results[-1]}"
    if [ $rc -ne 0 ]; then
        grep -E '^(FAILED|ERROR) ' "$log" | head -20 | sed 's/^/    /'
    fi
done
stop_hogs
echo "stress: $((runs - failed))/$runs runs passed with $hogs CPU hogs beside them"
[ $failed -eq 0 ]
