#!/usr/bin/env bash
# The whole link at the paper's delay: the real daemon (foresight-remote --sim)
# and the ground's CLI in two network namespaces joined by the link emulator at
# a 4 s round trip with 200 ms jitter and 1% loss. A 1,800 x 7 trajectory is
# uploaded, must arrive whole (COMMITTED, the remote's hash equal to the local
# one) and only then runs to COMPLETED at its last sample. Exit 77 (skipped)
# where network namespaces cannot be made.
set -euo pipefail
BIN=${FORESIGHT_BIN_DIR:?}
SRC=${FORESIGHT_SOURCE_DIR:?}
work=$(mktemp -d /tmp/foresight_emulink_XXXXXX)
trap 'rm -rf "$work"' EXIT

# 18 s at 100 Hz: joint 1 from 0 to 0.1 rad along a minimum-jerk profile (the
# simulated arm starts at zero), the other joints still.
awk 'BEGIN { print "t,q1,q2,q3,q4,q5,q6,q7";
  for (i = 0; i < 1800; i++) { s = i / 1799; p = 10*s^3 - 15*s^4 + 6*s^5;
    printf "%.2f,%.9f,0,0,0,0,0,0\n", i * 0.01, 0.1 * p } }' > "$work/traj.csv"

set +e
bash "$SRC/scripts/linkemu_session.sh" --delay-ms 2000 --jitter-ms 200 --loss 0.01 \
  --remote "$BIN/foresight-remote --sim --journal $work/journal.db --domain 7" \
  --ground "$BIN/foresight recover --domain 7 --connect-timeout 60 && $BIN/foresight send $work/traj.csv --run --json --domain 7 --connect-timeout 60 > $work/send.json" \
  2> "$work/session.log"
rc=$?
set -e
if [[ $rc -eq 77 ]]; then
  echo "skipped: $(tail -1 "$work/session.log")"
  exit 77
fi
if [[ $rc -ne 0 ]]; then
  echo "the emulated-link session failed ($rc):"; cat "$work/session.log"; cat "$work/send.json" 2>/dev/null; exit 1
fi
cat "$work/send.json"
grep -Eq '"state": *"completed"' "$work/send.json" || { echo "not COMPLETED"; exit 1; }
# COMMITTED before the run: the journal holds the upload's verdict before the TRAJECTORY command.
"$BIN/foresight-remote" journal --db "$work/journal.db" --json > "$work/journal.json"
grep -q '"COMMITTED"' "$work/journal.json" || { echo "no COMMITTED upload in the journal"; exit 1; }
echo "ok"
