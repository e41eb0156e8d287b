#!/usr/bin/env bash
# Live scan (simulated cell, the demo sweep: 150 frames, six parts) recorded to a bag, then the
# bag replayed through the processing nodes: the replayed cloud must hold the same points within
# 1e-6 m. And the same bag located in one process (cellsight_locate_bag, the nodes' functions
# without ROS transport) must give the live nodes' and the replayed nodes' detections: the same
# parts, names and models, poses within 1e-9 m.
# Usage: replay_equivalence.sh <build folder> <work folder>
set -uo pipefail
BUILD=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$BUILD"
source "$ROOT/test/live_cell.sh"
live_cell "$WORK" trajectory:=demo_sweep || exit 1
[ -f "$WORK/live/scan.ply" ] || { echo "FAIL: the live scan produced no cloud (see $WORK/live_launch.log)"; exit 1; }
export ROS_MASTER_URI="http://127.0.0.1:$(free_port)"
bash "$ROOT/scripts/replay.sh" "$BUILD" "$WORK/live/raw.bag" "$WORK/replay.ply" "$WORK/replay_detections.json" ||
  { echo "FAIL: replay failed"; exit 1; }
passed=0
failed=0
if "$BUILD/devel/lib/cellsight/cellsight_scanner_accuracy" compare --a "$WORK/live/scan.ply" --b "$WORK/replay.ply" --tolerance-m 1e-6; then
  passed=$((passed + 1))
else
  echo "FAIL: the replayed cloud differs from the live one"
  failed=$((failed + 1))
fi
"$BUILD/devel/lib/cellsight/cellsight_locate_bag" --bag "$WORK/live/raw.bag" --root "$ROOT" --json "$WORK/inprocess_detections.json" \
  --cloud "$WORK/inprocess.ply" >"$WORK/inprocess.log" 2>&1
echo "in-process: $(head -1 "$WORK/inprocess.log")"
for nodes in live/detections_raw.json replay_detections.json; do
  if /usr/bin/python3 "$ROOT/test/same_detections.py" "$WORK/$nodes" "$WORK/inprocess_detections.json" 1e-9; then
    passed=$((passed + 1))
  else
    echo "FAIL: the nodes ($nodes) and the in-process pipeline located the same frames differently"
    failed=$((failed + 1))
  fi
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
