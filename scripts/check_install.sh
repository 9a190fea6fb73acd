#!/usr/bin/env bash
# The install space holds the product and nothing of the bench: installs the
# package from a built workspace (build/ws, or WS) into a temporary prefix
# (cmake --install of the package's build folder; the workspace's own install
# space is not touched) and checks that
# - the product is there: the core, store, ROS and nodelet libraries,
#   nodelets.xml and package.xml, every header under include/stereo_occupancy/,
#   the msg/srv and dynamic_reconfigure headers, every file of launch/,
#   config/ and rviz/, and the user's tools, exactly the sources in src/tools/;
# - each installed tool runs (--help) and each library loads with the
#   install's libraries alone;
# - nothing of bench/ is: no tool of bench/src/tools/, no simulation library,
#   no header of bench/include/, no script of bench/scripts/, and the CMake
#   and pkg-config files export no bench library or include folder.
# Needs a built workspace (scripts/build.sh); writes a JUnit file to $RESULTS
# if set.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ws="${WS:-$repo/build/ws}"
build="$ws/build/stereo_occupancy"
export PATH="/usr/bin:$PATH"
prefix="$(mktemp -d)"
trap 'rm -rf "$prefix"' EXIT
log="$ws/build/check_install.log"
problems=()

# The install's libraries first, none of the workspace's (devel/lib): a
# library the install lacks must not be found there.
libs="$prefix/lib$(echo "${LD_LIBRARY_PATH:-}" | tr ':' '\n' | grep -v "^$ws/" | grep . | sed 's/^/:/' | tr -d '\n')"

if ! cmake --install "$build" --prefix "$prefix" >"$log" 2>&1; then
  why="$(grep -m1 -A4 'CMake Error' "$log" | tr -s ' \n' ' ')"
  problems+=("cmake --install failed (is the workspace built and up to date? scripts/build.sh): $why(see $log)")
else
  pkg_lib="$prefix/lib/stereo_occupancy"
  share="$prefix/share/stereo_occupancy"
  include="$prefix/include/stereo_occupancy"
  need() {  # PATH...: each must be in the install
    for f in "$@"; do [ -e "$f" ] || problems+=("missing: ${f#"$prefix"/}"); done
  }
  name_of() { local b="${1##*/}"; echo "${b%.*}"; }

  # --- The product ---------------------------------------------------------
  for lib in core store ros nodelets; do need "$prefix/lib/libstereo_occupancy_$lib.so"; done
  need "$share/nodelets.xml" "$share/package.xml"
  while IFS= read -r h; do need "$include/${h#"$repo"/include/stereo_occupancy/}"; done \
    < <(find "$repo/include/stereo_occupancy" -name '*.h')
  for m in "$repo"/msg/*.msg "$repo"/srv/*.srv; do need "$include/$(name_of "$m").h"; done
  for c in "$repo"/config/*.cfg; do need "$include/$(name_of "$c")Config.h"; done
  for dir in launch config rviz; do
    while IFS= read -r f; do need "$share/${f#"$repo"/}"; done < <(find "$repo/$dir" -type f)
  done
  # The user's tools: exactly the sources in src/tools/, each running.
  expected="$(for t in "$repo"/src/tools/*.cpp; do name_of "$t"; done | sort)"
  installed="$(find "$pkg_lib" -maxdepth 1 -type f -executable -printf '%f\n' 2>/dev/null | sort)"
  [ "$installed" = "$expected" ] ||
    problems+=("the installed tools are [$(echo $installed)], the user's tools (src/tools/) [$(echo $expected)]")
  for t in $expected; do
    [ ! -x "$pkg_lib/$t" ] || LD_LIBRARY_PATH="$libs" "$pkg_lib/$t" --help >/dev/null 2>&1 ||
      problems+=("lib/stereo_occupancy/$t --help fails with the install's libraries")
  done
  for f in "$prefix"/lib/*.so "$pkg_lib"/*; do
    [ -f "$f" ] || continue
    missing="$(LD_LIBRARY_PATH="$libs" ldd "$f" 2>/dev/null | grep 'not found' | awk '{print $1}' | tr '\n' ' ')"
    [ -z "$missing" ] || problems+=("${f#"$prefix"/} needs what the install lacks: $missing")
  done

  # --- Nothing of the bench --------------------------------------------------
  bench_names=()
  for t in "$repo"/bench/src/tools/*.cpp; do bench_names+=("$(name_of "$t")"); done
  for s in "$repo"/bench/scripts/*; do bench_names+=("${s##*/}"); done
  for n in "${bench_names[@]}"; do
    while IFS= read -r f; do problems+=("bench file installed: ${f#"$prefix"/}"); done \
      < <(find "$prefix" -name "$n")
  done
  while IFS= read -r f; do problems+=("bench library installed: ${f#"$prefix"/}"); done \
    < <(find "$prefix" -name 'libstereo_occupancy_sim*')
  while IFS= read -r h; do
    rel="${h#"$repo"/bench/include/}"
    [ ! -e "$prefix/include/$rel" ] || problems+=("bench header installed: include/$rel")
  done < <(find "$repo/bench/include" -type f)
  [ ! -e "$include/sim" ] || problems+=("bench folder installed: include/stereo_occupancy/sim")
  # What catkin exports to other packages (find_package, pkg-config).
  for f in "$share"/cmake/stereo_occupancyConfig.cmake "$prefix"/lib/pkgconfig/stereo_occupancy.pc; do
    if [ ! -f "$f" ]; then
      problems+=("missing: ${f#"$prefix"/}")
    elif grep -qE 'stereo_occupancy_sim|/bench/include' "$f"; then
      problems+=("${f#"$prefix"/} exports the bench: $(grep -ohE '[^ ";]*(stereo_occupancy_sim|/bench/include)[^ ";]*' "$f" | sort -u | tr '\n' ' ')")
    fi
  done
  echo "check_install: $(find "$prefix" -type f -o -type l | wc -l) entries installed; install log: $log"
fi

for p in "${problems[@]}"; do echo "check_install: $p"; done
echo "check_install: the product without the bench: ${#problems[@]} problems"
# shellcheck source=scripts/junit.sh
source "$repo/scripts/junit.sh"
[ -z "${RESULTS:-}" ] || junit "$RESULTS" install product_installed_without_bench \
  "$([ ${#problems[@]} = 0 ] || echo "${#problems[@]} problems: $(printf '%s; ' "${problems[@]}")")"
[ ${#problems[@]} = 0 ]
