#!/usr/bin/env bash
# Replays a raw bag through the scanner's processing nodes (replay.launch) and writes the
# finished cloud; with a fourth argument, waits for model_matching's detections of it and
# writes them there. Usage: scripts/replay.sh <build folder> <raw.bag> <out.ply> [detections.json]
set -euo pipefail
BUILD=$1
BAG=$(realpath "$2")
OUTPUT=$(realpath -m "$3")
DETECTIONS=${4:+$(realpath -m "$4")}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$BUILD"
LOG="$OUTPUT.launch.log"
rm -f "$OUTPUT" ${DETECTIONS:+"$DETECTIONS"}
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight replay.launch bag:="$BAG" output_file:="$OUTPUT" \
  detections_file:="${DETECTIONS:-}" >"$LOG" 2>&1 &
LAUNCH_PID=$!
# on exit roslaunch is stopped (it may be gone already: how it ends is not the result) and the
# script leaves with its own status; the result is the finisher's clean exit within 300 s and the
# cloud it wrote, both checked below
stop_launch() {
  local rc=$?
  set +e
  kill -INT "$LAUNCH_PID" 2>/dev/null
  wait "$LAUNCH_PID" 2>/dev/null
  exit "$rc"
}
trap stop_launch EXIT
finished=0
for _ in $(seq 1200); do
  if grep -q "replay_finisher-[0-9]*\] process has finished cleanly" "$LOG"; then
    finished=1
    break
  fi
  if grep -qE "replay_finisher.*has died|replay_finisher: " "$LOG" && grep -q "\[ERROR\].*replay_finisher" "$LOG"; then
    echo "replay: failed, see $LOG" >&2
    grep "replay_finisher" "$LOG" | tail -3 >&2
    # what the processing nodes said about dropped frames (missing tf, camera_info, ...)
    grep -E "\[ (WARN|ERROR)\]" "$LOG" | grep -v "replay_finisher" | tail -8 | sed 's/^/replay: node: /' >&2
    exit 1
  fi
  kill -0 $LAUNCH_PID 2>/dev/null || { echo "replay: roslaunch ended early, see $LOG" >&2; exit 1; }
  sleep 0.25
done
[ "$finished" = 1 ] || { echo "replay: the replay did not finish within 300 s, see $LOG" >&2; exit 1; }
[ -f "$OUTPUT" ] || { echo "replay: no cloud written, see $LOG" >&2; exit 1; }
grep "replay_finisher: scan of" "$LOG" | sed 's/.*replay_finisher: /replay: /'
if [ -n "$DETECTIONS" ]; then
  # the finished scan goes on through clustering and model_matching
  # (after the last pass of a cycle: the file is rewritten after every pass)
  final() { /usr/bin/python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1])).get("final") else 1)' "$DETECTIONS" 2>/dev/null; }
  for _ in $(seq 480); do
    final && break
    kill -0 $LAUNCH_PID 2>/dev/null || break
    sleep 0.25
  done
  final || { echo "replay: model_matching wrote no detections of the bag's last pass within 120 s, see $LOG" >&2; exit 1; }
  grep "model_matching: .* parts located" "$LOG" | tail -1 | sed 's/.*model_matching: /replay: /'
fi
