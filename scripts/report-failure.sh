# Sourced by scripts/fuzz.sh and scripts/sanitize.sh: show_report LOG PATTERN prints the lines of
# LOG matching PATTERN (at most 20) to stderr, or its last 30 lines when none match. Only ever
# called after the failure has been recorded; it never decides a result.
show_report() {
  if ! grep -E "$2" "$1" | head -20 >&2; then tail -30 "$1" >&2 || true; fi
}
