#!/usr/bin/env bash
# Foresight set-up on a fresh Debian 12 machine (run as root):
# installs the Debian packages the project needs (a fast no-op when all are
# present), then configures and builds into ./build with Ninja.
#
#   scripts/setup.sh            install + configure + build (Release)
#   FORESIGHT_WERROR=ON scripts/setup.sh   warnings as errors (CI)
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
cmake -S . -B "$BUILD_DIR" -G Ninja \
  -DCMAKE_BUILD_TYPE="${FORESIGHT_BUILD_TYPE:-Release}" \
  -DFORESIGHT_WERROR="${FORESIGHT_WERROR:-OFF}" \
  -DPython3_EXECUTABLE=/usr/bin/python3 >/dev/null
cmake --build "$BUILD_DIR" -j2
