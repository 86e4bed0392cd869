"""A bus configuration resolved the way python-can does it, with lowerbase's default (the
udp_multicast group on loopback: hop limit 0, so datagrams never leave this host)."""

from __future__ import annotations

from typing import Any

import can

from lowerbase.errors import TransportError

DEFAULT_INTERFACE = "udp_multicast"
#: an administratively scoped IPv4 group; with hop_limit 0 nothing is sent off this host
DEFAULT_CHANNEL = "239.74.163.2"
DEFAULT_PORT = 43113
DEFAULT_HOP_LIMIT = 0


def bus_config(
    interface: str | None = None,
    channel: Any = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """Resolve a bus configuration the way python-can does, with lowerbase's default.

    Explicit arguments win over python-can's environment variables (CAN_INTERFACE,
    CAN_CHANNEL, ...) and config files (~/.canrc, can.ini); with none of them, the default is
    udp_multicast on 239.74.163.2:43113 with hop limit 0.
    """
    given = {k: v for k, v in {"interface": interface, "channel": channel, **kwargs}.items()
             if v is not None}
    try:
        config = dict(can.util.load_config(config=given))
    except can.CanInterfaceNotImplementedError:
        if given.get("interface"):
            raise TransportError(
                f"unknown CAN interface {given['interface']!r}; "
                f"choose one of: {', '.join(sorted(can.VALID_INTERFACES))}"
            ) from None
        config = {
            "interface": DEFAULT_INTERFACE,
            "channel": DEFAULT_CHANNEL,
            "port": DEFAULT_PORT,
            "hop_limit": DEFAULT_HOP_LIMIT,
            **given,
        }
    config = {k: v for k, v in config.items() if v is not None}
    if config.get("interface") == DEFAULT_INTERFACE:
        config.setdefault("channel", DEFAULT_CHANNEL)
        config.setdefault("hop_limit", DEFAULT_HOP_LIMIT)
    return config
