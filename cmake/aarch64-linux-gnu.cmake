# CMake toolchain: aarch64 Linux with Debian's cross compiler (g++-aarch64-linux-gnu).
#
# AARCH64_SYSROOT (cache variable or environment variable): a directory holding
# the arm64 packages' files, as scripts/cross_aarch64.sh extracts them; headers,
# libraries and CMake packages are then looked up there only. Unset, or "/":
# the arm64 packages installed with multiarch (apt-get install foo:arm64).
#
# Tests run with CMAKE_CROSSCOMPILING_EMULATOR, qemu-aarch64 with that root.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

if(NOT DEFINED AARCH64_SYSROOT AND DEFINED ENV{AARCH64_SYSROOT})
  set(AARCH64_SYSROOT "$ENV{AARCH64_SYSROOT}")
endif()
# try_compile() projects read the toolchain file again: give them the root too.
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES AARCH64_SYSROOT)

if(AARCH64_SYSROOT AND NOT AARCH64_SYSROOT STREQUAL "/")
  # The compiler's own libc and libstdc++ (/usr/aarch64-linux-gnu) come first;
  # --sysroot replaces /usr/include and the library directories by the root's,
  # so no amd64 header in /usr/include is seen.
  set(CMAKE_SYSROOT "${AARCH64_SYSROOT}")
  set(CMAKE_FIND_ROOT_PATH "${AARCH64_SYSROOT}")
  # The libraries' own dependencies (OpenCV's GDAL, ...) are resolved in the root
  # as well; some of them live in /usr/lib (not multiarch).
  set(_aarch64_rpath_link "${AARCH64_SYSROOT}/lib/aarch64-linux-gnu:${AARCH64_SYSROOT}/usr/lib/aarch64-linux-gnu:${AARCH64_SYSROOT}/usr/lib")
  foreach(kind EXE SHARED MODULE)
    set(CMAKE_${kind}_LINKER_FLAGS_INIT "-Wl,-rpath-link,${_aarch64_rpath_link}")
  endforeach()
  set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64 -L "${AARCH64_SYSROOT}")
else()
  set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64 -L /usr/aarch64-linux-gnu)
endif()

# Programs (cmake's own tools, pkg-config) from the host; the rest from the target.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
