# Sourced by the self-calibrated tests: calibrate_demo_cell TOOLS ROOT WORK — simulated captures
# of the demo cell as built (cellsight_simulate_captures) calibrated as make demo does
# (scripts/calibrate-captures.sh) into WORK/calibration; prints FAIL and returns 1 on a failure.
calibrate_demo_cell() {
  local tools=$1 root=$2 work=$3
  "$tools/cellsight_simulate_captures" --scene "$root/config/scenes/demo.yaml" --out "$work/captures" >"$work/captures.json" ||
    { echo "FAIL: simulated captures"; return 1; }
  bash "$root/scripts/calibrate-captures.sh" "$tools" "$work/captures" "$work/calibration" ||
    { echo "FAIL: calibration (logs in $work/logs)"; return 1; }
}
