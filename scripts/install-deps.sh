#!/usr/bin/env bash
# Installs every Debian package cellsight needs to build, test and run its demo.
# Idempotent: packages already present are skipped; run as root or with sudo.
set -euo pipefail
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
export DEBIAN_FRONTEND=noninteractive

PACKAGES=(
  # build tools
  build-essential cmake pkg-config ccache googletest libgtest-dev libbenchmark-dev
  # the sanitizer + fuzz build (make sanitize, make fuzz): clang with its ASan/UBSan/libFuzzer runtimes
  clang-14 libclang-rt-14-dev
  # ROS 1 (Debian's own packaging, under /usr)
  catkin catkin-lint python3-rosdep2 ros-message-generation ros-message-runtime libroscpp-dev
  libtf2-ros-dev libtf2-eigen-dev libtf2-geometry-msgs-dev ros-tf2-msgs
  libsensor-msgs-dev libgeometry-msgs-dev libvisualization-msgs-dev libstd-msgs-dev libstd-srvs-dev
  ros-std-msgs ros-std-srvs ros-geometry-msgs ros-sensor-msgs ros-visualization-msgs ros-rosgraph-msgs
  libactionlib-dev libactionlib-msgs-dev ros-actionlib-msgs python3-actionlib
  libimage-transport-dev libdiagnostic-updater-dev libdiagnostic-msgs-dev ros-diagnostic-msgs
  libnodeletlib-dev libnodeletlib-tools libnodelet-dev pluginlib-dev
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure
  librosbag-dev python3-rosbag librostest-dev python3-rostest python3-roslaunch python3-rosmaster rosout
  rosbash python3-rostopic python3-rosservice python3-rosnode python3-rosparam
  python3-rospy python3-sensor-msgs python3-geometry-msgs python3-visualization-msgs python3-tf2-ros python3-nose python3-yaml
  rviz
  # core libraries
  libeigen3-dev libopencv-dev libyaml-cpp-dev nlohmann-json3-dev libembree-dev libtbb-dev
  libqrencode-dev libzbar-dev libvisp-dev libpcl-dev libpcl-conversions-dev libopen3d-dev
  libcli11-dev gnuplot-nox libassimp-dev liborocos-kdl-dev
  # planning: the arm's URDF and kinematics, the collision map, collision checks, paths; rviz's robot
  liburdfdom-dev libkdl-parser-dev liboctomap-dev libfcl-dev libompl-dev libtrajectory-msgs-dev ros-trajectory-msgs
  python3-trajectory-msgs
  ros-robot-state-publisher
  # the learned descriptor (libtorch, CPU) and a BLAS for it
  libtorch-dev libopenblas0-pthread
  # headless rviz screenshots
  xvfb x11-utils imagemagick libgl1-mesa-dri mesa-utils
  # the two-PC test: roslaunch reaches the second "PC" by ssh
  openssh-server python3-paramiko
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing ${#missing[@]} packages: ${missing[*]}"
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
# openssh-server is only for the two-PC test (which runs its own sshd on 127.0.0.2): when this
# script installed it on a systemd machine, the system sshd it started on port 22 is stopped and
# disabled again (an sshd the machine already had is left alone)
if [[ " ${missing[*]} " == *" openssh-server "* ]] && [ -d /run/systemd/system ]; then
  $SUDO systemctl disable --now ssh.service >/dev/null 2>&1 &&
    echo "install-deps: openssh-server installed for the tests; its system service is disabled"
fi
echo "install-deps: done"
