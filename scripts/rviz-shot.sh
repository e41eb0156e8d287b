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
# colour_pixels <png> <fx test>: how many pixels pass an ImageMagick -fx test (r, g, b in [0, 1]).
colour_pixels() { /usr/bin/convert "$1" -fx "$2" -format '%[fx:round(mean*w*h)]' info:; }
# What the cell's rviz view must show: the located parts (model_matching's markers, magenta) and
# the scan (the intensity-coloured cloud, green on the 48-grey background).
LOCATED_PART_PIXEL='r>0.45 && b>0.4 && g<0.5*min(r,b) ? 1 : 0'
SCAN_PIXEL='g>0.55 && r<0.5*g ? 1 : 0'
# rviz_drawing_problem <png>: empty when the screenshot shows located parts and the scan, else why not
rviz_drawing_problem() {
  local parts scan
  parts=$(colour_pixels "$1" "$LOCATED_PART_PIXEL")
  scan=$(colour_pixels "$1" "$SCAN_PIXEL")
  if [ "${parts:-0}" -lt 150 ]; then echo "no located part drawn ($parts magenta pixels, 150 needed)"
  elif [ "${scan:-0}" -lt 2000 ]; then echo "no scan drawn ($scan green pixels, 2000 needed)"; fi
}
