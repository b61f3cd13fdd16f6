#!/usr/bin/env bash
# Where the build time goes, from a build's own .ninja_log (no rebuild):
#
#   scripts/build_report.sh [BUILD_DIR]     default: build (or $FORESIGHT_BUILD_DIR)
#
# Prints
#   1. the step-seconds (the sum of every compile and link step's own wall time,
#      as ninja logged it: on 2 cores the wall time of a cold build is about
#      half of it) per target (library, executable, test), largest first;
#   2. the ten slowest steps (files);
#   3. the step-seconds of what the demo's three executables need
#      (foresight, foresight-remote, foresight-linkemu: every step `ninja -t
#      inputs` reaches from them), against the target of at most 900.
# Only the last run of each output counts (a rebuilt file replaces its earlier
# entry). A build interrupted or partly from ccache shows what was logged: ccache
# hits are fast steps, so measure a cold build with CCACHE_DISABLE=1.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-${FORESIGHT_BUILD_DIR:-build}}
LOG=$BUILD/.ninja_log
if [[ ! -f $LOG ]]; then
  echo "build_report: no $LOG (build first: scripts/setup.sh, or give the build directory)" >&2
  exit 2
fi
if ! head -n1 "$LOG" | grep -q '^# ninja log v[56]'; then
  echo "build_report: $LOG is not a ninja log (first line: $(head -n1 "$LOG"))" >&2
  exit 2
fi
DEMO_TARGETS=(foresight foresight-remote foresight-linkemu)

# The last entry per output: output <TAB> seconds.
steps=$(mktemp)
need=$(mktemp)
trap 'rm -f "$steps" "$need"' EXIT
awk -F'\t' 'NR > 1 && NF >= 4 { t[$4] = ($2 - $1) / 1000.0 }
  END { for (o in t) printf "%s\t%.3f\n", o, t[o] }' "$LOG" >"$steps"
if [[ ! -s $steps ]]; then
  echo "build_report: $LOG holds no steps" >&2
  exit 2
fi

# Target of a step from its output path: <dir>/CMakeFiles/<target>.dir/... for
# objects, bin/<name>, bench/<name> and lib<name>.a / lib<name>.so for links.
target_of='
function target(o,   m, n) {
  if (match(o, /CMakeFiles\/[^\/]+\.dir\//)) { n = substr(o, RSTART + 11, RLENGTH - 16); return n }
  n = o; sub(/.*\//, "", n)
  if (n ~ /\[[0-9]+\]_tests\.cmake$/) { sub(/\[[0-9]+\]_tests\.cmake$/, "", n); return n }
  if (n ~ /^lib.*\.(a|so)$/) { sub(/^lib/, "", n); sub(/\.(a|so)$/, "", n); return n }
  if (o ~ /(^|\/)(bin|bench)\//) return n
  return "(other: " n ")"
}'

total=$(awk -F'\t' '{ s += $2 } END { printf "%.0f", s }' "$steps")
count=$(wc -l <"$steps")
echo "== build report: $LOG ($count steps, $total step-seconds)"
echo
echo "-- step-seconds per target (compile + link), largest first"
awk -F'\t' "$target_of"' { s[target($1)] += $2; n[target($1)]++ }
  END { for (t in s) printf "%8.1f  %4d  %s\n", s[t], n[t], t }' "$steps" | sort -rn | head -n 40
echo "   (step-seconds, steps, target; the 40 largest)"
echo
echo "-- the ten slowest steps"
sort -t$'\t' -k2,2 -rn "$steps" | head -n 10 | awk -F'\t' '{ printf "%8.1f  %s\n", $2, $1 }'
echo
if ninja -C "$BUILD" -t inputs "${DEMO_TARGETS[@]}" >"$need" 2>/dev/null; then
  for t in "${DEMO_TARGETS[@]}"; do echo "bin/$t" >>"$need"; done
  awk -F'\t' 'NR == FNR { want[$1] = 1; next } ($1 in want) { s += $2; n++ }
    END { printf "-- the demo executables (%s) need %d steps, %.0f step-seconds (target: at most 900)\n", \
          names, n, s }' names="${DEMO_TARGETS[*]}" "$need" "$steps"
else
  echo "-- the demo executables: ninja -t inputs failed (is $BUILD configured?)"
fi
