# Sourced helpers: a private Xvfb display and an rviz screenshot of it.
# Needs scripts/ros-env.sh sourced first.
start_xvfb() {
  XVFB_DISPLAY=$(free_display)
  Xvfb ":$XVFB_DISPLAY" -screen 0 1280x1024x24 -nolisten tcp >"$ROS_LOG_DIR/xvfb.log" 2>&1 &
  XVFB_PID=$!
  export DISPLAY=":$XVFB_DISPLAY"
  for _ in $(seq 50); do xdpyinfo >/dev/null 2>&1 && return 0; sleep 0.1; done
  echo "Xvfb did not start on $DISPLAY (see $ROS_LOG_DIR/xvfb.log)" >&2
  return 1
}
# screenshot <png>: the whole virtual screen.
screenshot() { /usr/bin/import -window root "$1"; }
# image_stddev <png>: grey-level standard deviation in [0, 1].
image_stddev() { /usr/bin/convert "$1" -colorspace Gray -format '%[fx:standard_deviation]' info:; }
