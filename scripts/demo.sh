#!/usr/bin/env bash
# The main job: `foresight demo` -- the ORU changeout (Kim 1996) end to end on
# the synthetic work site (config/scene.yaml) with a simulated operator:
#
#   1. the controller daemon `foresight-remote --sim` (the embedded simulated
#      robot: CiA 402 drives on a mock CAN bus, F/T sensor, LST over Modbus) on
#      a fresh DDS domain, through the link emulator at a 4 s round trip where
#      network namespaces can be made (as root), else on loopback (it says so);
#   2. the simulated operator clicks on the arm (4 arm poses) and the ORU in
#      four camera views (1 px noise);
#   3. each camera calibrated with the arm as the fixture (the paper's two-step
#      method); the ORU localized from all four views; the calibrated overlay;
#   4. the changeout task script (config/scripts/oru_changeout.task, the
#      paper's 17 steps) over DDS, every motion previewed before it is sent;
#   5. report.json and report.md (steps, calibration, localization, the
#      re-inserted ORU's alignment from the simulator's truth, the delay);
#   6. the accuracy study (Monte Carlo of the paper's tables, with the bound).
#
# Everything is written to $FORESIGHT_DEMO_DIR (default build/demo).
# FORESIGHT_DEMO_ARGS adds options to `foresight demo` (e.g. "--fast", "--rtt 1").
set -euo pipefail
cd "$(dirname "$0")/.."
# Only what the demo runs (the tests and benchmarks build in scripts/test.sh).
bash scripts/setup.sh foresight foresight-remote foresight-linkemu
BUILD=${FORESIGHT_BUILD_DIR:-build}
F="$PWD/$BUILD/bin/foresight"
OUT=${FORESIGHT_DEMO_DIR:-$BUILD/demo}
rm -rf "$OUT"
mkdir -p "$OUT"

# The changeout twice: step by step (every step waits for the one before to be
# acknowledged), then with the motions sent ahead as chains; the second
# report shows both timings side by side (report.md, "Timing").
printf '== the changeout step by step (for comparison): %s/step_by_step ==\n' "$OUT"
# shellcheck disable=SC2086
"$F" demo --out "$OUT/step_by_step" ${FORESIGHT_DEMO_ARGS:-}
printf '\n== the changeout with its motions sent ahead as chains (--chain): %s ==\n' "$OUT"
# shellcheck disable=SC2086
"$F" demo --chain --compare "$OUT/step_by_step/report.json" --out "$OUT" ${FORESIGHT_DEMO_ARGS:-}

printf '\n== accuracy study: the paper'"'"'s Tables 1-3 beside the Cramer-Rao bound (200 trials, 1 px) ==\n'
"$F" eval localization --trials 200 --noise-px 1 >"$OUT/eval_localization.txt" 2>/dev/null
tail -n 3 "$OUT/eval_localization.txt"

printf '\n== done: %s/report.md ==\n' "$OUT"
