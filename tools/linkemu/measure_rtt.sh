#!/usr/bin/env bash
# The long run of the link emulator (too long for ctest): DDS Ping/Pong
# (linkemu_ddsping -> foresight_protocol_peer) across the emulated link at the
# paper's 4 s round trip, without and with 200 ms jitter and 1% loss, through
# scripts/linkemu_session.sh; then an 1800 x 7 trajectory upload (reliable
# chunks) until the remote reports COMMITTED with the same hash. Prints one
# JSON line per scenario and the emulator's statistics. About 3 minutes.
# Numbers are in docs/linkemu.md.
#
#   tools/linkemu/measure_rtt.sh [COUNT]      (default 100 pings, 200 ms apart)
#
# Environment: FORESIGHT_BIN_DIR (default build/bin). Exit 77 where network
# namespaces are not permitted.
set -eu
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
bin="${FORESIGHT_BIN_DIR:-$here/build/bin}"
export FORESIGHT_BIN_DIR="$bin"
count="${1:-100}"
for scenario in "--delay-ms 2000" "--delay-ms 2000 --jitter-ms 200 --loss 0.01"; do
  echo "== foresight-linkemu $scenario"
  # shellcheck disable=SC2086  # the scenario is a list of options
  "$here/scripts/linkemu_session.sh" $scenario \
    --remote "$bin/foresight_protocol_peer --domain 7 --lifetime-s 600" \
    --ground "$bin/linkemu_ddsping --domain 7 --count $count --interval-ms 200 --discovery-timeout-s 60 --pong-timeout-s 15 --upload-samples 1800 --upload-timeout-s 300" \
    2> >(grep -v '^linkemu_session: link up' >&2)
done
