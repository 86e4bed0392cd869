"""Which address a ROS 1 node listens on: loopback when the master is on this host (rospy's
default is every interface). Plain networking, no ROS."""

from __future__ import annotations

import ipaddress
import socket
import urllib.parse
from collections.abc import Callable, Mapping, Sequence


def resolve_host(host: str) -> list[str]:
    """Every address ``host`` resolves to (socket.getaddrinfo); [] when it does not resolve."""
    try:
        infos = socket.getaddrinfo(host, None, proto=socket.IPPROTO_TCP)
    except (OSError, UnicodeError):
        return []
    return [str(info[4][0]) for info in infos]


def _is_loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address.split("%", 1)[0]).is_loopback
    except ValueError:
        return False


def loopback_address(environ: Mapping[str, str], master_uri: str,
                     args: Sequence[str] = (), *,
                     resolve: Callable[[str], list[str]] = resolve_host) -> str | None:
    """The ROS_IP that keeps the node on loopback, or None to leave the address alone.

    Without ROS_IP, ROS_HOSTNAME, ``__ip:=`` or ``__hostname:=`` rospy listens on every
    interface (0.0.0.0). When the master is on this host's loopback (``http://localhost:11311``,
    or a hostname such as the machine's own that resolves to 127.0.x.x / ::1 only), nothing
    off this host can use the node anyway, so it listens on loopback only; set ROS_IP (or
    ROS_HOSTNAME) to the address to serve to open it up. ``resolve``: host -> addresses.
    """
    if environ.get("ROS_IP") or environ.get("ROS_HOSTNAME"):
        return None
    if any(a.startswith(("__ip:=", "__hostname:=")) for a in args):
        return None
    host = urllib.parse.urlparse(master_uri).hostname or ""
    if not host:
        return None
    if host == "localhost":  # RFC 6761: always loopback
        return "127.0.0.1"
    addresses = [host] if _is_loopback(host) else resolve(host)
    if not addresses or not all(_is_loopback(a) for a in addresses):
        return None  # remote, or not resolvable: rospy's default
    return "127.0.0.1" if any(":" not in a for a in addresses) else "::1"
