#!/usr/bin/env bash
# Brings the cabinet's SocketCAN interfaces up for foresight-remote:
# bit rate (must equal `buses[].bitrate` in /etc/foresight/remote.yaml),
# restart-ms (automatic recovery from bus-off after that many ms), and the
# transmit queue length (a 500 Hz cycle writes ~9 frames at once per bus;
# the default 10 can overflow with ENOBUFS while the bus is busy).
#
#   can-setup.sh [--dry-run] [--bitrate BPS] [--restart-ms MS] [--txqueuelen N] IF...
#   can-setup.sh can0 can1                     1 Mbit/s, restart-ms 100, txqueuelen 1000
#
# --dry-run prints the ip commands instead of running them. Needs root and a
# kernel with CAN (CONFIG_CAN, CONFIG_CAN_RAW, the adapter's driver). Installed
# as /usr/lib/foresight/can-setup.sh; foresight-can.service runs it at boot
# (or use the systemd-networkd files beside it instead). docs/deploy.md.
set -euo pipefail

dry=0
bitrate=1000000
restart_ms=100
txqueuelen=1000
ifaces=()
while (($#)); do
  case $1 in
    --dry-run) dry=1 ;;
    --bitrate) bitrate=${2:?--bitrate needs a value}; shift ;;
    --restart-ms) restart_ms=${2:?--restart-ms needs a value}; shift ;;
    --txqueuelen) txqueuelen=${2:?--txqueuelen needs a value}; shift ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    -*) echo "can-setup.sh: unknown option $1" >&2; exit 2 ;;
    *) ifaces+=("$1") ;;
  esac
  shift
done
((${#ifaces[@]})) || { echo "usage: can-setup.sh [--dry-run] [--bitrate BPS] [--restart-ms MS] [--txqueuelen N] IF..." >&2; exit 2; }
case $bitrate in
  10000|20000|50000|100000|125000|250000|500000|800000|1000000) ;;
  *) echo "can-setup.sh: bit rate $bitrate is not one of 10000 20000 50000 100000 125000 250000 500000 800000 1000000" >&2; exit 2 ;;
esac
[[ $restart_ms =~ ^[0-9]+$ ]] || { echo "can-setup.sh: restart-ms '$restart_ms' is not a number" >&2; exit 2; }
[[ $txqueuelen =~ ^[0-9]+$ && $txqueuelen -ge 1 ]] || { echo "can-setup.sh: txqueuelen '$txqueuelen' is not a positive number" >&2; exit 2; }

run() {
  if ((dry)); then echo "$*"; else "$@"; fi
}

for ifc in "${ifaces[@]}"; do
  [[ $ifc =~ ^[A-Za-z0-9_.-]{1,15}$ ]] || { echo "can-setup.sh: '$ifc' is not an interface name" >&2; exit 2; }
  if ((!dry)) && [[ ! -e /sys/class/net/$ifc ]]; then
    echo "can-setup.sh: no interface $ifc (adapter, driver, kernel CAN support?)" >&2
    exit 1
  fi
  # The bit timing can only change while the interface is down.
  run ip link set "$ifc" down
  run ip link set "$ifc" type can bitrate "$bitrate" restart-ms "$restart_ms"
  run ip link set "$ifc" txqueuelen "$txqueuelen"
  run ip link set "$ifc" up
done
if ((!dry)); then
  for ifc in "${ifaces[@]}"; do ip -details -brief link show "$ifc" || true; done
fi
