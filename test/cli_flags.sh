#!/usr/bin/env bash
# Every command-line tool: --help succeeds, and an unknown or misspelt option is refused with a
# message naming it and a non-zero exit. Usage: cli_flags.sh <devel lib folder of cellsight>
set -uo pipefail
BIN=$1
failed=0
passed=0
check() {  # check <description> <expect rc 0|nonzero> <must contain (or "")> <command...>
  local what=$1 expect=$2 needle=$3
  shift 3
  local out rc
  out=$("$@" 2>&1)
  rc=$?
  if { [ "$expect" = 0 ] && [ $rc -ne 0 ]; } || { [ "$expect" != 0 ] && [ $rc -eq 0 ]; } ||
     { [ -n "$needle" ] && ! grep -qF -- "$needle" <<<"$out"; }; then
    echo "FAIL: $what (exit $rc): $(head -2 <<<"$out")"
    failed=$((failed + 1))
  else
    passed=$((passed + 1))
  fi
}
tools=("$BIN"/cellsight_*)
[ -x "${tools[0]}" ] || { echo "FAIL: no tools in $BIN"; exit 1; }
for t in "${tools[@]}"; do
  n=$(basename "$t")
  check "$n --help" 0 "Usage:" "$t" --help
  check "$n --no-such-flag" 1 "--no-such-flag" "$t" --no-such-flag
done
# subcommands: help of each, a misspelt option, a value with units
check "calibrate intrinsics --help" 0 "--square" "$BIN/cellsight_calibrate" intrinsics --help
check "calibrate --sqaure" 1 "--sqaure" "$BIN/cellsight_calibrate" intrinsics --images /tmp --board 9x6 --sqaure 0.025 --out /tmp/x.yaml
check "calibrate --square 25mm" 1 "--square" "$BIN/cellsight_calibrate" intrinsics --images /tmp --board 9x6 --square 25mm --out /tmp/x.yaml
check "calibrate unknown subcommand" 1 "intrinsic" "$BIN/cellsight_calibrate" intrinsic
check "evaluate_localization occlusion --help" 0 "--trials" "$BIN/cellsight_evaluate_localization" occlusion --help
check "scanner_accuracy sim --help" 0 "--scene" "$BIN/cellsight_scanner_accuracy" sim --help
check "plan cycles --help" 0 "--limit-sigma-mm" "$BIN/cellsight_plan" cycles --help
check "plan cycles --cycels" 1 "--cycels" "$BIN/cellsight_plan" cycles --cycels 3
check "plan cycles --cycles 0" 1 "--cycles" "$BIN/cellsight_plan" cycles --cycles 0
check "train_descriptor --dims 8" 1 "--dims" "$BIN/cellsight_train_descriptor" --dims 8 --steps 1
check "train_descriptor --rotation spin" 1 "--rotation" "$BIN/cellsight_train_descriptor" --rotation spin --steps 1
check "train_descriptor --mesh missing" 1 "cannot open" "$BIN/cellsight_train_descriptor" --mesh /nonexistent.ply --steps 1 --generated 0 --output /tmp/cs_cli_flags.pt --quiet
check "evaluate_localization descriptors --help" 0 "--limit-beats-fpfh" "$BIN/cellsight_evaluate_localization" descriptors --help
check "evaluate_localization descriptors missing model" 1 "cannot be opened" "$BIN/cellsight_evaluate_localization" descriptors --learned /nonexistent.pt --views 1 --no-real
# validate_config: a bad file is reported as ERROR only, never "ok" first
BAD=$(mktemp -d)
printf 'outlier_k: -5\n' >"$BAD/scanner.yaml"
out=$("$BIN/cellsight_validate_config" "$BAD/scanner.yaml" 2>&1)
if [ $? -ne 0 ] && grep -q "^ERROR .*outlier_k" <<<"$out" && ! grep -q "^ok" <<<"$out"; then
  passed=$((passed + 1))
else
  echo "FAIL: validate_config on a bad file: $out"
  failed=$((failed + 1))
fi
rm -rf "$BAD"
echo "$passed passed, $failed failed"
[ $failed -eq 0 ]
