#!/usr/bin/env bash
# Load test of the two nodelets in one manager (issue: reliability under load):
# starts a roscore and launch/mapping.launch, drives them with load_test at
# 640x480 / 60 Hz, 1280x960 / 30 Hz and, as an overload, 1920x1200 / 60 Hz
# for DURATION seconds each, and writes
# the figures to OUT (default docs/load.md). Assumes scripts/build.sh has run.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
duration="${DURATION:-60}"
out="${OUT:-$repo/docs/load.md}"
export PATH="/usr/bin:$PATH"
set +u
source "$ws/devel/setup.bash"
set -u
export ROS_MASTER_URI="http://localhost:${ROS_PORT:-11391}"
log="$ws/build/load_test"
mkdir -p "$log"

roscore -p "${ROS_PORT:-11391}" > "$log/roscore.log" 2>&1 &
core=$!
trap 'kill $launch $core 2>/dev/null || true; wait 2>/dev/null || true' EXIT
sleep 3
roslaunch stereo_occupancy mapping.launch save_dir:="$log" > "$log/launch.log" 2>&1 &
launch=$!
sleep 5

tool="$ws/devel/lib/stereo_occupancy/load_test"
{
  echo "# Load test: the two nodelets in one manager"
  echo
  echo "Made by \`scripts/run_load_test.sh\` (DURATION=$duration s per row) on $(date -u +%Y-%m-%d):"
  echo "a roscore, \`launch/mapping.launch\` with its default parameters (\`line_pyramid_bounded\`,"
  echo "0.25 m cells, 25 m range, no blur), and \`load_test\` publishing the 'posts' flight's"
  echo "disparity images (40 distinct frames, rendered at the size, f scaled) with their poses"
  echo "on /tf. Latency: image stamp to the occupancy update received by \`load_test\` (a"
  echo "separate process, so it includes the update's transport). Dropped: published images"
  echo "without an update (the mapper's input queue keeps the newest). Machine: $(nproc) cores,"
  echo "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), the publisher on the same machine."
  echo
  "$tool" --width 640 --height 480 --rate 60 --duration "$duration" 2>>"$log/load_test.log"
  "$tool" --width 1280 --height 960 --rate 30 --duration "$duration" 2>>"$log/load_test.log" | tail -n 1
  # Overload: more than the mapper can draw; the queues drop the oldest images.
  "$tool" --width 1920 --height 1200 --rate 60 --duration "$duration" 2>>"$log/load_test.log" | tail -n 1
  echo
  echo "The last row is an overload on purpose (1920x1200 at 60 Hz): the mapper's input queue"
  echo "(\`queue_size\`, newest wins) drops what it cannot draw, latency stays bounded by the"
  echo "queue, and the manager's memory stays bounded by the full queues of 9 MB images (third line
below) and falls back when the load ends (the "end" column)."
  echo
  echo "Resident memory of the manager every second [MiB] (from load_test's log):"
  echo
  echo '```'
  grep "RSS every second" "$log/load_test.log" | tail -n 3
  echo '```'
} > "$out"
cat "$out"
