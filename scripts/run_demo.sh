#!/usr/bin/env bash
# The README's main command: a simulated helicopter flight replayed through
# the two nodelets in a real roscore. Installs what is missing, builds,
# generates the flight's bag (or reuses it), replays it with
# launch/replay.launch, saves the map (.bt and .ot), scores it against the
# ground truth, draws a top and a side view, and prints a summary whose last
# line is "map: <path of the .bt file>".
#
#   SCENARIO=posts|houses|forest|wires (default posts)   SEED=1   OUT=build/demo
#   CONFIG=<parameters file> (default config/mapping.yaml)
#   UPDATE_DOCS=1: also copy the two views, the distance field's slice and rviz's screenshot to docs/
#   (demo_<scenario>_map_{top,side}.png, demo_<scenario>_distance_slice.png, rviz_<scenario>.png)
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
out="${OUT:-$repo/build/demo}"
scenario="${SCENARIO:-posts}"
seed="${SEED:-1}"
export PATH="/usr/bin:$PATH"
# A roscore of its own, never the default port another program may hold.
ros_port="${ROS_PORT:-11394}"
export ROS_MASTER_URI="http://localhost:$ros_port"

"$repo/scripts/install_deps.sh"
mkdir -p "$out"
"$repo/scripts/build.sh" >"$out/build.log" 2>&1 || { cat "$out/build.log"; exit 1; }
bin="$ws/devel/lib/stereo_occupancy"

bag="$out/${scenario}_seed${seed}.bag"
if [ ! -f "$bag" ]; then
  "$bin/simulate_flight" --scenario "$scenario" --seed "$seed" --output "$bag.tmp"
  mv "$bag.tmp" "$bag"
  mv "$bag.tmp.scene.txt" "$bag.scene.txt"
fi

map_dir="$out/map_$scenario"
rm -rf "$map_dir"
mkdir -p "$map_dir"
set +u
# shellcheck disable=SC1091
source "$ws/devel/setup.bash"
set -u
echo "replaying $bag through DisparityMapper and OctomapAccumulator (launch/replay.launch) ..."
roslaunch -p "$ros_port" stereo_occupancy replay.launch bag:="$bag" save_dir:="$map_dir" config:="${CONFIG:-$repo/config/mapping.yaml}" >"$out/replay_$scenario.log" 2>&1 || {
  tail -30 "$out/replay_$scenario.log"
  exit 1
}
map="$map_dir/stereo_occupancy_map.bt"
[ -f "$map" ] || { echo "no map was saved; see $out/replay_$scenario.log"; exit 1; }

summary="$(grep -m1 'DisparityMapper summary:' "$out/replay_$scenario.log" || true)"
accumulator="$(grep -m1 'OctomapAccumulator summary:' "$out/replay_$scenario.log" || true)"
field() { echo "$summary" | sed -n "s/.* $1=\([0-9.]*\).*/\1/p"; }  # " key=": cpu_ms_... also ends in ms_...
quality="$("$bin/evaluate_map" --map "$map" --scenario "$scenario" --views "$out/${scenario}_map" 2>/dev/null)"
quality="${quality%%\"bands\"*}"  # the whole map's scores (the range bands repeat the keys)
q() { echo "$quality" | sed -n "s/.*\"$1\": \([0-9.e+-]*\).*/\1/p"; }
pct() { awk -v v="$1" 'BEGIN { printf "%.1f %%", 100 * v }'; }

# The planners' distance field of the saved map around the last camera position, its layer at 2 m
# (what the accumulator publishes on distance_slice).
"$bin/draw_distance_slice" --map "$map" --scenario "$scenario" --z 2 --out "$out/${scenario}_distance_slice.png" >/dev/null
algorithm="$(echo "$summary" | sed -n 's/.*algorithm=\([a-z_]*\).*/\1/p')"
# The map as rviz shows it (rviz/mapping.rviz, headless): a second replay.
rviz_line="$(BAG="$bag" OUT="$out/rviz_$scenario.png" "$repo/scripts/render_rviz.sh" 2>&1 | tail -1 || true)"
report() {
  echo "stereo_occupancy demo: scenario '$scenario' (seed $seed), $algorithm at $(field resolution_m) m, 25 m range"
  echo "  frames:       $(field images_received) received, $(field images_processed) mapped, $(field dropped_no_transform) dropped (no pose), $(field dropped_invalid) refused"
  echo "  ms per frame: $(field ms_per_image_mean) mean, $(field ms_per_image_median) median, $(field ms_per_image_p99) p99, $(field ms_per_image_max) max (draw + blur + encode + publish)"
  echo "  cpu ms:       $(field cpu_ms_per_image_median) median, $(field cpu_ms_per_image_p99) p99 (the same span in the mapper thread's CPU time, without waits for a core)"
  echo "  fusion ms:    $(summary="$accumulator" field fusion_ms_median) median, $(summary="$accumulator" field fusion_ms_p99) p99, $(summary="$accumulator" field fusion_ms_max) max (one update into the OctoMap, accumulator)"
  echo "  distance ms:  $(summary="$accumulator" field distance_field_ms_median) median, $(summary="$accumulator" field distance_field_ms_p99) p99, $(summary="$accumulator" field distance_field_ms_max) max (the distance field brought up to date after an update, accumulator)"
  echo "  map quality against the ground truth (within one cell):"
  echo "    occupied precision       $(pct "$(q occupied_precision)")  ($(q occupied_at_surface) of $(q occupied_cells) occupied cells at a true surface)"
  echo "    occupied recall          $(pct "$(q occupied_recall)")  ($(q surface_found) of $(q truth_surface_cells) observed surface cells)"
  echo "    phantom obstacles        $(pct "$(q phantom_share)")  ($(q occupied_phantom) occupied cells in free air, more than a cell from any surface)"
  echo "    F1                       $(q f1)"
  echo "    surface called free      $(pct "$(q surface_called_free_fraction)")"
  echo "    free-space coverage      $(pct "$(q free_coverage)")  (of the truly empty cells the rays crossed)"
  echo "  views:        $out/${scenario}_map_top.png, $out/${scenario}_map_side.png, $out/${scenario}_distance_slice.png"
  echo "  rviz:         ${rviz_line#render_rviz: }"
  echo "  log:          $out/replay_$scenario.log"
  echo "map: $map"
}
echo
report
if [ "${UPDATE_DOCS:-0}" = 1 ]; then
  cp "$out/${scenario}_map_top.png" "$repo/docs/demo_${scenario}_map_top.png"
  cp "$out/${scenario}_map_side.png" "$repo/docs/demo_${scenario}_map_side.png"
  cp "$out/${scenario}_distance_slice.png" "$repo/docs/demo_${scenario}_distance_slice.png"
  cp "$out/rviz_$scenario.png" "$repo/docs/rviz_$scenario.png"
  {
    echo "*Generated by \`UPDATE_DOCS=1\` [scripts/run_demo.sh](../scripts/run_demo.sh): do not edit this page by hand; run the script again.*"
    echo
    echo "# The demo's output"
    echo
    echo "Written by \`UPDATE_DOCS=1 scripts/run_demo.sh\` (scenario \`$scenario\`, $(date -u +%Y-%m-%d)), with the"
    echo "pictures beside it: [top](demo_${scenario}_map_top.png), [side](demo_${scenario}_map_side.png),"
    echo "[rviz](rviz_$scenario.png). Times are this machine's (2 cores, shared)."
    echo
    echo '```'
    report | sed "s|$repo/||g"
    echo '```'
  } >"$repo/docs/demo_output.md"
fi

