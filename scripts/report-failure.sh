# Sourced by scripts/fuzz.sh and scripts/sanitize.sh: show_report LOG PATTERN prints the lines of
# LOG matching PATTERN (at most 20) to stderr, or its last 30 lines when none match. Only ever
# called after the failure has been recorded; it never decides a result.
show_report() {
  if [ ! -r "$1" ]; then
    echo "report: cannot read $1" >&2
  elif grep -qE "$2" "$1"; then
    grep -E -m 20 "$2" "$1" >&2
  else
    tail -n 30 "$1" >&2
  fi
}
