#!/usr/bin/env bash
# The scanner's calibration from a folder of captures laid out as cellsight_simulate_captures
# writes it (or a real cell's, laid out alike): intrinsics, camera pose, light sheet by least
# squares into CAL/ (and the fixture camera's intrinsics and its pose by eye-to-hand
# calibration when the captures hold fixture_intrinsics/ and hand_eye/), the thesis's three-point light sheet into THREE_POINT/ if given. Each step's
# JSON goes to CAL/../logs/calibrate_<step>.json; a failing step stops with its cause.
# Usage: calibrate-captures.sh TOOLS_DIR CAPTURES CAL [THREE_POINT_DIR] [--board 9x6 --square 0.025]
set -uo pipefail
TOOLS=$1
CAP=$2
CAL=$3
shift 3
THREE=""
if [ $# -gt 0 ] && [ "${1#--}" = "$1" ]; then THREE=$1; shift; fi
BOARD=(--board 9x6 --square 0.025)
# the fixture camera's board: the same corners, 50 mm squares (FIXTURE_BOARD="--board CxR --square S" overrides)
read -r -a FIXTURE_BOARD <<<"${FIXTURE_BOARD:---board 9x6 --square 0.05}"
# the board the robot carries for the fixture camera's pose: 30 mm squares (HAND_EYE_BOARD overrides)
read -r -a HAND_EYE_BOARD <<<"${HAND_EYE_BOARD:---board 9x6 --square 0.03}"
[ $# -gt 0 ] && BOARD=("$@")
LOGS="$(dirname "$CAL")/logs"
mkdir -p "$LOGS"
step() {
  local name=$1
  shift
  if ! "$TOOLS/cellsight_calibrate" "$@" >"$LOGS/calibrate_$name.json" 2>"$LOGS/calibrate_$name.log"; then
    echo "calibration step '$name' failed: $(grep -v '^\s*$' "$LOGS/calibrate_$name.log" | tail -1)" >&2
    exit 1
  fi
}
step intrinsics intrinsics --images "$CAP/intrinsics" "${BOARD[@]}" --out "$CAL/scanner_camera.yaml"
step extrinsics extrinsics --camera "$CAL/scanner_camera.yaml" --image "$CAP/extrinsics/pattern.png" "${BOARD[@]}" \
  --taught "$CAP/extrinsics/taught.yaml" --out "$CAL/scanner_camera_pose.yaml"
step light_sheet laser --camera "$CAL/scanner_camera.yaml" --camera-pose "$CAL/scanner_camera_pose.yaml" \
  --observations "$CAP/laser/observations.yaml" --out "$CAL/laser.yaml"
# the fixture camera (QR fixtures), when the captures hold its views: intrinsics from its board
# views, its pose by eye-to-hand calibration (refined) from the board the robot carries through
# its view; the pose from the taught board on the table goes to the logs, for comparison only
if [ -d "$CAP/fixture_intrinsics" ]; then
  step fixture_intrinsics intrinsics --images "$CAP/fixture_intrinsics" "${FIXTURE_BOARD[@]}" --name fixture_camera \
    --out "$CAL/fixture_camera.yaml"
  step fixture_hand_eye hand_eye --camera "$CAL/fixture_camera.yaml" --poses "$CAP/hand_eye/flange_poses.yaml" \
    "${HAND_EYE_BOARD[@]}" --touched "$CAP/hand_eye/touched.yaml" --child fixture_camera_optical \
    --out "$CAL/fixture_camera_pose.yaml"
  step fixture_extrinsics_taught extrinsics --camera "$CAL/fixture_camera.yaml" --image "$CAP/fixture_extrinsics/pattern.png" \
    "${FIXTURE_BOARD[@]}" --taught "$CAP/fixture_extrinsics/taught.yaml" --child fixture_camera_optical \
    --out "$LOGS/fixture_camera_pose_taught.yaml"
fi
if [ -n "$THREE" ]; then
  step light_sheet_three_point laser --method three_point --camera "$CAL/scanner_camera.yaml" \
    --camera-pose "$CAL/scanner_camera_pose.yaml" --observations "$CAP/laser_three_point/observations.yaml" \
    --out "$THREE/laser.yaml"
fi
