#!/usr/bin/env bash
# One pipeline online and offline: a short simulated flight mapped by
# bag_to_map and replayed through the nodelets (launch/replay.launch) must
# give byte-identical .bt and .ot files that hold the flight's surfaces
# (evaluate_map: occupied cells and recall). Needs a built workspace; writes a
# JUnit file to $RESULTS if set. FRAMES (default 60), SCENARIO (default posts).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
out="$repo/build/online_offline"
export PATH="/usr/bin:$PATH"
# A roscore of its own, never the default port another program may hold.
ros_port="${ROS_PORT:-11392}"
export ROS_MASTER_URI="http://localhost:$ros_port"
bin="$ws/devel/lib/stereo_occupancy"
scenario="${SCENARIO:-posts}"
rm -rf "$out"
mkdir -p "$out/online"
"$bin/simulate_flight" --scenario "$scenario" --frames "${FRAMES:-60}" --output "$out/flight.bag" 2>/dev/null
"$bin/bag_to_map" --bag "$out/flight.bag" --output "$out/offline" >"$out/bag_to_map.json" 2>"$out/bag_to_map.log"
set +u
# shellcheck disable=SC1091
source "$ws/devel/setup.bash"
set -u
roslaunch -p "$ros_port" stereo_occupancy replay.launch bag:="$out/flight.bag" save_dir:="$out/online" >"$out/replay.log" 2>&1

failure=""
for ext in bt ot; do
  if ! cmp -s "$out/offline.$ext" "$out/online/stereo_occupancy_map.$ext"; then
    failure="$failure the .$ext files differ;"
  fi
done
grep -q '"dropped_no_pose": 0, "refused": 0' "$out/bag_to_map.json" || failure="$failure bag_to_map dropped images;"
# Two empty maps are byte-identical too: each map must hold the flight's
# surfaces (the posts flight of 60 frames: 25 831 occupied cells, recall 1).
min_occupied="${MIN_OCCUPIED:-10000}"
for map in "$out/offline.bt" "$out/online/stereo_occupancy_map.bt"; do
  score="$("$bin/evaluate_map" --map "$map" --scenario "$scenario" --frames "${FRAMES:-60}" 2>/dev/null || true)"
  occupied="$(grep -o '"occupied_cells": [0-9]*' <<<"$score" | head -n 1 | grep -o '[0-9]*$' || true)"
  recall="$(grep -o '"occupied_recall": [0-9.e+-]*' <<<"$score" | head -n 1 | cut -d' ' -f2 || true)"
  if [ -z "$occupied" ] || [ "$occupied" -lt "$min_occupied" ] || ! awk -v r="$recall" 'BEGIN { exit !(r >= 0.9) }'; then
    failure="$failure $(basename "$map") holds ${occupied:-no} occupied cells (recall ${recall:-none}; at least $min_occupied and 0.9 wanted);"
  fi
done
if [ -n "$failure" ]; then
  echo "online/offline check FAILED:$failure see $out"
else
  echo "online and offline maps are byte-identical ($(stat -c %s "$out/offline.bt") + $(stat -c %s "$out/offline.ot") bytes, $occupied occupied cells, recall $recall)"
fi
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" online_offline "bag_to_map_equals_replay_launch_${scenario}" \
  "${failure:+$failure see build/online_offline}"
[ -z "$failure" ]
