# Sourced by replay_equivalence.sh and cycle_passes.sh: live_cell WORK [demo.launch args...] runs
# the simulated demo cell with its true calibration (out_dir WORK/live, log WORK/live_launch.log)
# until model_matching has written the detections of its cycle's last pass (detections_raw.json,
# "final"), then stops it. Returns non-zero, with the nodes' last lines, when none came.
detections_final() {
  /usr/bin/python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1])).get("final") else 1)' "$1" 2>/dev/null
}
live_cell() {
  local work=$1
  shift
  rm -rf "$work" && mkdir -p "$work/live"
  roslaunch -p "${ROS_MASTER_URI##*:}" cellsight demo.launch out_dir:="$work/live" \
    calibration_dir:="$work/live/truth/calibration" camera_info_from_calibration:=false "$@" \
    >"$work/live_launch.log" 2>&1 &
  local pid=$!
  for _ in $(seq 1500); do
    detections_final "$work/live/detections_raw.json" && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.2
  done
  sleep 1
  kill -INT "$pid" 2>/dev/null
  wait "$pid" 2>/dev/null
  if ! detections_final "$work/live/detections_raw.json"; then
    echo "FAIL: no detections of the live cell's last pass (see $work/live_launch.log):"
    grep -E "scan_client|camera_trigger|model_matching.*(ERROR|dropped)" "$work/live_launch.log" | tail -5
    return 1
  fi
}
