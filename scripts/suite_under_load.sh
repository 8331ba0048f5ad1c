#!/usr/bin/env bash
# The whole suite N times in a row under a background load of K busy processes (issue 24:
# no flaky timing asserts). Stops at the first failing run; prints one line per run and a
# closing "N passed, N failed" line. Usage: scripts/suite_under_load.sh [RUNS [BUSY]]
#   (make test-under-load; defaults: 5 runs, 2 busy processes, one per core here).
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
RUNS="${1:-5}"
BUSY="${2:-2}"
pids=()
cleanup() { [ ${#pids[@]} -gt 0 ] && kill "${pids[@]}" 2>/dev/null; }
trap cleanup EXIT
for _ in $(seq "$BUSY"); do
  python3 -c 'while True: pass' &
  pids+=($!)
done
passed=0
failed=0
for i in $(seq "$RUNS"); do
  log="out/suite_under_load_$i.log"
  mkdir -p out
  start=$SECONDS
  if make test > "$log" 2>&1; then
    passed=$((passed + 1))
    echo "run $i: passed in $((SECONDS - start)) s ($(tail -n 1 "$log"))"
  else
    failed=$((failed + 1))
    echo "run $i: FAILED in $((SECONDS - start)) s, see $log:"
    grep -E '^(FAILED|ERROR)' "$log" | head -20
    break
  fi
done
echo "suite under load ($BUSY busy processes): $passed passed, $failed failed"
[ "$failed" -eq 0 ]
