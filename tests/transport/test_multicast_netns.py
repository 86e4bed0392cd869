"""python-can's own udp_multicast bus and lowerbase's, both ways, as python-can's docs open it
(hop limit 0, the default multicast interface), in a network namespace of the test's own.

The namespace (``unshare --net``, root only) has loopback and a veth pair of its own, v0 and
v1, with the multicast route on v0: v0 plays the host's network interface, v1 another host on
that network. So lowerbase's join on the default interface (IGMP) and every datagram stay on
the project's own virtual devices. Checked inside:

- python-can's default sender (on v0) reaches lowerbase (``recv`` and ``recv_frame``), and
  lowerbase reaches python-can;
- a datagram from "another host" (sent on v1 with TTL 1, arriving on v0 from the network) is
  dropped in the kernel: nothing from outside this host.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time

import can
import pytest
from can.interfaces.udp_multicast.bus import UdpMulticastBus
from can.interfaces.udp_multicast.utils import pack_message

from lowerbase.transport import open_bus
from tests.conftest import ROOT, TEST_GROUP

PORT = 43199
SETUP = ("ip link set lo up && ip link add v0 type veth peer name v1 && ip link set v0 up && "
         "ip link set v1 up && ip addr add 10.213.0.1/24 dev v0 && "
         "ip addr add 10.213.0.2/24 dev v1 && ip route add 224.0.0.0/4 dev v0 && "
         # v1's address is this namespace's own: let v0 take it from the wire as a foreign one
         "sysctl -q -w net.ipv4.conf.all.rp_filter=0 net.ipv4.conf.v0.rp_filter=0 "
         "net.ipv4.conf.v0.accept_local=1")


def _namespace_problem() -> str | None:
    if sys.platform != "linux" or shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs Linux with unshare and ip (iproute2)"
    probe = subprocess.run(["unshare", "--net", "sh", "-c", SETUP], capture_output=True,
                           text=True, timeout=60)
    if probe.returncode != 0:
        why = (probe.stderr.strip().splitlines() or ["?"])[-1]
        return f"cannot make a network namespace with a veth pair here (root needed): {why}"
    return None


def test_python_cans_default_sender_and_lowerbase_in_a_namespace_of_their_own() -> None:
    if (reason := _namespace_problem()) is not None:
        pytest.skip(reason)
    env = {k: v for k, v in os.environ.items() if k != "LOWERBASE_MULTICAST_JOIN"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    run = subprocess.run(
        ["unshare", "--net", "sh", "-c",
         f"{SETUP} && exec {sys.executable} -m tests.transport.test_multicast_netns"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"in the namespace:\n{run.stdout}\n{run.stderr}"
    assert run.stdout.strip().splitlines()[-1] == "ok"


# -- what runs inside the namespace ------------------------------------------------------------


def _recv_all(bus: can.BusABC, timeout: float) -> list[tuple[int, bytes]]:
    got = []
    while (msg := bus.recv(timeout)) is not None:
        got.append((msg.arbitration_id, bytes(msg.data)))
    return got


def _from_another_host(arbitration_id: int) -> None:
    """A frame sent on v1 (another host on v0's network), TTL 1 so it crosses the wire."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("10.213.0.2"))
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 0)
        msg = can.Message(arbitration_id=arbitration_id, data=b"\xee", is_extended_id=False)
        s.sendto(pack_message(msg), (TEST_GROUP, PORT))


def main() -> None:
    os.environ.pop("LOWERBASE_MULTICAST_JOIN", None)  # tests.conftest's, imported above
    config = {"interface": "udp_multicast", "channel": TEST_GROUP, "port": PORT, "hop_limit": 0}
    ours = open_bus(config)
    theirs = UdpMulticastBus(channel=TEST_GROUP, port=PORT, hop_limit=0)  # as python-can's docs
    try:
        assert ours._multicast.host_only == socket.if_nametoindex("lo"), "no host-only filter"  # type: ignore[attr-defined]
        # python-can sends on the default multicast interface (v0), not on loopback
        assert socket.inet_ntoa(theirs._multicast._socket.getsockopt(
            socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)) == "0.0.0.0"
        _from_another_host(0x666)  # first, so that it would be first in the queue
        theirs.send(can.Message(arbitration_id=0x321, data=b"\x07\x08", is_extended_id=False))
        theirs.send(can.Message(arbitration_id=0x1ABCDE0, data=b"\x01", is_extended_id=True))
        got = []
        deadline = time.monotonic() + 10.0
        while len(got) < 2 and time.monotonic() < deadline:
            if (msg := ours.recv(1.0)) is not None:
                got.append((msg.arbitration_id, bytes(msg.data)))
        assert got == [(0x321, b"\x07\x08"), (0x1ABCDE0, b"\x01")], \
            f"python-can's default sender -> lowerbase: {got}"
        ours.send_frame(0x124, b"\x02")  # type: ignore[attr-defined]
        back = _recv_all(theirs, 2.0)  # python-can's socket also hears its own two
        assert (0x124, b"\x02") in back, f"lowerbase -> python-can: {back}"
        assert (0x666, b"\xee") in back, "the other host's frame did not cross the veth pair"
        theirs.send(can.Message(arbitration_id=0x322, data=b"\x09", is_extended_id=False))
        assert ours._poll.poll(5000)  # type: ignore[attr-defined]
        assert ours.recv_frame() == (0x322, b"\x09")  # type: ignore[attr-defined]  # fast path
        _from_another_host(0x667)
        theirs.send(can.Message(arbitration_id=0x323, data=b"\x0a", is_extended_id=False))
        rest = _recv_all(ours, 2.0)
        assert rest == [(0x323, b"\x0a")], f"lowerbase heard another host: {rest}"
    finally:
        theirs.shutdown()
        ours.shutdown()
    print("ok")


if __name__ == "__main__":
    main()
