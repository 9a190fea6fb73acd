#!/usr/bin/env bash
# The README's main command. Until the simulated flight lands it installs what
# is missing, builds the package, reproduces the paper's Table I on the
# synthetic test image and draws that image into a map file.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
out="${OUT:-$repo/build/demo}"
export PATH="/usr/bin:$PATH"

"$repo/scripts/install_deps.sh"
"$repo/scripts/build.sh" >/dev/null
bin="$ws/devel/lib/stereo_occupancy"
mkdir -p "$out"

"$bin/table1" --repeat 21 --save-image "$out/table1_image.pfm"
echo
# The test image's pose: 2 m above the ground looking along +x (optical frame in W).
"$bin/draw_disparity" --disparity "$out/table1_image.pfm" --focal 700 --cx 319.5 --cy 239.5 \
  --baseline 0.3 --delta-d 0.5 --pose "0 0 2 -0.5 0.5 -0.5 0.5" --resolution 0.25 --max-range 25 \
  --algorithm line_pyramid --blur 0.1 0.01 --repeat 21 --output "$out/table1_map.bt"
echo "map: $out/table1_map.bt"
