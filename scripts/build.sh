#!/usr/bin/env bash
# Builds stereo_occupancy in a catkin workspace under build/ws (kept out of git)
# whose src/ links to this repository. BUILD_TYPE=Debug for a debug build.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
# pyenv's python3 may come first on PATH and lacks catkin_pkg.
export PATH="/usr/bin:$PATH"

mkdir -p "$ws/src"
[ -e "$ws/src/stereo_occupancy" ] || ln -s "$repo" "$ws/src/stereo_occupancy"
cd "$ws"
catkin_make -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_ENABLE_TESTING=ON -j"$(nproc)" "$@"
