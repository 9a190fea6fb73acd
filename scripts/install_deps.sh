#!/usr/bin/env bash
# Installs the Debian 12 packages stereo_occupancy needs to build, test and run.
# Idempotent: runs apt-get only when a package is missing. Needs root.
set -euo pipefail

PACKAGES=(
  build-essential cmake catkin python3-catkin-pkg python3-empy
  libeigen3-dev libopencv-dev liboctomap-dev libdynamicedt3d-dev libsqlite3-dev pkg-config libgtest-dev clang libclang-rt-14-dev
  sqlite3  # the CLI tests damage a database row as another program would
  clang-format  # scripts/check_format.sh
  ros-base-dev libroscpp-dev ros-message-generation libnodeletlib-dev pluginlib-dev
  libtf2-ros-dev libtf2-msgs-dev libtf2-eigen-dev libimage-transport-dev libcv-bridge-dev
  libstereo-msgs-dev ros-stereo-msgs libsensor-msgs-dev libgeometry-msgs-dev
  libvisualization-msgs-dev libnav-msgs-dev libstd-srvs-dev ros-std-srvs
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure libdiagnostic-updater-dev
  librostest-dev python3-rostest librosbag-dev python3-rosbag rosbash ros-stereo-image-proc libstereo-image-proc-dev
  opencv-doc  # the Middlebury "Aloe" stereo pair of test/rostest/stereo_pipeline.test
  rviz xvfb xauth imagemagick  # scripts/render_rviz.sh: rviz headless, a screenshot
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
