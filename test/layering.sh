#!/usr/bin/env bash
# The cell's nodes run the core, not the simulator or the evaluation: no ROS source but the
# simulator node's includes cellsight/sim or cellsight/eval, and no node binary but cell_sim links
# their libraries. And no source file in src/ is over 600 lines.
# Usage: layering.sh <devel lib folder of the package> (e.g. _build/devel/lib/cellsight)
set -uo pipefail
BIN=$1
ROOT=$(cd "$(dirname "$0")/.." && pwd)
fail=0
# the simulator node and its marker builder may include the simulator
bad=$(grep -lE '#include "cellsight/(eval|sim)/' "$ROOT"/src/ros/*.cpp "$ROOT"/src/ros/*.hpp 2>/dev/null |
  grep -vE '/src/ros/(cell_sim_node\.cpp|cell_markers\.(cpp|hpp))$')
if [ -n "$bad" ]; then
  echo "FAIL: ROS sources that include the simulator or the evaluation:"; echo "$bad"; fail=1
fi
LIBDIR=$(cd "$BIN/../.." && pwd)/lib
[ -f "$LIBDIR/libcellsight_sim.so" ] || { echo "FAIL: no $LIBDIR/libcellsight_sim.so to check the links against"; exit 1; }
nodes=(calibration_publisher camera_trigger laser_plane_tracker triangulation scanner_calibration clustering
  model_matching scan_client replay_finisher qr_frame_adjustment robot_bridge grasp_planner assembly_client
  cellsight_locate_bag)
for n in "${nodes[@]}"; do
  [ -x "$BIN/$n" ] || { echo "FAIL: node $n not built in $BIN"; fail=1; continue; }
  linked=$(readelf -d "$BIN/$n" | grep -oE 'libcellsight_(sim|eval)\.so' | sort -u | tr '\n' ' ')
  if [ -n "$linked" ]; then echo "FAIL: node $n links $linked"; fail=1; fi
done
readelf -d "$BIN/cell_sim" | grep -q 'libcellsight_sim\.so' || { echo "FAIL: the check cannot see cell_sim's link to the simulator"; fail=1; }
long=$(find "$ROOT/src" -name '*.cpp' -o -name '*.hpp' | xargs wc -l | awk '$2 != "total" && $1 > 600 {print $2 " " $1}')
if [ -n "$long" ]; then
  echo "FAIL: source files over 600 lines:"; echo "$long"; fail=1
fi
if [ $fail -eq 0 ]; then echo "1 passed, 0 failed"; else echo "0 passed, 1 failed"; fi
exit $fail
