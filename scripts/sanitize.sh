#!/usr/bin/env bash
# The sanitizer build: clang with AddressSanitizer + UndefinedBehaviorSanitizer (a report stops
# the process) in its own build folder, then the core and scanner gtests under it. Non-zero on
# any failing test or sanitizer report. The same folder holds the fuzz targets (scripts/fuzz.sh).
# Usage: scripts/sanitize.sh [build folder, default _build_san]
#        scripts/sanitize.sh --configure-only [build folder]
set -euo pipefail
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
CONFIGURE_ONLY=0
if [ "${1:-}" = "--configure-only" ]; then CONFIGURE_ONLY=1; shift; fi
BUILD=$(realpath -m "${1:-_build_san}")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
# shellcheck disable=SC1091
source "$ROOT/scripts/report-failure.sh"
TESTS="test_common test_sim test_scanner test_localization test_eval test_scanner_acceptance test_ros_conversions test_fixtures test_bridge test_planning"
# Under ASan + UBSan + libFuzzer coverage, model matching runs ~50x slower: the long matching
# runs of test_localization (15 min on 2 cores; the flat-view, see-through, sheet-lit, steep-face,
# model-cache and learned-descriptor tests, 5.5 min at 1186e53, stay and cover the same matching code) and the two demo-scan
# localisation tests of test_scanner_acceptance (4 min) are left out unless SANITIZE_ALL=1. A new
# test runs unless named here.
SLOW_MATCHING="ModelMatching.FindsEach*:ModelMatching.Occlusion*:ModelMatching.Unconstrained*"
SLOW_MATCHING+=":ModelMatching.SupportPlane*:ModelMatching.FinePpf*:ModelMatching.BadInput*"
SLOW_MATCHING+=":ModelMatching.Centring*:ModelMatching.TwoTouching*:ModelMatching.NearTies*:ModelMatchingRealData.*"
SLOW_MATCHING+=":LearnedDescriptor.ClusterTooLarge*:LearnedDescriptor.GuidedSamplingFinds*"
# each 33-100 s under the sanitizers (5.5 min together at c40ee05); the light-sweep and
# incidence-weighted fitness stay covered by FitnessCountsOnlyWhatTheSheetLit and SteepFaces*
SLOW_MATCHING+=":ModelMatching.ABracketOnItsSide*:ModelMatching.APartSplit*:ModelMatching.RefineOnASecondScan"
SLOW_MATCHING+=":ModelMatching.MixedEdgePoints*:ModelMatching.SurfaceTheScan*"
# 40-100 s each under the sanitizers: the second look's shading stays covered by
# APartShadedByAFoundPartIsLookedAtAgain, the rounds of locate() by every matching test
SLOW_MATCHING+=":ModelMatching.ThreeTouching*:ModelMatching.APartShadedByAFoundPartIsFoundOn*"
# 85 s under the sanitizers (preparing four models); the merge's space test is the one
# TwoDetectionsThatWouldShareSpaceKeepTheBetterExplained covers (SANITIZE_ALL=1 runs it)
SLOW_MATCHING+=":ModelMatching.ASecondPassAddsOnlyWhatTheFirstLeftFree"
# 258 s under the sanitizers; laying a pose into its rest stays covered by
# APartLyingOnTheTableIsFoundFromItsRests and ARestPoseTiedWithTurnedOnesIsWithinTheQuota
SLOW_MATCHING+=":ModelMatching.APoseALittleTiltedFromARestIsLaidIntoIt"
# 85-140 s each beside another shard: the rests stay covered by APartLyingOnTheTableIsFoundFromItsRests,
# a split part by APartThatClusteringSplitIsPolishedOnBothPieces, the support and overhang
# refusals by AHolderFittedOntoASmallerBoxIsRefusedForItsOverhang
SLOW_MATCHING+=":ModelMatching.ARestPoseTiedWithTurnedOnes*:ModelMatching.ARefusedPieceOfASplitPart*"
SLOW_MATCHING+=":ModelMatching.AHolderSunkIntoTheTable*:ModelMatching.APartFittedOntoALargerObjectsFace*"
filter() {
  [ "${SANITIZE_ALL:-0}" = 1 ] && return 0
  case $1 in
    test_localization) echo "--gtest_filter=-$SLOW_MATCHING" ;;
    test_scanner_acceptance) echo "--gtest_filter=-ScannerAcceptance.DemoScan*" ;;
  esac
}

if [ ! -f "$BUILD/CMakeCache.txt" ]; then
  command -v clang++ >/dev/null || { echo "sanitize: clang++ is missing: run scripts/install-deps.sh" >&2; exit 2; }
  mkdir -p "$BUILD/devel/lib/python3/dist-packages"
  cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
    -DCELLSIGHT_SANITIZE=ON -DCATKIN_ENABLE_TESTING=ON >"$BUILD/configure.log" 2>&1 ||
    { tail -30 "$BUILD/configure.log" >&2; echo "sanitize: configuring $BUILD failed" >&2; exit 1; }
fi
[ "$CONFIGURE_ONLY" = 1 ] && exit 0

# shellcheck disable=SC2086
cmake --build "$BUILD" -j"${JOBS:-2}" --target $TESTS

# Eigen and Debian's PCL agree on malloc (EIGEN_MALLOC_ALREADY_ALIGNED=1, see CMakeLists.txt);
# leaks inside uninstrumented libraries are listed, with reasons, in test/fuzz/lsan.supp
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:halt_on_error=1:abort_on_error=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/test/fuzz/lsan.supp:print_suppressions=0}
# shellcheck disable=SC1091
source "$ROOT/scripts/ros-env.sh" "$BUILD"
# Each program runs as SHARDS gtest shards (default: JOBS), the shards of all programs JOBS at a
# time, so both cores stay busy through the long matching tests.
SHARDS=${SHARDS:-${JOBS:-2}}
run_shard() {  # program shard: 0 when it passed with no report
  local t=$1 i=$2 log="$BUILD/sanitize_${1}_$2.log" start
  start=$(date +%s)
  # shellcheck disable=SC2046
  if (cd "$BUILD" && GTEST_TOTAL_SHARDS=$SHARDS GTEST_SHARD_INDEX=$i \
      "devel/lib/cellsight/$t" $(filter "$t") >"$log" 2>&1); then
    echo "sanitize: $t shard $i/$SHARDS passed, 0 reports ($(grep -c '^\[       OK \]' "$log") tests, $(( $(date +%s) - start )) s)"
  else
    echo "sanitize: $t shard $i/$SHARDS FAILED ($log):" >&2
    show_report "$log" "ERROR: |runtime error|SUMMARY|\[  FAILED  \]"
    touch "$BUILD/sanitize_failed_$t"
  fi
}
export -f run_shard filter show_report
export BUILD SHARDS SLOW_MATCHING
rm -f "$BUILD"/sanitize_failed_* "$BUILD"/sanitize_test_*.log
for t in $TESTS; do for ((i = 0; i < SHARDS; i++)); do echo "$t $i"; done; done |
  xargs -P "${JOBS:-2}" -L 1 bash -c 'run_shard "$0" "$1"'
failed=()
for t in $TESTS; do [ -e "$BUILD/sanitize_failed_$t" ] && failed+=("$t"); done
if [ ${#failed[@]} -gt 0 ]; then
  echo "sanitize: ${#failed[@]} test program(s) failed: ${failed[*]}" >&2
  exit 1
fi
echo "sanitize: all ${TESTS// /, } passed under ASan + UBSan"
