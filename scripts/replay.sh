#!/usr/bin/env bash
# Replays a raw bag through the scanner's processing nodes and writes the finished cloud.
# Usage: scripts/replay.sh <build folder> <raw.bag> <out.ply>
set -euo pipefail
BUILD=$1
BAG=$(realpath "$2")
OUTPUT=$(realpath -m "$3")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
source "$ROOT/scripts/ros-env.sh" "$BUILD"
LOG=$(dirname "$OUTPUT")/replay_launch.log
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight replay.launch >"$LOG" 2>&1 &
LAUNCH_PID=$!
trap 'kill -INT $LAUNCH_PID 2>/dev/null; wait $LAUNCH_PID 2>/dev/null || true' EXIT
for _ in $(seq 100); do
  rosservice list 2>/dev/null | grep -q '^/scan/finish$' && break
  sleep 0.2
done
rosservice list | grep -q '^/scan/finish$' || { echo "replay: triangulation did not start (see $LOG)" >&2; exit 1; }
sleep 1  # subscriptions connected
frames=$(/usr/bin/python3 -c 'import rosbag,sys; b=rosbag.Bag(sys.argv[1]); print(b.get_message_count("/scanner_camera/image_raw"))' "$BAG")
rosbag play --clock --quiet --delay 2 "$BAG" --topics /scanner_camera/image_raw /scanner_camera/camera_info /tf /tf_static
rosservice call /scan/finish "{output_file: '$OUTPUT', expected_frames: $frames, wait_frames_timeout: 60.0}" \
  | tee "$OUTPUT.finish.txt" | grep -E '^(status|message|frames|points):'
grep -q '^status: 0' "$OUTPUT.finish.txt"
