#!/usr/bin/env bash
# A cell cycle of three passes through the ROS nodes (the demo's: demo_sweep detect,
# reverse_sweep add_detections, cross_sweep refine, one cycle id) on the simulated cell, recorded
# to a bag with its Scan goals; the same bag located in one process (cellsight_locate_bag, the
# passes split at the recorded goals) must give the live nodes' detections of the cycle: the same
# passes and roles, parts, names and models, poses within 1e-9 m; and so must the bag replayed
# through the processing nodes (replay_finisher pausing the player between the passes).
# Usage: cycle_passes.sh <build folder> <work folder>
set -uo pipefail
BUILD=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$BUILD"
source "$ROOT/test/live_cell.sh"
live_cell "$WORK" fixtures:=false || exit 1
failed=0
/usr/bin/python3 - "$WORK/live/detections_raw.json" "$WORK/live/scan_result.json" <<'PY' || failed=1
import json, sys
det, scan = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
roles = ["detect", "add_detections", "refine"]
print("live cycle %s: passes %s, %d parts; scan passes %s" % (det["cycle_id"], det["passes"], len(det["detections"]),
      [(p["trajectory"], p["frames"]) for p in scan["passes"]]))
if det["passes"] != roles or not det["cycle_id"] or det["cycle_id"] != scan["cycle_id"]:
    sys.exit("FAIL: the nodes located passes %s of cycle '%s', expected %s of '%s'" % (det["passes"], det["cycle_id"], roles, scan["cycle_id"]))
PY
"$BUILD/devel/lib/cellsight/cellsight_locate_bag" --bag "$WORK/live/raw.bag" --root "$ROOT" --json "$WORK/inprocess_detections.json" \
  >"$WORK/inprocess.log" 2>&1
echo "in-process: $(head -1 "$WORK/inprocess.log")"
if ! /usr/bin/python3 "$ROOT/test/same_detections.py" "$WORK/live/detections_raw.json" "$WORK/inprocess_detections.json" 1e-9; then
  echo "FAIL: the nodes and the in-process pipeline located the cycle's frames differently"
  failed=1
fi
export ROS_MASTER_URI="http://127.0.0.1:$(free_port)"
if bash "$ROOT/scripts/replay.sh" "$BUILD" "$WORK/live/raw.bag" "$WORK/replay.ply" "$WORK/replay_detections.json"; then
  if ! /usr/bin/python3 "$ROOT/test/same_detections.py" "$WORK/replay_detections.json" "$WORK/inprocess_detections.json" 1e-9; then
    echo "FAIL: the replayed nodes and the in-process pipeline located the cycle's frames differently"
    failed=1
  fi
else
  echo "FAIL: the replay of the cycle's bag failed"
  failed=1
fi
[ "$failed" -eq 0 ] && echo "passed" || exit 1
