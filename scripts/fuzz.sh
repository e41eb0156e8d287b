#!/usr/bin/env bash
# Runs every libFuzzer target (test/fuzz/fuzz_*.cpp) for a bounded time, starting from its seed
# corpus test/fuzz/corpus/<target> (which holds every crash found so far as a regression input).
# Non-zero when any target crashes, hangs (> 10 s on one input), leaks or goes over its memory
# limit; the input that did it is in <build>/fuzz_artifacts/, to be added to the corpus once fixed.
# Usage: scripts/fuzz.sh [seconds per target, default 60] [build folder, default _build_san]
#        FUZZ_TARGETS="fuzz_mesh fuzz_cloud" scripts/fuzz.sh 3600     (a chosen subset)
set -euo pipefail
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
SECONDS_PER_TARGET=${1:-60}
BUILD=$(realpath -m "${2:-_build_san}")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
# shellcheck disable=SC1091
source "$ROOT/scripts/report-failure.sh"
TARGETS=${FUZZ_TARGETS:-"fuzz_mesh fuzz_cloud fuzz_yaml fuzz_ros_msgs fuzz_bridge"}
case $SECONDS_PER_TARGET in ''|*[!0-9]*) echo "fuzz: seconds per target must be a whole number, not '$SECONDS_PER_TARGET'" >&2; exit 2 ;; esac

bash "$ROOT/scripts/sanitize.sh" --configure-only "$BUILD"
# shellcheck disable=SC2086
cmake --build "$BUILD" -j"${JOBS:-2}" --target $TARGETS

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/test/fuzz/lsan.supp:print_suppressions=0}
ART="$BUILD/fuzz_artifacts"
mkdir -p "$ART"
failed=()
for t in $TARGETS; do
  work="$BUILD/fuzz_corpus/$t"   # what this machine found; the seeds stay untouched
  mkdir -p "$work"
  log="$BUILD/fuzz_$t.log"
  echo "fuzz: $t for ${SECONDS_PER_TARGET} s (log $log)"
  if "$BUILD/fuzz/$t" "$work" "$ROOT/test/fuzz/corpus/$t" -max_total_time="$SECONDS_PER_TARGET" \
      -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 -max_len=8192 -print_final_stats=1 \
      -artifact_prefix="$ART/$t-" >"$log" 2>&1; then
    runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -n1 || echo 0)
    echo "fuzz: $t ok: $runs inputs in ${SECONDS_PER_TARGET} s ($((runs / (SECONDS_PER_TARGET > 0 ? SECONDS_PER_TARGET : 1))) per second)"
  else
    echo "fuzz: $t FAILED; the input is in $ART/, the report:" >&2
    show_report "$log" "ERROR|runtime error|SUMMARY|Test unit written"
    failed+=("$t")
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: ${#failed[@]} target(s) failed: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: all targets ran clean"
