#!/usr/bin/env bash
# Runs a remote command and a ground command in the two network namespaces of
# a fresh foresight-linkemu link, then removes everything (also on Ctrl-C,
# SIGTERM, or a failed command; if this script is SIGKILLed, the emulator and
# both commands get SIGTERM from the kernel (--exit-with-parent), and the
# emulator still removes its namespaces).
#
#   scripts/linkemu_session.sh [EMULATOR OPTIONS...] --remote 'CMD' --ground 'CMD'
#
# EMULATOR OPTIONS are foresight-linkemu's (--delay-ms 2000 --jitter-ms 200
# --loss 0.01 --rate-kbit 512 ...; see docs/linkemu.md). The remote command
# starts first, in the background; the ground command runs until it ends, and
# its exit status is the script's. Both see CYCLONEDDS_URI set for the link,
# and LINKEMU_GROUND_NS, LINKEMU_REMOTE_NS, LINKEMU_PID (the emulator: SIGUSR1
# takes the link down, SIGUSR2 brings it back). A "link up" line and, at the end,
# the emulator's statistics (one JSON line) go to stderr.
#
# Exit status: the ground command's; 77 when namespaces are not permitted here
# (the emulator's reason is printed); 2 for bad usage; 1 if the link did not
# come up.
#
# Environment: FORESIGHT_BIN_DIR (default: build/bin beside this script),
# LINKEMU_READY_TIMEOUT_S (default 30).
set -u

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="${FORESIGHT_BIN_DIR:-$here/build/bin}"
emu="$bin/foresight-linkemu"
ready_timeout_s="${LINKEMU_READY_TIMEOUT_S:-30}"

usage() {
  echo "linkemu_session: $1" >&2
  echo "usage: scripts/linkemu_session.sh [EMULATOR OPTIONS...] --remote 'CMD' --ground 'CMD'" >&2
  exit 2
}

emu_opts=()
remote_cmd=""
ground_cmd=""
while [ $# -gt 0 ]; do
  case "$1" in
    --remote) [ $# -ge 2 ] || usage "--remote wants a command"; remote_cmd="$2"; shift 2 ;;
    --ground) [ $# -ge 2 ] || usage "--ground wants a command"; ground_cmd="$2"; shift 2 ;;
    --exit-with-parent) shift ;;
    -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
    *) emu_opts+=("$1"); shift ;;
  esac
done
[ -n "$ground_cmd" ] || usage "--ground 'CMD' is required"
[ -x "$emu" ] || usage "no $emu (build it: ninja -C build foresight-linkemu, or set FORESIGHT_BIN_DIR)"

work="$(mktemp -d /tmp/linkemu_session.XXXXXX)"
emu_pid=""
remote_pid=""
ground_pid=""

# Stops one of our own processes (a process group for the commands, so their
# children go too): SIGTERM, then SIGKILL after `grace` seconds.
stop_pid() {
  local pid="$1" group="$2" grace="$3" i
  [ -n "$pid" ] || return 0
  kill -0 "$pid" 2>/dev/null || return 0
  if [ "$group" = yes ]; then kill -TERM -- "-$pid" 2>/dev/null; else kill -TERM "$pid" 2>/dev/null; fi
  for ((i = 0; i < grace * 10; i++)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  if [ "$group" = yes ]; then kill -KILL -- "-$pid" 2>/dev/null; else kill -KILL "$pid" 2>/dev/null; fi
}

cleanup() {
  trap - EXIT INT TERM HUP
  # 8 s: longer than the exec wrapper's own 3 s before it SIGKILLs the command.
  stop_pid "$ground_pid" yes 8
  stop_pid "$remote_pid" yes 8
  # The emulator removes its namespaces on SIGTERM; give it time to.
  stop_pid "$emu_pid" no 10
  [ -n "$emu_pid" ] && wait "$emu_pid" 2>/dev/null
  if [ -s "$work/emu.out" ]; then
    grep '"event":"stats"' "$work/emu.out" | sed 's/^/linkemu_session: /' >&2
  fi
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
trap 'exit 129' HUP

"$emu" "${emu_opts[@]}" --exit-with-parent >"$work/emu.out" 2>"$work/emu.err" &
emu_pid=$!

ready=""
for ((i = 0; i < ready_timeout_s * 10; i++)); do
  ready="$(grep -m1 '"event":"ready"' "$work/emu.out" 2>/dev/null || true)"
  [ -n "$ready" ] && break
  if ! kill -0 "$emu_pid" 2>/dev/null; then
    wait "$emu_pid"
    rc=$?
    cat "$work/emu.err" >&2
    emu_pid=""
    if [ "$rc" -eq 77 ]; then
      echo "linkemu_session: network namespaces are not permitted here (see above); skipping" >&2
      exit 77
    fi
    echo "linkemu_session: the link emulator exited with status $rc before it was ready" >&2
    exit "$([ "$rc" -eq 2 ] && echo 2 || echo 1)"
  fi
  sleep 0.1
done
if [ -z "$ready" ]; then
  cat "$work/emu.err" >&2
  echo "linkemu_session: the link emulator was not ready within ${ready_timeout_s} s" >&2
  exit 1
fi

field() { printf '%s' "$ready" | sed -n "s/.*\"$1\":\"\([^\"]*\)\".*/\1/p"; }
LINKEMU_GROUND_NS="$(field ground_netns)"
LINKEMU_REMOTE_NS="$(field remote_netns)"
LINKEMU_PID="$emu_pid"  # kill -USR1 / -USR2: link down / up (docs/linkemu.md)
export LINKEMU_GROUND_NS LINKEMU_REMOTE_NS LINKEMU_PID
echo "linkemu_session: link up: ground $LINKEMU_GROUND_NS ($(field ground_address)), remote $LINKEMU_REMOTE_NS ($(field remote_address)); emulator options: ${emu_opts[*]:-none}" >&2

if [ -n "$remote_cmd" ]; then
  setsid "$emu" exec "$LINKEMU_REMOTE_NS" --exit-with-parent -- /bin/sh -c "$remote_cmd" &
  remote_pid=$!
fi
setsid "$emu" exec "$LINKEMU_GROUND_NS" --exit-with-parent -- /bin/sh -c "$ground_cmd" &
ground_pid=$!
wait "$ground_pid"
status=$?
ground_pid=""
exit "$status"
