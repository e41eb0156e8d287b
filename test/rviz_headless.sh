#!/usr/bin/env bash
# Headless rviz test: the simulated cell with rviz/cell.rviz under Xvfb, a located part as
# model_matching draws it and a scan (test/rviz_scene.py); rviz must stay alive and the screenshot
# must show something (not one flat colour), the located part and the scan.
# Usage: rviz_headless.sh <devel folder> <work folder>
set -uo pipefail
DEVEL=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$DEVEL/.."
source "$ROOT/scripts/rviz-shot.sh"
rm -rf "$WORK" && mkdir -p "$WORK"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null; done
  sleep 1
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  [ -n "${XVFB_PID:-}" ] && kill "$XVFB_PID" 2>/dev/null
}
trap cleanup EXIT
start_xvfb || exit 1
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight sim.launch truth_dir:="$WORK/truth" >"$WORK/launch.log" 2>&1 &
pids+=($!)
/usr/bin/python3 "$ROOT/test/rviz_scene.py" >"$WORK/scene.log" 2>&1 &
pids+=($!)
rviz -d "$ROOT/rviz/cell.rviz" >"$WORK/rviz.log" 2>&1 &
RVIZ=$!
pids+=($RVIZ)
sleep 15
kill -0 "$RVIZ" 2>/dev/null || { echo "FAIL: rviz died: $(tail -2 "$WORK/rviz.log")"; exit 1; }
screenshot "$WORK/rviz.png" || { echo "FAIL: screenshot failed"; exit 1; }
sd=$(image_stddev "$WORK/rviz.png")
colours=$(/usr/bin/convert "$WORK/rviz.png" -format '%k' info:)
problem=$(rviz_drawing_problem "$WORK/rviz.png")
echo "rviz screenshot: $WORK/rviz.png, grey stddev $sd, $colours colours${problem:+; $problem}"
if awk -v s="$sd" -v c="$colours" 'BEGIN { exit !(s > 0.05 && c > 100) }' && [ -z "$problem" ]; then
  echo "1 passed, 0 failed"
  exit 0
fi
echo "FAIL: the rviz screenshot looks blank or lacks the located part or the scan"
exit 1
