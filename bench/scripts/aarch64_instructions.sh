#!/usr/bin/env bash
# Guest instructions per Table I frame on aarch64 (grid preparation and
# drawing, one thread), the free run scalar and in NEON, for line_pyramid
# and the mapper's default: each run under qemu-user with a plugin that
# counts the instructions executed (bench/scripts/aarch64_count/icount_plugin.c),
# FRAMES frames minus none (the scene's set-up), divided by FRAMES.
# Needs scripts/cross_aarch64.sh to have built build/aarch64/ first.
# The counts are exact and repeatable, unlike times under an emulator; they
# are not cycles (docs/performance.md).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out="$repo/build/aarch64"
frames="${FRAMES:-10}"
bench="$out/build/stereo_occupancy_draw_frames"
[ -x "$bench" ] || { echo "aarch64_instructions: run scripts/cross_aarch64.sh first ($bench is missing)" >&2; exit 1; }
plugin="$out/icount_plugin.so"
gcc -shared -fPIC -O2 -Wall -Wextra -o "$plugin" "$repo/bench/scripts/aarch64_count/icount_plugin.c"

log="$out/aarch64_instructions.log"
count() {  # algorithm simd frames -> guest instructions of the whole process
  # qemu 7.x loads plugins of API version 1 (Debian 12's 7.2; 9.x asks for 2 or more).
  qemu-aarch64 -L "$out/sysroot" -plugin "$plugin" "$bench" "$1" "$2" "$3" >"$log" 2>&1 ||
    { echo "aarch64_instructions: $1 $2 $3 failed:" >&2; cat "$log" >&2; return 1; }
  sed -n 's/^guest instructions: //p' "$log"
}
echo "| algorithm | free run | M instructions a frame |"
echo "|---|---|---:|"
for algorithm in line_pyramid default; do
  for simd in scalar neon; do
    none=$(count "$algorithm" "$simd" 0) || exit 1
    some=$(count "$algorithm" "$simd" "$frames") || exit 1
    [ -n "$none" ] && [ -n "$some" ] || { echo "aarch64_instructions: no count for $algorithm $simd" >&2; exit 1; }
    awk -v a="$algorithm" -v s="$simd" -v n="$none" -v m="$some" -v f="$frames" \
      'BEGIN { printf "| %s | %s | %.2f |\n", a, s, (m - n) / f / 1e6 }'
  done
done
