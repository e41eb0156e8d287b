#!/usr/bin/env bash
# `rosdep check` for this package on Debian 12, offline: the rules come from rosdep/debian12.yaml
# (every key package.xml names → Debian packages) and an empty local rosdistro index, so nothing
# is fetched. Exit 0 when every key resolves and its packages are installed.
# Usage: scripts/rosdep-check.sh [work folder]
set -euo pipefail
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK=$(realpath -m "${1:-$(mktemp -d)}")
mkdir -p "$WORK/sources" "$WORK/home" "$WORK/index/cellsight"
cat >"$WORK/index/index-v4.yaml" <<YAML
%YAML 1.1
---
distributions:
  cellsight:
    distribution: [cellsight/distribution.yaml]
    distribution_status: active
    distribution_type: ros1
    python_version: 3
type: index
version: 4
YAML
cat >"$WORK/index/cellsight/distribution.yaml" <<YAML
%YAML 1.1
---
release_platforms:
  debian: [bookworm]
repositories: {}
type: distribution
version: 2
YAML
echo "yaml file://$ROOT/rosdep/debian12.yaml" >"$WORK/sources/10-cellsight.list"
export ROSDISTRO_INDEX_URL="file://$WORK/index/index-v4.yaml" ROSDEP_SOURCE_PATH="$WORK/sources" ROS_HOME="$WORK/home"
rosdep update --rosdistro cellsight >"$WORK/update.log" 2>&1 || { cat "$WORK/update.log" >&2; exit 1; }
rosdep check --from-paths "$ROOT" --ignore-src --rosdistro cellsight --os debian:bookworm
