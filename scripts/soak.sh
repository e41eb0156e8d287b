#!/usr/bin/env bash
# make soak: the cell cycle (scan -> cloud -> clusters -> detections -> locate_objects) many times
# against one set of running nodes (the simulated cell of make demo, calibrated from its own
# captures), sampling every process's resident memory and open files after each cycle.
# Writes <out>/soak.csv, soak.json (slopes, cycle times, failures, verdict) and soak.png (RSS,
# open files and cycle time per cycle). Non-zero when a cycle fails, a process's RSS trend
# (Theil-Sen after the warm-up) is over SOAK_MAX_SLOPE_KB per cycle (default 8), it gains open
# files, or (SOAK_MAX_CYCLE_RATIO) a cycle takes longer than that many medians.
# Usage: scripts/soak.sh [cycles, default 1000] [trajectory, default quick_sweep] [build] [out]
set -euo pipefail
CYCLES=${1:-1000}
TRAJECTORY=${2:-quick_sweep}
BUILD=${3:-_build}
OUT=${4:-out/soak}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
case $CYCLES in ''|*[!0-9]*) echo "soak: cycles must be a whole number, not '$CYCLES'" >&2; exit 2 ;; esac

source scripts/ros-env.sh "$BUILD"
OUT=$(realpath -m "$OUT")
rm -rf "$OUT"
mkdir -p "$OUT/logs"
TOOLS="$CELLSIGHT_BUILD/devel/lib/cellsight"
LAUNCH_PID=""
# roslaunch ignores an INT that comes before it has set up its handlers: INT, then TERM, then KILL
# (how roslaunch ends is not a result: the kills and the wait may fail, errexit is off meanwhile)
stop_launch() {
  [ -n "$LAUNCH_PID" ] || return 0
  local errexit=$-
  set +e
  kill -INT "$LAUNCH_PID" 2>/dev/null
  for _ in $(seq 60); do kill -0 "$LAUNCH_PID" 2>/dev/null || break; sleep 0.5; done
  if kill -TERM "$LAUNCH_PID" 2>/dev/null; then
    sleep 5
    kill -KILL "$LAUNCH_PID" 2>/dev/null
  fi
  wait "$LAUNCH_PID" 2>/dev/null
  LAUNCH_PID=""
  [[ $errexit == *e* ]] && set -e
  return 0
}
cleanup() { stop_launch; }
trap cleanup EXIT

# the cell calibrates itself first, as in make demo
"$TOOLS/cellsight_simulate_captures" --scene config/scenes/demo.yaml --out "$OUT/captures" >"$OUT/logs/captures.json" 2>"$OUT/logs/captures.log" ||
  { echo "soak: FAILED to simulate the calibration captures; see $OUT/logs/captures.log" >&2; exit 1; }
bash scripts/calibrate-captures.sh "$TOOLS" "$OUT/captures" "$OUT/calibration" "$OUT/calibration_three_point" \
  >"$OUT/logs/calibration.json" 2>"$OUT/logs/calibration.log" ||
  { echo "soak: FAILED to calibrate; see $OUT/logs/calibration.log" >&2; exit 1; }

# SOAK_MMAP_THRESHOLD (bytes) fixes glibc's mmap threshold for the cell's processes: frames and
# clouds then come from mmap and go back at free, so the heap does not grow in steps of a few MB
# that a short run would read as a trend (the 50-cycle ctest sets it; make soak does not)
if [ -n "${SOAK_MMAP_THRESHOLD:-}" ]; then
  export GLIBC_TUNABLES="glibc.malloc.mmap_threshold=$SOAK_MMAP_THRESHOLD"
fi
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight demo.launch out_dir:="$OUT/cell" calibration_dir:="$OUT/calibration" \
  trajectory:=none record:=false rviz:=false >"$OUT/launch.log" 2>&1 &
LAUNCH_PID=$!
echo "soak: $CYCLES cycles of '$TRAJECTORY' on $ROS_MASTER_URI, output in $OUT"
rc=0
/usr/bin/python3 scripts/soak_driver.py --cycles "$CYCLES" --trajectory "$TRAJECTORY" --out "$OUT" \
  --max-slope-kb "${SOAK_MAX_SLOPE_KB:-8}" --max-cycle-ratio "${SOAK_MAX_CYCLE_RATIO:-0}" || rc=$?
if grep -q "has died" "$OUT/launch.log"; then
  echo "soak: FAILED: a node died; see $OUT/launch.log:" >&2
  grep "has died" "$OUT/launch.log" >&2
  rc=1
fi
stop_launch  # a node that died is caught above

if [ -s "$OUT/soak.csv" ] && command -v gnuplot >/dev/null; then
  nodes=$(cut -d, -f2 "$OUT/soak.csv" | tail -n +2 | sort -u)
  rss="" fds=""
  for n in $nodes; do
    rss+="'< grep \",$n,\" $OUT/soak.csv' using 1:(\$4/1024) with lines title '$n',"
    fds+="'< grep \",$n,\" $OUT/soak.csv' using 1:5 with lines title '$n',"
  done
  first=$(echo "$nodes" | head -1)
  gnuplot <<GP || echo "soak: warning: gnuplot could not draw $OUT/soak.png" >&2
set terminal pngcairo size 1200,1100 noenhanced
set output '$OUT/soak.png'
set datafile separator ','
set multiplot layout 3,1 title 'cellsight soak: $CYCLES cycles of $TRAJECTORY'
set key outside right
set xlabel 'cycle'
set ylabel 'RSS [MiB]'
plot ${rss%,}
set ylabel 'open files'
plot ${fds%,}
set ylabel 'cycle time [s]'
plot '< grep ",$first," $OUT/soak.csv' using 1:6 with lines title 'scan -> detections -> locate'
unset multiplot
GP
fi
exit $rc
