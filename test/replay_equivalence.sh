#!/usr/bin/env bash
# Live scan (simulated cell, quick_sweep) recorded to a bag, then the bag replayed through the
# processing nodes: the replayed cloud must hold the same points within 1e-6 m.
# Usage: replay_equivalence.sh <build folder> <work folder>
set -uo pipefail
BUILD=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$BUILD"
rm -rf "$WORK" && mkdir -p "$WORK/live"
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight demo.launch out_dir:="$WORK/live" trajectory:=quick_sweep \
  calibration_dir:="$WORK/live/truth/calibration" camera_info_from_calibration:=false \
  >"$WORK/live_launch.log" 2>&1 &
LAUNCH_PID=$!
for _ in $(seq 600); do
  [ -f "$WORK/live/scan_result.json" ] && break
  kill -0 $LAUNCH_PID 2>/dev/null || break
  sleep 0.2
done
sleep 1
kill -INT $LAUNCH_PID 2>/dev/null
wait $LAUNCH_PID 2>/dev/null
[ -f "$WORK/live/scan.ply" ] || { echo "FAIL: the live scan produced no cloud (see $WORK/live_launch.log)"; exit 1; }
export ROS_MASTER_URI="http://127.0.0.1:$(free_port)"
bash "$ROOT/scripts/replay.sh" "$BUILD" "$WORK/live/raw.bag" "$WORK/replay.ply" || { echo "FAIL: replay failed"; exit 1; }
if "$BUILD/devel/lib/cellsight/cellsight_scanner_accuracy" compare --a "$WORK/live/scan.ply" --b "$WORK/replay.ply" --tolerance-m 1e-6; then
  echo "1 passed, 0 failed"
  exit 0
fi
echo "FAIL: the replayed cloud differs from the live one"
exit 1
