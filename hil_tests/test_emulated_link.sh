#!/usr/bin/env bash
# The whole link at the paper's delay: the real daemon (foresight-remote --sim)
# and the ground's CLI in two network namespaces joined by the link emulator at
# a 4 s round trip with 200 ms jitter and 1% loss. A 1,800 x 7 trajectory is
# uploaded, must arrive whole (COMMITTED, the remote's hash equal to the local
# one) and only then runs to COMPLETED at its last sample. Exit 77 (skipped)
# where network namespaces cannot be made.
source "$(dirname "$0")/lib.sh"
hil_begin emulink

# 18 s at 100 Hz: joint 1 from 0 to 0.1 rad.
min_jerk_joint1 1800 0.1 > "$work/traj.csv"

rc=0
linkemu_run "$BIN/foresight recover --domain 7 --connect-timeout 60 && $BIN/foresight send $work/traj.csv --run --json --domain 7 --connect-timeout 60 > $work/send.json" \
  --delay-ms 2000 --jitter-ms 200 --loss 0.01 || rc=$?
if [[ $rc -ne 0 ]]; then
  echo "the emulated-link session failed ($rc):"; cat "$work/session.log"; cat "$work/send.json" 2>/dev/null; exit 1
fi
cat "$work/send.json"
grep -Eq '"state": *"completed"' "$work/send.json" || { echo "not COMPLETED"; exit 1; }
# COMMITTED before the run: the journal holds the upload's verdict before the TRAJECTORY command.
"$BIN/foresight-remote" journal --db "$work/journal.db" --json > "$work/journal.json"
grep -q '"COMMITTED"' "$work/journal.json" || { echo "no COMMITTED upload in the journal"; exit 1; }
echo "ok"
