#!/usr/bin/env bash
# The package's C++ against .clang-format: lists every file whose layout
# clang-format would change (clang-format --dry-run), and fails if there is
# one. Format a file with `clang-format -i FILE`. Writes a JUnit file to
# $RESULTS if set.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
unformatted=()
while IFS= read -r file; do
  clang-format --dry-run --Werror "$file" > /dev/null 2>&1 || unformatted+=("$file")
done < <(git ls-files '*.cpp' '*.h')
for f in "${unformatted[@]}"; do echo "check_format: $f differs from .clang-format (clang-format -i $f)"; done
echo "check_format: $(git ls-files '*.cpp' '*.h' | wc -l) files, ${#unformatted[@]} unformatted"
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" format cpp_files_follow_clang_format \
  "$([ ${#unformatted[@]} = 0 ] || echo "${#unformatted[@]} files: $(printf '%s ' "${unformatted[@]}")")"
[ ${#unformatted[@]} = 0 ]
