# Shared by the shell HIL tests (sourced): the work folder, a known trajectory,
# and the emulated-link session with the real daemon.
#   hil_begin NAME                 BIN, SRC and a work folder removed on exit
#   min_jerk_joint1 N AMPLITUDE    N samples at 100 Hz: joint 1 from 0 to
#                                  AMPLITUDE rad along a minimum-jerk profile
#                                  (the simulated arm starts at zero), the
#                                  other joints still; CSV on stdout
#   linkemu_run GROUND_CMD LINKEMU_ARGS...
#                                  foresight-remote --sim (journal in the work
#                                  folder, domain 7) and GROUND_CMD in two
#                                  namespaces joined by the link emulator; the
#                                  session's stderr in $work/session.log; exits
#                                  77 (skipped) where namespaces cannot be made,
#                                  else returns the session's exit code.

hil_begin() {
  set -euo pipefail
  BIN=${FORESIGHT_BIN_DIR:?}
  SRC=${FORESIGHT_SOURCE_DIR:?}
  work=$(mktemp -d "/tmp/foresight_$1_XXXXXX")
  trap 'rm -rf "$work"' EXIT
}

min_jerk_joint1() {
  awk -v n="$1" -v a="$2" 'BEGIN { print "t,q1,q2,q3,q4,q5,q6,q7";
    for (i = 0; i < n; i++) { s = i / (n - 1); p = 10*s^3 - 15*s^4 + 6*s^5;
      printf "%.2f,%.9f,0,0,0,0,0,0\n", i * 0.01, a * p } }'
}

linkemu_run() {
  local ground=$1 rc
  shift
  set +e
  bash "$SRC/scripts/linkemu_session.sh" "$@" \
    --remote "$BIN/foresight-remote --sim --journal $work/journal.db --domain 7" \
    --ground "$ground" 2> "$work/session.log"
  rc=$?
  set -e
  if [[ $rc -eq 77 ]]; then
    echo "skipped: $(tail -1 "$work/session.log")"
    exit 77
  fi
  return $rc
}
