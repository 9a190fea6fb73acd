# shellcheck shell=bash
# junit RESULTS SUITE CASE [FAILURE]: writes RESULTS/SUITE.xml, one test case,
# failed with the message FAILURE when it is given and not empty. Sourced by
# the test command's scripts, so that catkin_test_results counts them.
junit() {
  local results="$1" suite="$2" name="$3" failure="${4:-}"
  mkdir -p "$results"
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"$suite\" tests=\"1\" failures=\"$([ -z "$failure" ] && echo 0 || echo 1)\" errors=\"0\">"
    echo "  <testcase classname=\"$suite\" name=\"$name\">"
    [ -z "$failure" ] || echo "    <failure message=\"$(echo "$failure" | sed 's/&/\&amp;/g; s/"/\&quot;/g; s/</\&lt;/g')\"/>"
    echo "  </testcase>"
    echo "</testsuite>"
  } >"$results/$suite.xml"
}
