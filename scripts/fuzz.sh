#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, with AddressSanitizer and
# UndefinedBehaviorSanitizer) over the core and runs them: the drawer for
# SECONDS (default 60), the accumulator's update input and the map-file and
# tile-row reader (test/fuzz/fuzz_octree_data.cpp) for half as long each.
# Writes a JUnit file to $RESULTS (if set) so the test command counts it.
# Crashes land in build/fuzz/; each target's log in build/fuzz/<target>.log.
#
# As a test (the default) it is reproducible: a fixed seed (FUZZ_SEED, default
# 1) from a fresh copy of the seeds in test/fuzz/corpus, so a clean clone runs
# the same inputs as this machine, as far as its time allows; a red result
# names an input that fails anywhere. FUZZ_EXPLORE=1 hunts instead: a random
# seed and a corpus kept in build/fuzz/corpus across runs. Add what a hunt
# finds to test/fuzz/corpus with its fix.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds="${1:-60}"
out="$repo/build/fuzz"
if [ "${FUZZ_EXPLORE:-0}" = 1 ]; then
  corpus=corpus
  seed=0  # libFuzzer picks one
else
  corpus=test-corpus
  seed="${FUZZ_SEED:-1}"
  rm -rf "$out/$corpus"
fi
mkdir -p "$out/$corpus"
cp -n "$repo"/test/fuzz/corpus/* "$out/$corpus/" 2>/dev/null || true

flags=(-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
       -I"$repo/include" -isystem /usr/include/eigen3 -isystem /usr/include/opencv4)
targets=(fuzz_disparity_drawer fuzz_occupancy_update fuzz_octree_data)
rm -rf "$out/obj" "$out/core"  # objects of renamed sources must not link in
mkdir -p "$out/obj" "$out/core"
# One object per source, compiled in parallel; the core's objects are shared.
printf '%s\n' "$repo"/src/core/*.cpp |
  xargs -P "$(nproc)" -I{} sh -c 'clang++ "$@" -c "{}" -o "'"$out"'/core/$(basename {} .cpp).o"' _ "${flags[@]}"
for t in "${targets[@]}"; do
  clang++ "${flags[@]}" -c "$repo/test/fuzz/$t.cpp" -o "$out/obj/$t.o"
  clang++ "${flags[@]}" "$out/obj/$t.o" "$out"/core/*.o -lopencv_core -lopencv_imgproc -lopencv_imgcodecs \
    -loctomap -loctomath -o "$out/$t"
done

# The drawer from the seeds in test/fuzz/corpus for SECONDS, the other
# targets from nothing for half as long (run_from_nothing below).
# -malloc_limit_mb: one allocation of more than 2 GB is a failure, so an
# update that claims a huge box and makes the code allocate for it is found.
run() {  # NAME SECONDS CORPUS
  ( cd "$out" && ./"$1" -max_total_time="$2" -seed="$seed" -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=20 \
      -print_final_stats=1 "$3" ) >"$out/$1.log" 2>&1
}
status=0
run fuzz_disparity_drawer "$seconds" "$corpus" || status=$?
tail -n 12 "$out/fuzz_disparity_drawer.log"
# The accumulator's input (occupancy updates from any node), then map files
# and tile rows (the bytes OctoMap's readers would take), each from nothing
# for half as long.
run_from_nothing() {  # TARGET CORPUS; prints the target's last lines, returns its status
  [ "${FUZZ_EXPLORE:-0}" = 1 ] || rm -rf "${out:?}/$2"
  mkdir -p "$out/$2"
  local target_status=0
  run "$1" "$(( (seconds + 1) / 2 ))" "$2" || target_status=$?
  tail -n 12 "$out/$1.log"
  return $target_status
}
update_status=0
run_from_nothing fuzz_occupancy_update "update-$corpus" || update_status=$?
tree_status=0
run_from_nothing fuzz_octree_data "tree-$corpus" || tree_status=$?
if [ -n "${RESULTS:-}" ]; then
  mkdir -p "$RESULTS"
  testcase() {  # TARGET SECONDS STATUS
    echo "  <testcase classname=\"fuzz\" name=\"$1_$2s\">"
    [ "$3" = 0 ] || echo "    <failure message=\"libFuzzer found a crash; see build/fuzz/$1.log\"/>"
    echo "  </testcase>"
  }
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"fuzz\" tests=\"3\" failures=\"$(( (status != 0) + (update_status != 0) + (tree_status != 0) ))\" errors=\"0\">"
    testcase fuzz_disparity_drawer "$seconds" "$status"
    testcase fuzz_occupancy_update "$(( (seconds + 1) / 2 ))" "$update_status"
    testcase fuzz_octree_data "$(( (seconds + 1) / 2 ))" "$tree_status"
    echo "</testsuite>"
  } >"$RESULTS/fuzz.xml"
fi
[ $status = 0 ] && [ $update_status = 0 ] && [ $tree_status = 0 ]
