#!/usr/bin/env bash
# Cross-builds the ROS-free core, the simulation library and the core's gtests
# for aarch64 with Debian's cross compiler (cmake/core_only with the toolchain
# cmake/aarch64-linux-gnu.cmake) and runs the gtests under qemu-user.
# Everything goes to build/aarch64/. Needs root the first time (apt-get).
# Writes JUnit to $RESULTS (if set); JOBS (default: nproc) parallel compiles;
# CXXFLAGS are added to the build type's flags (e.g. CXXFLAGS=-ffp-contract=off).
# Last line: "aarch64: N tests passed, M failed".
#
# The arm64 libraries are not installed with multiarch: libopencv-imgcodecs406
# needs libgdal32, which is not Multi-Arch: same (libopencv-imgcodecs406:arm64
# would remove the amd64 OpenCV, cv_bridge and stereo_image_proc), the arm64
# copies of Multi-Arch: same libraries must have the amd64 versions (they
# would upgrade amd64 packages), and liboctomap-dev:arm64 and :amd64 ship
# different /usr/share/octomap/*.cmake. Instead the arm64 packages are
# downloaded (apt-get as on an empty arm64 system, dpkg untouched) and
# unpacked into build/aarch64/sysroot, the compiler's --sysroot and qemu's -L.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$repo/build/aarch64"
sysroot="$out/sysroot"
jobs="${JOBS:-$(nproc)}"
export DEBIAN_FRONTEND=noninteractive

# --- Host packages (amd64): the cross compiler and qemu ----------------------
HOST_PACKAGES=(g++-aarch64-linux-gnu qemu-user cmake)
# --- Target packages (arm64), unpacked into the sysroot -------------------------
ARM64_PACKAGES=(libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev libopencv-calib3d-dev liboctomap-dev
  libgtest-dev libeigen3-dev)

