#!/usr/bin/env bash
# Remove a virtual CAN interface: sudo vcan/teardown.sh [vcan0]
set -euo pipefail
IFACE=${1:-vcan0}
if ip link show "$IFACE" >/dev/null 2>&1; then
  ip link set "$IFACE" down
  ip link delete "$IFACE"
  echo "$IFACE removed"
else
  echo "$IFACE does not exist"
fi
