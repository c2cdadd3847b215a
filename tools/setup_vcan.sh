#!/bin/sh
# Set up a virtual SocketCAN interface on a Linux host whose kernel has CAN support.
#
#   tools/setup_vcan.sh [IFACE]          (default vcan0; uses sudo when not root)
#
# Then, e.g.:
#   suspid node --scenario bump --interface socketcan --channel vcan0 &
#   candump -L vcan0            # can-utils, to watch the frames
#   python -m pytest -m socketcan
#
# Containers and minimal VMs often lack the vcan module (or AF_CAN altogether): there
# tools/vcan_bench.sh COMMAND runs COMMAND with vcan0 up inside User-Mode Linux (it calls
# this script itself on a host that has SocketCAN), e.g.
#   tools/vcan_bench.sh .venv/bin/python -m pytest -m socketcan
set -eu
IFACE="${1:-vcan0}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

if ! command -v ip >/dev/null 2>&1; then
    echo "error: the 'ip' command (iproute2) is missing; install it first" >&2
    exit 1
fi
if ! $SUDO modprobe vcan 2>/dev/null; then
    if ! grep -qw vcan /proc/modules 2>/dev/null; then
        echo "error: cannot load the vcan kernel module (kernel without CAN/vcan support?)" >&2
        exit 1
    fi
fi
if ip link show "$IFACE" >/dev/null 2>&1; then
    echo "$IFACE already exists"
else
    $SUDO ip link add dev "$IFACE" type vcan
fi
$SUDO ip link set up "$IFACE"
ip -details link show "$IFACE"
echo "ok: $IFACE is up; use --interface socketcan --channel $IFACE"
