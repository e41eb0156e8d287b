#!/usr/bin/env bash
# The second pass (cellsight_evaluate_localization cells --second-pass reverse_sweep): in tuning
# cell 3217 a standing flanged shaft shades a sphere beside it from the demo sweep's sheet (the
# scan holds no point of it), so one pass misses it; the mirrored sweep lights it and the merged
# detections hold every part of the cell with no false one. Both halves must hold: the one-pass
# run must miss (exit 4 on --limit-recall 1), or the test no longer shows what the pass adds.
# Usage: second_pass.sh <devel lib folder of cellsight> <work folder>
set -uo pipefail
BIN=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$WORK"
run() {  # run <tag> <extra args...>
  local tag=$1
  shift
  "$BIN/cellsight_evaluate_localization" cells --root "$ROOT" --seeds 3217 --out "$WORK/cells" --json "$WORK/$tag.json" \
    --limit-recall 1 "$@" >"$WORK/$tag.log" 2>&1
}
run one_pass
one=$?
run two_passes --second-pass reverse_sweep
two=$?
tail -4 "$WORK/one_pass.log"
tail -5 "$WORK/two_passes.log"
fail=0
if [ "$one" -ne 4 ]; then
  echo "FAIL: one pass was expected to miss the shaded sphere (limit exit 4), exit $one"
  fail=1
fi
if [ "$two" -ne 0 ]; then
  echo "FAIL: two passes were expected to find every part (exit 0), exit $two"
  fail=1
fi
if ! grep -q "cells: 6 found, 0 missed" "$WORK/two_passes.log" || ! grep -q ", 0 false$" "$WORK/two_passes.log"; then
  echo "FAIL: two passes: not every part found without a false detection"
  fail=1
fi
[ "$fail" -eq 0 ] && echo "PASS: the second pass finds the part the first pass's sheet could not reach"
exit "$fail"
