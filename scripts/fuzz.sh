#!/usr/bin/env bash
# Builds the libFuzzer target (clang, with AddressSanitizer and
# UndefinedBehaviorSanitizer) over the core and runs it for SECONDS (default
# 60). Writes a JUnit file to $RESULTS (if set) so the test command counts it.
# Crashes land in build/fuzz/.
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
mkdir -p "$out/obj"
# One object per source, compiled in parallel.
printf '%s\n' "$repo"/test/fuzz/fuzz_disparity_drawer.cpp "$repo"/src/core/*.cpp |
  xargs -P "$(nproc)" -I{} sh -c 'clang++ "$@" -c "{}" -o "'"$out"'/obj/$(basename {} .cpp).o"' _ "${flags[@]}"
clang++ "${flags[@]}" "$out"/obj/*.o -lopencv_core -lopencv_imgproc -lopencv_imgcodecs -loctomap -loctomath \
  -o "$out/fuzz_disparity_drawer"

status=0
( cd "$out" && ./fuzz_disparity_drawer -max_total_time="$seconds" -seed="$seed" -rss_limit_mb=2048 -timeout=20 \
    -print_final_stats=1 "$corpus" ) >"$out/fuzz.log" 2>&1 || status=$?
tail -n 12 "$out/fuzz.log"
if [ -n "${RESULTS:-}" ]; then
  mkdir -p "$RESULTS"
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"fuzz\" tests=\"1\" failures=\"$([ $status = 0 ] && echo 0 || echo 1)\" errors=\"0\">"
    echo "  <testcase classname=\"fuzz\" name=\"fuzz_disparity_drawer_${seconds}s\">"
    [ $status = 0 ] || echo "    <failure message=\"libFuzzer found a crash; see build/fuzz/fuzz.log\"/>"
    echo "  </testcase>"
    echo "</testsuite>"
  } >"$RESULTS/fuzz.xml"
fi
exit $status
