"""How every lowerbase ROS node starts and stops: :func:`ros_session`.

The world, navigation, tasks and trace nodes (and driver_base) do the same things around their
own work: refuse to start without a master (one line saying what to do), listen on loopback
when the master is on this host (``lowerbase.ros1.loopback.loopback_address``), init the
node, hand lowerbase's log records to rosout, print one line once on the master (what
``lowerbase robot`` waits for: ``on ROS master``) and, on the way out, one line of counts, then
undo all of it. Imported only by the rospy layers, so the ROS-free cores never need rospy.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from lowerbase.errors import RosUnavailableError, TransportError


class ToRosout(logging.Handler):
    """Hands lowerbase's log records to rospy's ``rosout`` logger (console and /rosout)."""

    def emit(self, record: logging.LogRecord) -> None:
        logging.getLogger("rosout").handle(record)


#: what to do when rospy cannot be imported
ROS_HINT = ("run lowerbase from a venv made from the ROS Python (Debian: /usr/bin/python3 -m venv "
            "--system-site-packages VENV) or source /opt/ros/noetic/setup.bash; docs/driver.md")


def import_rospy() -> Any:
    """rospy, or RosUnavailableError in one line saying how to get it."""
    try:
        import rospy
    except ImportError as exc:
        raise RosUnavailableError(f"ROS is not installed ({exc}): {ROS_HINT}") from None
    return rospy


@dataclass
class RosSession:
    """A node on the master: ``rospy``, the master's URI, the loopback address it listens on
    (None: rospy's choice, set by ROS_IP/ROS_HOSTNAME or a remote master)."""

    command: str
    rospy: Any
    master_uri: str
    loopback: str | None

    def announce(self, detail: str = "") -> None:
        """``lowerbase world: /world on ROS master http://... (loopback only); detail``."""
        where = " (loopback only)" if self.loopback else ""
        print(f"lowerbase {self.command}: {self.rospy.get_name()} on ROS master "
              f"{self.master_uri}{where}{'; ' + detail if detail else ''}", flush=True)

    def stopped(self, stats: Mapping[str, Any]) -> None:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(stats.items()))
        print(f"lowerbase {self.command}: stopped; {counts or 'nothing counted'}",
              file=sys.stderr, flush=True)


@contextmanager
def ros_session(command: str, node_name: str, ros_args: Sequence[str]) -> Iterator[RosSession]:
    """rospy initialised as ``node_name`` on the master in ROS_MASTER_URI for the block."""
    rospy = import_rospy()
    import rosgraph

    from lowerbase.ros1.loopback import loopback_address

    uri = rosgraph.get_master_uri()
    if not rosgraph.is_master_online():
        raise TransportError(f"no ROS master at {uri} (start roscore, or set ROS_MASTER_URI)")
    address = loopback_address(os.environ, uri, [*sys.argv, *ros_args])
    if address is not None:  # a local master: listen on loopback, not on every interface
        os.environ["ROS_IP"] = address
    rospy.init_node(node_name, argv=[node_name, *ros_args], anonymous=False)
    logger = logging.getLogger("lowerbase")
    handler = ToRosout()
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield RosSession(command, rospy, uri, address)
    finally:
        logger.removeHandler(handler)
        logger.propagate = True
        if not rospy.is_shutdown():
            rospy.signal_shutdown(f"{command} stopped")
