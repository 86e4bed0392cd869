"""Who holds a process that publishes synchronously (:func:`lowerbase.ros1.wire.
publish_synchronously`): the connections of its publications whose subscriber stopped reading.

Written on the publishing thread, a message to a subscriber that reads no more (a stopped
process, a debugger at a breakpoint) waits in ``sendall`` once that connection's socket buffers
are full, and with it the lockstep robot's simulated time. :func:`backlogs` names such
connections by the bytes their socket has not delivered yet (Linux ``SIOCOUTQ``: a subscriber
that reads has next to none on loopback). Ctrl-C still stops such a process: the signal
interrupts the blocked write, and rospy drops that connection.
"""

from __future__ import annotations

import fcntl
import struct
import termios
from dataclasses import dataclass
from typing import Any

#: Linux' SIOCOUTQ: the bytes a TCP socket has not had acknowledged yet (TIOCOUTQ's number)
SIOCOUTQ = termios.TIOCOUTQ


@dataclass(frozen=True)
class Backlog:
    topic: str
    subscriber: str  #: the subscribing node's caller id
    unsent: int  #: [bytes] in the connection's socket, not yet taken by the subscriber

    def __str__(self) -> str:
        return f"{self.topic} -> {self.subscriber} ({self.unsent / 1024:.0f} KiB unsent)"


def unsent_bytes(sock: Any) -> int:
    """[bytes] ``sock`` has not had acknowledged; 0 where it cannot tell (closed, not TCP)."""
    try:
        raw = fcntl.ioctl(sock.fileno(), SIOCOUTQ, b"\0" * 4)
    except (OSError, ValueError):
        return 0
    return int(struct.unpack("i", raw)[0])


def _connections(rospy: Any) -> list[tuple[str, Any]]:
    from rospy.impl.registration import get_topic_manager

    manager = get_topic_manager()
    if manager is None:
        return []
    with manager.lock:
        publications = list(manager.pubs.values())
    return [(impl.resolved_name, c) for impl in publications for c in list(impl.connections)]


def backlogs(rospy: Any, at_least: int = 1) -> list[Backlog]:
    """The connections of this process' publications with ``at_least`` unsent bytes, the
    largest backlog first."""
    found = []
    for topic, conn in _connections(rospy):
        sock = getattr(conn, "socket", None)
        n = unsent_bytes(sock) if sock is not None else 0
        if n >= at_least:
            found.append(Backlog(topic, str(getattr(conn, "endpoint_id", "?")), n))
    return sorted(found, key=lambda b: -b.unsent)
