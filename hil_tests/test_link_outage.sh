#!/usr/bin/env bash
# The link drops mid-trajectory and returns (issue 13's fault campaign, through
# the real link): the daemon (foresight-remote --sim) and the ground CLI in two
# network namespaces joined by the link emulator (400 ms round trip). A 15 s
# trajectory is uploaded and started; once the arm is moving the emulator cuts
# the link both ways (SIGUSR1) for longer than the remote's loss timeout
# (config/remote.yaml controller.link: loss_timeout_s 3, policy finish_and_hold),
# then restores it (SIGUSR2). Checked:
#   - the remote declared the link lost while the trajectory was still running,
#     and regained once it came back (journal events, in that order);
#   - the committed trajectory ran to its end (finish_and_hold): the ground's
#     `send --run` got COMPLETED through the restored link, at the last sample;
#   - no fault and no stop was journaled, and every command has its outcome;
#   - the task goes on: a new motion from the ground completes.
# Exit 77 (skipped) where network namespaces cannot be made.
source "$(dirname "$0")/lib.sh"
hil_begin outage

# 15 s at 100 Hz: joint 1 from 0 to 0.3 rad.
min_jerk_joint1 1500 0.3 > "$work/traj.csv"

# Run inside the ground namespace by linkemu_session.sh (LINKEMU_PID set).
cat > "$work/ground.sh" <<EOF
set -euo pipefail
journal() { "$BIN/foresight-remote" journal --db "$work/journal.db" 2>/dev/null || true; }
# wait_for WHAT SECONDS COMMAND...: polls COMMAND every 0.1 s until it succeeds.
wait_for() {
  local what=\$1 limit=\$2; shift 2
  for ((i = 0; i < limit * 10; i++)); do "\$@" && return 0; sleep 0.1; done
  echo "outage test: timed out after \${limit} s waiting for \$what" >&2; return 1
}
moving() { journal | grep -Eq 'TRAJECTORY +EXECUTING'; }
has_event() { journal | grep -Eq "^ +[^ ]+ +\$1 "; }
# The first link_regained is the start-up's (the ground first seen): wait for a second.
regained_again() { [ "\$(journal | grep -Ec '^ +[^ ]+ +link_regained ')" -ge 2 ]; }

"$BIN/foresight" recover --domain 7 --connect-timeout 60 > /dev/null
"$BIN/foresight" send "$work/traj.csv" --run --json --domain 7 --connect-timeout 60 > "$work/send.json" &
send_pid=\$!
wait_for "the trajectory to start" 120 moving
kill -USR1 "\$LINKEMU_PID"
echo "outage test: link cut at \$(date -u +%H:%M:%S.%N)" >&2
wait_for "the remote to declare the link lost" 30 has_event link_lost
kill -USR2 "\$LINKEMU_PID"
echo "outage test: link restored at \$(date -u +%H:%M:%S.%N)" >&2
wait_for "the remote to regain the link" 30 regained_again
wait "\$send_pid"
# The task goes on: back to zero, sent after the outage.
"$BIN/foresight" goto --joints 0,0,0,0,0,0,0 --speed 0.2 --domain 7 --connect-timeout 60 --json > "$work/goto.json"
journal > "$work/journal.txt"  # before the session's end stops the daemon (its SIGTERM stop is journaled)
EOF

rc=0
linkemu_run "bash $work/ground.sh" --delay-ms 200 || rc=$?
[[ -s "$work/journal.txt" ]] || "$BIN/foresight-remote" journal --db "$work/journal.db" > "$work/journal.txt" 2>&1 || true
fail() {
  echo "FAIL: $*"; echo "--- session"; cat "$work/session.log"; echo "--- send"; cat "$work/send.json" 2>/dev/null
  echo "--- journal"; cat "$work/journal.txt"; exit 1
}
[[ $rc -eq 0 ]] || fail "the session failed ($rc)"
cat "$work/send.json"
grep -Eq '"state": *"completed"' "$work/send.json" || fail "the trajectory did not complete through the outage"
grep -Eq '"state": *"completed"' "$work/goto.json" || fail "the motion after the outage did not complete"
# At its last sample: joint 1 at 0.3 rad (the first final_q_rad value).
awk '/"final_q_rad"/ { getline; v = $1 + 0; exit !(v > 0.298 && v < 0.302) }' "$work/send.json" ||
  fail "the trajectory did not end at its last sample (q1 = 0.3 rad)"

# Order in the journal: lost while the trajectory executed, regained, then
# the trajectory's completion after the loss (the table's times are ISO 8601 UTC).
t_of() { grep -E "$1" "$work/journal.txt" | head -1 | awk '{ print $1 }'; }
lost=$(t_of '^ +[^ ]+ +link_lost ')
# (the first link_regained comes at start-up, when the ground first appears)
regained=$(grep -E '^ +[^ ]+ +link_regained ' "$work/journal.txt" | awk -v lost="$lost" '$1 > lost { print $1; exit }')
executing=$(t_of 'TRAJECTORY +EXECUTING')
completed=$(t_of 'TRAJECTORY +COMPLETED')
[[ -n $lost && -n $regained && -n $executing && -n $completed ]] ||
  fail "missing journal rows (lost '$lost', regained '$regained', executing '$executing', completed '$completed')"
[[ $executing < $lost ]] || fail "the link was lost ($lost) before the trajectory ran ($executing)"
[[ $lost < $completed ]] || fail "the trajectory completed ($completed) before the link was lost ($lost): not mid-trajectory"
grep -Eq '^faults: 0$' "$work/journal.txt" || fail "a fault was journaled"
# Every command the ground sent has its outcome: none is left received/queued/executing only.
awk '/^commands:/ { on = 1; next } /^$/ { on = 0 } on && $2 ~ /^[0-9]+$/ { key = $2 "/" $3; last[key] = $6 }
     END { for (k in last) if (last[k] != "COMPLETED") { print "command " k " ended " last[k]; bad = 1 } exit bad }' \
  "$work/journal.txt" || fail "a command without a final outcome"
grep -q 'dropped_outage' "$work/session.log" || fail "no emulator statistics"
echo "ok"
