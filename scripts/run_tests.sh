#!/usr/bin/env bash
# The README's test command: installs what is missing, builds the package and
# runs every test; fails if any test fails.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
export PATH="/usr/bin:$PATH"

"$repo/scripts/install_deps.sh"
"$repo/scripts/build.sh"
cd "$ws"
rm -rf build/test_results
catkin_make run_tests -j"$(nproc)"
results="$ws/build/test_results/stereo_occupancy"

# The core's gtests again under AddressSanitizer + UndefinedBehaviorSanitizer,
# and a short libFuzzer run over the core's entry point.
set +e
RESULTS="$results" "$repo/scripts/sanitize.sh" > "$ws/build/sanitize.log" 2>&1
sanitize_status=$?
[ $sanitize_status = 0 ] || { echo "sanitized core tests FAILED:"; tail -40 "$ws/build/sanitize.log"; }
RESULTS="$results" "$repo/scripts/fuzz.sh" "${FUZZ_SECONDS:-60}"
fuzz_status=$?
# One pipeline: bag_to_map and the nodelets give byte-identical maps.
RESULTS="$results" "$repo/scripts/check_online_offline.sh"
online_offline_status=$?
# The shipped rviz config, headless, during a replay of that flight: loads
# without an error and shows the map.
RESULTS="$results" BAG="$repo/build/online_offline/flight.bag" OUT="$repo/build/rviz/rviz_test.png" \
  "$repo/scripts/render_rviz.sh"
rviz_status=$?
# The core and its gtests for aarch64 (the vehicle's ARM computer), with
# Debian's cross compiler, run under qemu-user (about 5 minutes).
RESULTS="$results" "$repo/scripts/cross_aarch64.sh" > "$ws/build/aarch64.log" 2>&1
aarch64_status=$?
tail -n 1 "$ws/build/aarch64.log"
[ $aarch64_status = 0 ] || { echo "aarch64 core tests FAILED:"; tail -40 "$ws/build/aarch64.log"; }
# The README and docs/: links resolve, commands name what exists.
RESULTS="$results" "$repo/scripts/check_docs.sh"
docs_status=$?
# The C++ follows .clang-format.
RESULTS="$results" "$repo/scripts/check_format.sh"
format_status=$?
# The install space holds the product and nothing of bench/.
RESULTS="$results" "$repo/scripts/check_install.sh"
install_status=$?

summary="$(catkin_test_results build/test_results --verbose)"
status=$?
set -e
echo "$summary"
# One plain closing line, counted from the JUnit files: "N passed, N failed".
cases=$(cat build/test_results/*/*.xml | grep -o '<testcase ' | wc -l || true)
failed=$(cat build/test_results/*/*.xml | grep -oE '<(failure|error)[ >]' | wc -l || true)
# A script that stopped early may leave no JUnit file: count it as a failure.
[ $sanitize_status = 0 ] || failed=$((failed + 1))
[ $fuzz_status = 0 ] || [ -f "$results/fuzz.xml" ] || failed=$((failed + 1))
[ $online_offline_status = 0 ] || [ -f "$results/online_offline.xml" ] || failed=$((failed + 1))
[ $rviz_status = 0 ] || [ -f "$results/rviz.xml" ] || failed=$((failed + 1))
[ $docs_status = 0 ] || [ -f "$results/docs.xml" ] || failed=$((failed + 1))
[ $format_status = 0 ] || [ -f "$results/format.xml" ] || failed=$((failed + 1))
[ $install_status = 0 ] || [ -f "$results/install.xml" ] || failed=$((failed + 1))
[ $aarch64_status = 0 ] || [ -f "$results/aarch64-core.xml" ] || failed=$((failed + 1))
echo "tests: $((cases - failed)) passed, $failed failed"
[ $status = 0 ] && [ $sanitize_status = 0 ] && [ $fuzz_status = 0 ] && [ $online_offline_status = 0 ] &&
  [ $rviz_status = 0 ] && [ $docs_status = 0 ] && [ $format_status = 0 ] && [ $install_status = 0 ] &&
  [ $aarch64_status = 0 ]
