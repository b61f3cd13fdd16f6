#!/usr/bin/env bash
# Foresight set-up on a fresh Debian 12 machine (run as root):
# installs the Debian packages the project needs (a fast no-op when all are
# present), then configures and builds into ./build with Ninja.
#
#   scripts/setup.sh            install + configure + build everything (Release)
#   scripts/setup.sh T...       ... build only these targets and what they need
#                               (scripts/demo.sh: foresight foresight-remote foresight-linkemu)
#   FORESIGHT_WERROR=ON scripts/setup.sh   warnings as errors (CI)
#   FORESIGHT_BUILD_TESTS=OFF   tests and benchmarks out of `all` (default ON)
#
# ccache: used when the ccache command is installed (apt-get install ccache),
# never required; FORESIGHT_CCACHE=0 turns it off. A rebuild after touching one
# .cpp is seconds either way (ninja); ccache makes a clean rebuild or another
# build directory of the same sources fast.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  build-essential cmake pkg-config ninja-build
  libeigen3-dev liborocos-kdl-dev liburdfdom-dev libtinyxml-dev libconsole-bridge-dev libmodbus-dev
  cyclonedds-dev cyclonedds-tools libopencv-dev libosmesa6-dev
  libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri
  libgtest-dev libgmock-dev libyaml-cpp-dev libspdlog-dev libcli11-dev
  nlohmann-json3-dev libbenchmark-dev libssl-dev iproute2
  libsqlite3-dev sqlite3
  libsystemd-dev
  fastddsgen libfastrtps-dev
  clang libclang-rt-14-dev   # scripts/fuzz.sh (libFuzzer); the build itself stays GCC
  xvfb xdotool x11-apps
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${#missing[@]} missing package(s): ${missing[*]}"
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: need root to install packages (run as root or install them first)" >&2
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

BUILD_DIR=${FORESIGHT_BUILD_DIR:-build}
mkdir -p "$BUILD_DIR"
LAUNCHER=(-UCMAKE_CXX_COMPILER_LAUNCHER -UCMAKE_C_COMPILER_LAUNCHER)
if [[ ${FORESIGHT_CCACHE:-1} != 0 ]] && command -v ccache >/dev/null 2>&1; then
  LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  echo "setup: compiling through ccache ($(command -v ccache))"
fi
if ! cmake -S . -B "$BUILD_DIR" -G Ninja \
  -DCMAKE_BUILD_TYPE="${FORESIGHT_BUILD_TYPE:-Release}" \
  -DFORESIGHT_WERROR="${FORESIGHT_WERROR:-OFF}" \
  -DFORESIGHT_BUILD_TESTS="${FORESIGHT_BUILD_TESTS:-ON}" \
  "${LAUNCHER[@]}" -DPython3_EXECUTABLE=/usr/bin/python3 >"$BUILD_DIR/configure.log" 2>&1; then
  cat "$BUILD_DIR/configure.log" >&2
  echo "setup: cmake could not configure $BUILD_DIR (the log above)" >&2
  exit 1
fi
TARGETS=()
(($#)) && TARGETS=(--target "$@")
if ! cmake --build "$BUILD_DIR" -j2 "${TARGETS[@]}"; then
  echo "setup: the build failed (the compiler's message above; scripts/build_report.sh shows where the time went)" >&2
  exit 1
fi
