#!/usr/bin/env bash
# Create (or re-create) a virtual CAN interface: sudo vcan/setup.sh [vcan0] [mtu]
set -euo pipefail
IFACE=${1:-vcan0}
if ! ip link show "$IFACE" >/dev/null 2>&1; then
  modprobe vcan 2>/dev/null || { echo "vcan/setup.sh: the vcan kernel module is not available (no SocketCAN here); use the default udp_multicast transport instead" >&2; exit 1; }
  ip link add dev "$IFACE" type vcan
fi
ip link set "$IFACE" up
echo "$IFACE is up"
