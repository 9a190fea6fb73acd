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
set +e
summary="$(catkin_test_results build/test_results --verbose)"
status=$?
set -e
echo "$summary"
# One plain closing line, counted from the JUnit files: "N passed, N failed".
cases=$(cat build/test_results/*/*.xml | grep -o '<testcase ' | wc -l || true)
failed=$(cat build/test_results/*/*.xml | grep -oE '<(failure|error)[ >]' | wc -l || true)
echo "tests: $((cases - failed)) passed, $failed failed"
exit $status
