#!/usr/bin/env bash
# The self-calibrated chain's accuracy on generated cells: the demo cell as built is calibrated
# from simulated captures (cellsight_simulate_captures + cellsight_calibrate, as make demo does),
# then generated scenes are scanned in-process with that calibration and the robot's error,
# clustered, located and scored (cellsight_evaluate_localization cells).
# Usage: selfcal-accuracy.sh TOOLS_DIR WORK [--capture-seed N] [--laser-error-mm X] [cells options...]
#   --laser-error-mm X  moves the calibrated light sheet X mm along its normal before scanning
#                       (a deliberate calibration error the limits must catch)
#   cells options       e.g. --seeds 1001 --limit-rms-mm 0.1 --limit-t-mm 0.5 --json out.json
# Exit: that of `cells` (0, or 4 when a --limit-* is exceeded); 1 when a step fails.
set -euo pipefail
TOOLS=$1
WORK=$2
shift 2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
CAPTURE_SEED=1
LASER_ERROR_MM=0
CELLS_ARGS=()
while [ $# -gt 0 ]; do
  case $1 in
    --capture-seed) CAPTURE_SEED=$2; shift 2 ;;
    --laser-error-mm) LASER_ERROR_MM=$2; shift 2 ;;
    *) CELLS_ARGS+=("$1"); shift ;;
  esac
done
SCENE="$ROOT/config/scenes/demo.yaml"
rm -rf "$WORK"
mkdir -p "$WORK"
CAL="$WORK/calibration"
"$TOOLS/cellsight_simulate_captures" --scene "$SCENE" --out "$WORK/captures" --seed "$CAPTURE_SEED" >"$WORK/captures.json"
bash "$ROOT/scripts/calibrate-captures.sh" "$TOOLS" "$WORK/captures" "$CAL"
if [ "$LASER_ERROR_MM" != 0 ]; then
  # the sheet is the plane y = 0 of the laser frame: move the frame along its own y axis
  /usr/bin/python3 - "$CAL/laser.yaml" "$LASER_ERROR_MM" <<'PY'
import sys, yaml
path, mm = sys.argv[1], float(sys.argv[2])
doc = yaml.safe_load(open(path))
pose = doc["T_parent_child"] if "T_parent_child" in doc else doc["transform"]
x, y, z, w = pose["quat"]
# second column of the rotation matrix of (x, y, z, w): the laser frame's y axis in the flange frame
ny = (2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w))
pose["xyz"] = [pose["xyz"][i] + mm * 1e-3 * ny[i] for i in range(3)]
open(path, "w").write(yaml.safe_dump(doc))
print("selfcal-accuracy: light sheet moved %.3f mm along its normal" % mm)
PY
fi
exec "$TOOLS/cellsight_evaluate_localization" cells --root "$ROOT" --calibration "$CAL" --out "$WORK/cells" "${CELLS_ARGS[@]}"
