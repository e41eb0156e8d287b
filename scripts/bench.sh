#!/usr/bin/env bash
# Runs the benchmarks, one core each; results (JSON) land in <build>/bench/.
set -euo pipefail
BUILD=${1:-_build}
source "$(dirname "$0")/ros-env.sh" "$BUILD"
mkdir -p "$CELLSIGHT_BUILD/bench"
echo "== bench_render: simulated scanner camera (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_render" --benchmark_repetitions=3 \
  --benchmark_report_aggregates_only=true \
  --benchmark_out="$CELLSIGHT_BUILD/bench/render.json" --benchmark_out_format=json
echo "== bench_scanner: line extraction + triangulation per frame (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_scanner" --benchmark_repetitions=3 \
  --benchmark_report_aggregates_only=true \
  --benchmark_out="$CELLSIGHT_BUILD/bench/scanner.json" --benchmark_out_format=json
echo "== bench_mesh: own PLY/STL readers vs assimp on the same files (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_mesh" --benchmark_repetitions=3 \
  --benchmark_report_aggregates_only=true \
  --benchmark_out="$CELLSIGHT_BUILD/bench/mesh.json" --benchmark_out_format=json
echo "== bench_fixtures: QR decoding + poses of one fixture-camera frame vs zbar and wechat_qrcode alone (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_fixtures" --benchmark_repetitions=3 \
  --benchmark_report_aggregates_only=true \
  --benchmark_out="$CELLSIGHT_BUILD/bench/fixtures.json" --benchmark_out_format=json
echo "== bench_localization: ours vs PCL, Open3D, OpenCV on the same single-view clouds (one thread each)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_localization" "$CELLSIGHT_BUILD/bench/localization.json" 8
echo "== bench_descriptor: the learned descriptor's inference vs FPFH on the same clusters (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_descriptor" --benchmark_repetitions=3 \
  --benchmark_report_aggregates_only=true \
  --benchmark_out="$CELLSIGHT_BUILD/bench/descriptor.json" --benchmark_out_format=json
echo "== bench_planning: the demo assembly in 20 scenarios, ours vs OMPL RRTConnect / RRT unsimplified and straight joint moves (one core)"
taskset -c 0 "$CELLSIGHT_BUILD/devel/lib/cellsight/bench_planning" "$CELLSIGHT_BUILD/bench/planning.json" 20
