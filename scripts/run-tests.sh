#!/usr/bin/env bash
# Runs every test of the build with ctest; ROS logs stay in the build folder.
set -uo pipefail
BUILD=${1:-_build}
source "$(dirname "$0")/ros-env.sh" "$BUILD"
cd "$CELLSIGHT_BUILD"
ctest --output-on-failure --timeout 300
