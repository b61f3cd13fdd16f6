#!/usr/bin/env bash
# Set up (packages, configure, build) and run every test with ctest.
# CI sets FORESIGHT_WERROR=ON (warnings are errors there).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
ctest --test-dir "${FORESIGHT_BUILD_DIR:-build}" --output-on-failure -j2 --timeout 900
