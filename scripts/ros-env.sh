# Sourced by the scripts: a ROS environment confined to the build folder, on a free port.
# Usage: source scripts/ros-env.sh <build folder>
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
CELLSIGHT_BUILD=$(cd "$1" && pwd)
case $- in *u*) _cs_nounset=1; set +u ;; *) _cs_nounset=0 ;; esac
# shellcheck disable=SC1091
source "$CELLSIGHT_BUILD/devel/setup.bash"
[ "$_cs_nounset" = 1 ] && set -u
export ROS_HOME="$CELLSIGHT_BUILD/ros_home"
export ROS_LOG_DIR="$ROS_HOME/log"
mkdir -p "$ROS_LOG_DIR"
free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1]); s.close()'; }
free_display() {
  local d
  for d in $(seq 90 140); do
    [ -e "/tmp/.X${d}-lock" ] || [ -e "/tmp/.X11-unix/X${d}" ] || { echo "$d"; return; }
  done
  echo 199
}
export ROS_MASTER_URI="http://127.0.0.1:$(free_port)"
export ROS_IP=127.0.0.1
