#!/usr/bin/env bash
# The main job: for now the most complete end-to-end run that exists (it grows
# into `foresight demo`, the ORU changeout on the embedded simulated robot).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
B=${FORESIGHT_BUILD_DIR:-build}/bin
echo "== foresight: robot model =="
"$B/foresight" --help
