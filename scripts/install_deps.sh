#!/usr/bin/env bash
# Installs the Debian 12 packages stereo_occupancy needs to build, test and run.
# Idempotent: runs apt-get only when a package is missing. Needs root.
set -euo pipefail

PACKAGES=(
  build-essential cmake catkin python3-catkin-pkg python3-empy
  libeigen3-dev libopencv-dev liboctomap-dev libgtest-dev
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "install_deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
