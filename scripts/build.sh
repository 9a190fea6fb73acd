#!/usr/bin/env bash
# Builds stereo_occupancy in a catkin workspace under build/ws (kept out of git)
# whose src/ links to this repository. BUILD_TYPE=Debug for a debug build.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
# pyenv's python3 may come first on PATH and lacks catkin_pkg.
export PATH="/usr/bin:$PATH"

# The package in the workspace is a folder of links to the repository's
# top-level entries, all but build/: a link to the repository itself would
# put the workspace inside its own package, a loop that roslaunch and rostest
# walk into when they look for files.
pkg="$ws/src/stereo_occupancy"
mkdir -p "$ws/src"
[ -L "$pkg" ] && rm "$pkg"
mkdir -p "$pkg"
for entry in "$repo"/*; do
  name="$(basename "$entry")"
  [ "$name" = build ] && continue
  ln -sfn "$entry" "$pkg/$name"
done
for link in "$pkg"/*; do
  [ -e "$link" ] || rm -f "$link"  # entries removed from the repository
done
cd "$ws"
catkin_make -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_ENABLE_TESTING=ON -j"$(nproc)" "$@"
