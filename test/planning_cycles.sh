#!/usr/bin/env bash
# Issue 17 on the demo scene, in-process (cellsight_plan cycles): the cell calibrated as a user's
# would be (simulated captures -> calibrate-captures.sh), then full cycles (scan, locate, plan,
# execute with the robot as built) with fresh noise each:
#   1. the chain itself: planned on the true poses and executed by an exact robot, every part must
#      end on its target (< 0.001 mm) — a wrong grasp, target or execution shows here;
#   2. the system, self-calibrated, scanning as the cycle does (demo_sweep to find the parts,
#      cross_sweep to refine them): every part planned and placed, median planning time per part
#      <= 100 ms (one core), and the placement scatter within the issue's 0.2 mm / 0.1 deg
#      (docs/planning.md has the 40-cycle figure).
# Usage: planning_cycles.sh TOOLS_DIR WORK
set -uo pipefail
TOOLS=$1
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$WORK"
mkdir -p "$WORK"
# shellcheck source=test/calibrated_demo_cell.sh
source "$ROOT/test/calibrated_demo_cell.sh"
calibrate_demo_cell "$TOOLS" "$ROOT" "$WORK" || exit 1
taskset -c 0 "$TOOLS/cellsight_plan" cycles --root "$ROOT" --cycles 3 --true-poses --exact-robot \
  --calibration "$WORK/calibration" --limit-max-mm 0.001 --limit-success 1 --json "$WORK/chain.json" ||
  { echo "FAIL: the planning chain on true poses with an exact robot (see $WORK/chain.json)"; exit 1; }
taskset -c 0 "$TOOLS/cellsight_plan" cycles --root "$ROOT" --cycles 8 --calibration "$WORK/calibration" \
  --refine-trajectory cross_sweep --limit-success 1 --limit-median-plan-ms 100 --limit-sigma-mm 0.2 --limit-sigma-deg 0.1 --json "$WORK/cycles.json" \
  --dump-scans "$WORK" ||
  { echo "FAIL: self-calibrated cycles (see $WORK/cycles.json)"; exit 1; }
# the error budget's localisation rows: every located model's scatter, and the scans it came from
python3 - "$WORK/cycles.json" <<'PY' || exit 1
import json, sys
parts = json.load(open(sys.argv[1]))["parts"]
missing = [m for m in ("bracket", "housing", "flanged_shaft", "blade", "holder") if len(parts.get(m, {}).get("locate_sigma_mm", [])) != 3]
if missing:
    sys.exit("FAIL: no localisation sigma for " + ", ".join(missing))
PY
for s in 1 8; do [ -s "$WORK/scan_$s.ply" ] || { echo "FAIL: --dump-scans wrote no scan_$s.ply"; exit 1; }; done
echo "PASS"
