#!/usr/bin/env bash
# Builds the core and simulation libraries and their gtests with AddressSanitizer (with leak
# checking) and UndefinedBehaviorSanitizer, in build/sanitize (apart from the
# catkin build), and runs them. Writes JUnit to $RESULTS if set.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$repo/build/sanitize"
rm -rf "$out/obj"  # objects of renamed sources must not link in
mkdir -p "$out/obj"
flags=(-std=c++17 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=undefined
       -I"$repo/include" -I"$repo/bench/include" -isystem /usr/include/eigen3 -isystem /usr/include/opencv4)
printf '%s\n' "$repo"/src/core/*.cpp "$repo"/bench/src/sim/*.cpp "$repo"/test/core/*.cpp "$repo"/test/sim/*.cpp \
  "$repo"/test/gtest_main.cpp |
  xargs -P "$(nproc)" -I{} sh -c 'g++ "$@" -c "{}" -o "'"$out"'/obj/$(basename {} .cpp).o"' _ "${flags[@]}"
g++ "${flags[@]}" "$out"/obj/*.o -lgtest -lpthread -lopencv_core -lopencv_imgproc -lopencv_imgcodecs -lopencv_calib3d \
  -loctomap -loctomath -ldynamicedt3d -o "$out/core_test_sanitized"  # dynamicedt3d: the distance field's comparison
xml=()
[ -n "${RESULTS:-}" ] && mkdir -p "$RESULTS" && xml=(--gtest_output="xml:$RESULTS/sanitized-core.xml")
cd "$out"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ./core_test_sanitized "${xml[@]}"
