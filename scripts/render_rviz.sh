#!/usr/bin/env bash
# Opens the shipped rviz/mapping.rviz headless (Xvfb, software OpenGL) while
# a simulated flight replays through the nodelets, and saves a screenshot of
# what rviz shows: the map as a user sees it. Checks that rviz loaded the
# config without an error and that the map's cells are on screen; writes a
# JUnit file to $RESULTS if set. Needs a built workspace and the demo's bag
# (scripts/run_demo.sh makes it).
# The map's cells are told apart from the local grid's cloud and the tf axes
# (also in saturated colours) by a second rviz beside the first, on a copy of
# the config with only the map's display on: what it shows is the map alone,
# and the first rviz must show it at the same pixels.
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

# The copy: the shipped config with the grid, tf and local grid displays off
# (the map's MarkerArray and the disparity image, outside the 3D view, stay
# as they are, so the window's layout and the view are the same).
map_only="${out%.png}_map_only"
/usr/bin/python3 - "$repo/rviz/mapping.rviz" "$map_only.rviz" <<'PY'
import sys, yaml
config = yaml.safe_load(open(sys.argv[1]))
manager = config["Visualization Manager"]
for display in manager["Displays"]:
    if display["Class"] not in ("rviz/MarkerArray", "rviz/Image"):
        display["Enabled"] = display["Value"] = False
manager["Global Options"]["Frame Rate"] = 5  # two software-rendered rviz on one machine
yaml.safe_dump(config, open(sys.argv[2], "w"), default_flow_style=False)
PY

# Two X servers, each on a display number that is free (Xvfb picks it).
xvfb_pids=""
trap 'kill $xvfb_pids 2>/dev/null || true' EXIT
start_xvfb() {  # sets REPLY to the new server's display
  local number_file
  number_file="$(mktemp)"
  Xvfb -displayfd 3 -screen 0 1400x900x24 -nolisten tcp 3>"$number_file" >/dev/null 2>&1 &
  xvfb_pids="$xvfb_pids $!"
  for _ in $(seq 100); do [ -s "$number_file" ] && break; sleep 0.1; done
  REPLY=":$(head -n 1 "$number_file")"
  rm -f "$number_file"
}
start_xvfb
display="$REPLY"
start_xvfb
display_map_only="$REPLY"
# The flight starts once both rviz are up (software OpenGL starts slowly) and
# subscribed: the map is published while the bag's clock runs. The nodes
# stay up after the bag for the pictures.
delay_s=15
DISPLAY="$display" LIBGL_ALWAYS_SOFTWARE=1 roslaunch -p "$ros_port" stereo_occupancy replay.launch bag:="$bag" rviz:=true \
  end_with_bag:=false delay_s:=$delay_s >"$log" 2>&1 &
launch_pid=$!
sleep 3  # the master up
DISPLAY="$display_map_only" LIBGL_ALWAYS_SOFTWARE=1 rosrun rviz rviz -d "$map_only.rviz" \
  __name:=rviz_map_only >"$map_only.log" 2>&1 &
rviz_map_only_pid=$!
duration="$(rosbag info -y -k duration "$bag" | cut -d. -f1)"
sleep $(( delay_s + duration + 6 - 3 ))  # start-up, the replay, the map's last publication
DISPLAY="$display" import -window root "$out"
DISPLAY="$display_map_only" import -window root "$map_only.png"
kill -INT $rviz_map_only_pid 2>/dev/null || true
wait $rviz_map_only_pid 2>/dev/null || true
kill -INT $launch_pid 2>/dev/null || true
wait $launch_pid 2>/dev/null || true

failure=""
fail() { failure="${failure:+$failure; }$1"; }
# rviz's own errors (a display that failed to load, a broken config) and a
# replay that did not start. (Debian's rviz asks rospack for media_export,
# which Debian does not ship, at every start: not an error of the config.)
if cat "$log" "$map_only.log" | grep -E "\[(ERROR|FATAL)\]|Failed to (load|create)" | grep -iv "dropped" >/dev/null; then
  fail "errors in the replay or rviz (see $log, $map_only.log)"
fi
# Pixels of the 3D view (right of the panels) in saturated colours, not the
# grey of rviz's background and grid: a mask of them per screenshot.
saturated() {
  convert "$1" -crop 1000x780+380+70 +repage -colorspace HSL -channel G -separate +channel -threshold 60% "$2"
}
count() { convert "$@" -format "%[fx:int(mean*w*h+0.5)]" info:; }
saturated "$map_only.png" "$map_only.mask.png"
saturated "$out" "${out%.png}.mask.png"
# The map alone: its cells (full-saturation height colours) are all the
# copy's rviz draws in saturated colours.
map_pixels="$(count "$map_only.mask.png")"
[ "$map_pixels" -ge 20000 ] || fail "only $map_pixels pixels of the map's cells: the map is not on screen"
# The shipped config shows them where they are: most of those pixels are
# saturated in its picture too (the local grid's cloud and the tf axes may
# cover a few).
shown="$(count "$map_only.mask.png" "${out%.png}.mask.png" -compose multiply -composite)"
if [ $(( 100 * shown )) -lt $(( 75 * map_pixels )) ]; then
  fail "the shipped config shows $shown of the map's $map_pixels pixels (75 % wanted)"
fi
echo "render_rviz: $out (the map's cells: $map_pixels pixels, $shown of them shown with the shipped config)${failure:+; FAILED: $failure}"
if [ "${DOCS:-0}" = 1 ]; then cp "$out" "$repo/docs/$(basename "$out")"; fi
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" rviz mapping_rviz_shows_the_map "$failure"
[ -z "$failure" ]