missing=()
for p in "${HOST_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
update=0
[ ${#missing[@]} = 0 ] || update=1
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "cross_aarch64: adding the arm64 architecture"
  dpkg --add-architecture arm64
  update=1
fi
apt-cache show libopencv-core-dev:arm64 >/dev/null 2>&1 || update=1
[ $update = 0 ] || apt-get update -qq
if [ ${#missing[@]} -gt 0 ]; then
  echo "cross_aarch64: installing ${missing[*]}"
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# apt-get as on an arm64 system with nothing installed: its own (empty) dpkg
# status and cache, no lock on the system's dpkg; it only resolves and downloads.
mkdir -p "$out/apt/archives/partial"
: >"$out/apt/status"
apt_arm64=(apt-get -qq -o APT::Architecture=arm64 -o APT::Architectures::=arm64
  -o Dir::State::status="$out/apt/status" -o Dir::Cache="$out/apt" -o Dir::Cache::archives="$out/apt/archives"
  -o Dir::Cache::pkgcache= -o Dir::Cache::srcpkgcache= -o Debug::NoLocking=1 -o APT::Sandbox::User=root
  --no-install-recommends)
wanted="$("${apt_arm64[@]}" -s install "${ARM64_PACKAGES[@]}" | sed -n 's/^Inst \([^ ]*\) (\([^ ]*\) .*/\1=\2/p' | sort)"
[ -n "$wanted" ] || { echo "cross_aarch64: apt-get resolves no arm64 packages" >&2; exit 1; }
if [ "$(cat "$sysroot/.packages" 2>/dev/null)" != "$wanted" ]; then
  echo "cross_aarch64: unpacking $(echo "$wanted" | wc -l) arm64 packages into $sysroot"
  rm -f "$out/apt/archives/"*.deb
  "${apt_arm64[@]}" -y --download-only install "${ARM64_PACKAGES[@]}"
  rm -rf "$sysroot.new"
  mkdir -p "$sysroot.new"
  for deb in "$out/apt/archives/"*.deb; do dpkg-deb -x "$deb" "$sysroot.new"; done
  # Absolute symlinks (libz.so -> /lib/...) would leave the root: make them relative.
  find "$sysroot.new" -type l -lname '/*' | while read -r link; do
    ln -sfn "$(realpath -m -s --relative-to="$(dirname "$link")" "$sysroot.new$(readlink "$link")")" "$link"
  done
  # What update-alternatives would do in libblas3's and liblapack3's postinst.
  lib="$sysroot.new/usr/lib/aarch64-linux-gnu"
  for alt in blas/libblas.so.3 lapack/liblapack.so.3; do
    [ ! -e "$lib/$alt" ] || [ -e "$lib/${alt#*/}" ] || ln -s "$alt" "$lib/${alt#*/}"
  done
  echo "$wanted" >"$sysroot.new/.packages"
  rm -f "$out/apt/archives/"*.deb
  rm -rf "$sysroot"
  mv "$sysroot.new" "$sysroot"
fi

# --- Configure, build ------------------------------------------------------------
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.0f", b - a }'; }
start=$(now)
cmake -S "$repo/cmake/core_only" -B "$out/build" -DCMAKE_TOOLCHAIN_FILE="$repo/cmake/aarch64-linux-gnu.cmake" \
  -DAARCH64_SYSROOT="$sysroot" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS="${CXXFLAGS:-}" >"$out/configure.log" 2>&1 ||
  { tail -30 "$out/configure.log"; exit 1; }
cmake --build "$out/build" -j"$jobs" >"$out/build.log" 2>&1 ||
  { grep -A12 -m3 'error' "$out/build.log" || tail -30 "$out/build.log"; exit 1; }
build_seconds=$(since "$start")
grep 'warning:' "$out/build.log" | sort -u || true
test_bin="$out/build/stereo_occupancy_core_test"
aarch64-linux-gnu-readelf -h "$test_bin" | grep -q 'Machine: *AArch64' ||
  { echo "cross_aarch64: $test_bin is not an aarch64 binary" >&2; exit 1; }

# --- Run the gtests under qemu ---------------------------------------------------
xml="$out/core_test.xml"
rm -f "$xml"
start=$(now)
status=0
(cd "$out/build" && qemu-aarch64 -L "$sysroot" "$test_bin" --gtest_output="xml:$xml") >"$out/test.log" 2>&1 || status=$?
test_seconds=$(since "$start")
grep -E '^\[  (FAILED  |SKIPPED )\] [^ ]+ \(' "$out/test.log" || true
# gtest's per-test result lines ("[  FAILED  ] Suite.Name (12 ms)"): one per test.
failed=$(grep -cE '^\[  FAILED  \] [^ ]+ \(' "$out/test.log" || true)
skipped=$(grep -cE '^\[  SKIPPED \] [^ ]+ \(' "$out/test.log" || true)
cases=0
[ ! -f "$xml" ] || cases=$(grep -c '<testcase ' "$xml" || true)
if [ $status != 0 ] && [ "$failed" = 0 ]; then
  failed=1  # a crash, or an error outside the tests
  tail -n 20 "$out/test.log"
fi
if [ -n "${RESULTS:-}" ]; then
  mkdir -p "$RESULTS"
  if [ -f "$xml" ] && [ "$cases" -gt 0 ]; then
    cp "$xml" "$RESULTS/aarch64-core.xml"
  else
    # shellcheck source=scripts/junit.sh
    source "$repo/scripts/junit.sh"
    junit "$RESULTS" aarch64-core core_test "the aarch64 core tests stopped early (exit $status); see build/aarch64/test.log"
  fi
fi
echo "aarch64: cross build ${build_seconds} s, qemu test run ${test_seconds} s; log: build/aarch64/test.log"
passed=$((cases - failed - skipped))
[ $passed -ge 0 ] || passed=0
echo "aarch64: $passed tests passed, $failed failed$([ "$skipped" = 0 ] || echo ", $skipped skipped")"
[ $status = 0 ] && [ "$failed" = 0 ]
