#!/usr/bin/env bash
# roslaunch env-loader for a second PC (<machine env-loader=...>): sets up Debian's ROS and this
# package's build on that host, then runs the command roslaunch gives. The package must be built
# at the same path there (or set CELLSIGHT_BUILD in the remote user's environment).
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# installed: <prefix>/lib/cellsight/env-loader.sh next to setup.bash two levels up; in the source
# tree: <repo>/scripts/env-loader.sh with the build in <repo>/_build
for setup in "${CELLSIGHT_BUILD:-}/devel/setup.bash" "$HERE/_build/devel/setup.bash" "$HERE/../setup.bash"; do
  if [ -f "$setup" ]; then
    # shellcheck disable=SC1090
    source "$setup"
    break
  fi
done
export ROS_HOME=${ROS_HOME:-$HOME/.ros}
# the address this PC's nodes advertise: ROS_IP from the environment, else the first address of
# this host (a name the cell PC may not resolve would break the connections)
if [ -z "${ROS_IP:-}" ] && [ -z "${ROS_HOSTNAME:-}" ]; then
  ROS_IP=$(hostname -I 2>/dev/null | cut -d' ' -f1)
  [ -n "$ROS_IP" ] && export ROS_IP
fi
exec "$@"
