#!/usr/bin/env bash
# Opens the shipped rviz/mapping.rviz headless (Xvfb, software OpenGL) while
# a simulated flight replays through the nodelets, and saves a screenshot of
# what rviz shows: the map as a user sees it. Checks that rviz loaded the
# config without an error and that the map's cells are on screen; writes a
# JUnit file to $RESULTS if set. Needs a built workspace and the demo's bag
# (scripts/run_demo.sh makes it).
#   BAG=build/demo/posts_seed1.bag   OUT=build/demo/rviz_posts.png   DOCS=1: also docs/rviz_posts.png
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
bag="${BAG:-$repo/build/demo/posts_seed1.bag}"
out="${OUT:-$repo/build/demo/rviz_posts.png}"
export PATH="/usr/bin:$PATH"
# A roscore of its own, never the default port another program may hold.
ros_port="${ROS_PORT:-11393}"
export ROS_MASTER_URI="http://localhost:$ros_port"
[ -f "$bag" ] || { echo "render_rviz: no bag at $bag (run scripts/run_demo.sh first)"; exit 1; }
bag="$(realpath "$bag")"  # roslaunch's nodes run in ~/.ros
mkdir -p "$(dirname "$out")"
log="${out%.png}.log"
set +u
# shellcheck disable=SC1091
source "$ws/devel/setup.bash"
set -u

display=":$(( 90 + RANDOM % 9 ))"
Xvfb "$display" -screen 0 1400x900x24 -nolisten tcp >/dev/null 2>&1 &
xvfb_pid=$!
trap 'kill $xvfb_pid 2>/dev/null || true' EXIT
sleep 1
# The flight starts once rviz is up (software OpenGL starts slowly) and
# subscribed: the map is published while the bag's clock runs. The nodes
# stay up after the bag for the picture.
delay_s=10
DISPLAY="$display" LIBGL_ALWAYS_SOFTWARE=1 roslaunch -p "$ros_port" stereo_occupancy replay.launch bag:="$bag" rviz:=true \
  end_with_bag:=false delay_s:=$delay_s >"$log" 2>&1 &
launch_pid=$!
duration="$(rosbag info -y -k duration "$bag" | cut -d. -f1)"
sleep $(( delay_s + duration + 6 ))  # start-up, the replay, the map's last publication
DISPLAY="$display" import -window root "$out"
kill -INT $launch_pid 2>/dev/null || true
wait $launch_pid 2>/dev/null || true

failure=""
# rviz's own errors (a display that failed to load, a broken config) and a
# replay that did not start. (Debian's rviz asks rospack for media_export,
# which Debian does not ship, at every start: not an error of the config.)
if grep -E "\[(ERROR|FATAL)\]|Failed to (load|create)" "$log" | grep -iv "dropped" >/dev/null; then
  failure="errors in the replay or rviz (see $log)"
fi
# The map on screen: pixels of the 3D view (right of the panels) in the
# height colours' hues, not the grey of rviz's background and grid.
coloured="$(convert "$out" -crop 1000x780+380+70 -colorspace HSL -channel G -separate -threshold 60% \
  -format "%[fx:int(mean*w*h)]" info:)"
[ "$coloured" -gt 2000 ] || failure="$failure; only $coloured coloured pixels: the map is not on screen"
echo "render_rviz: $out ($coloured coloured pixels)${failure:+; FAILED: $failure}"
if [ "${DOCS:-0}" = 1 ]; then cp "$out" "$repo/docs/$(basename "$out")"; fi
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" rviz mapping_rviz_shows_the_map "$failure"
[ -z "$failure" ]
