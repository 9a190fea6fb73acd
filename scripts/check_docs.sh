#!/usr/bin/env bash
# The README and docs/ against the tree: every relative link resolves, and
# every command in their code blocks names what exists: a launch file and
# its args (roslaunch stereo_occupancy X.launch a:=...), a script
# (scripts/X.sh, bench/scripts/X.sh), a tool and its options (rosrun
# stereo_occupancy TOOL --opt: TOOL --help lists --opt). Needs a built
# workspace; writes a JUnit file to $RESULTS if set.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="${WS:-$repo/build/ws}/devel/lib/stereo_occupancy"
problems=()
cd "$repo"

for doc in README.md docs/*.md; do
  dir="$(dirname "$doc")"
  # Links: ](target), without web addresses and in-page anchors.
  while IFS= read -r target; do
    path="${target%%#*}"
    [ -z "$path" ] && continue
    [ -e "$dir/$path" ] || problems+=("$doc: the link $target does not resolve")
  done < <(grep -oE '\]\([^)]+\)' "$doc" | sed -E 's/^\]\(([^) ]+).*\)$/\1/' | grep -vE '^(https?:|mailto:|#)')

  # Commands in code blocks (a line's words; a trailing backslash continues it).
  in_block=0
  while IFS= read -r line; do
    if [[ "$line" == '```'* ]]; then in_block=$((1 - in_block)); continue; fi
    [ $in_block = 1 ] || continue
    words=($line)
    [ ${#words[@]} -gt 0 ] || continue
    case "${words[0]}" in
      roslaunch)
        [ "${words[1]:-}" = stereo_occupancy ] || continue
        launch="launch/${words[2]:-}"
        if [ ! -f "$launch" ]; then problems+=("$doc: no $launch"); continue; fi
        for w in "${words[@]:3}"; do
          [[ "$w" == *:=* ]] || continue
          arg="${w%%:=*}"
          grep -q "<arg name=\"$arg\"" "$launch" || problems+=("$doc: $launch has no arg '$arg'")
        done ;;
      scripts/* | bench/scripts/*)
        [ -x "${words[0]}" ] || problems+=("$doc: no executable ${words[0]}") ;;
      rosrun)
        [ "${words[1]:-}" = stereo_occupancy ] || continue
        tool="${words[2]:-}"
        if [ ! -x "$bin/$tool" ]; then problems+=("$doc: no tool $tool"); continue; fi
        help="$("$bin/$tool" --help 2>&1)"
        for w in "${words[@]:3}"; do
          opt="$(echo "$w" | grep -oE '^\[?--[a-z][a-z0-9-]*' | tr -d '[')"
          [ -n "$opt" ] || continue
          grep -q -- "$opt" <<<"$help" || problems+=("$doc: $tool --help does not list $opt")
        done ;;
    esac
  done < <(sed -e ':a' -e '/\\$/N; s/\\\n//; ta' "$doc")
done

for p in "${problems[@]}"; do echo "check_docs: $p"; done
echo "check_docs: README.md and docs/*.md: ${#problems[@]} problems"
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" docs links_resolve_and_commands_exist \
  "$([ ${#problems[@]} = 0 ] || echo "${#problems[@]} problems: $(printf '%s; ' "${problems[@]}")")"
[ ${#problems[@]} = 0 ]
