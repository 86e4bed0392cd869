"""One exception hierarchy for everything lowerbase raises on purpose.

Programming errors stay ordinary Python exceptions; everything a user or the wire can cause is a
:class:`LowerbaseError`, so callers catch one root and the CLI prints one clear line. Bad input
that arrives over and over (a topic, a bus) is dropped, counted and logged a few times:
:func:`count_drop`.
"""

from __future__ import annotations

import logging
from collections.abc import MutableMapping


def worth_logging(n: int) -> bool:
    """Whether the ``n``-th drop of one kind is logged: the 1st, 10th, 100th and every 1000th
    (a flood of bad input stays a few lines; the count says how many)."""
    return n in (1, 10, 100) or n % 1000 == 0


def count_drop(stats: MutableMapping[str, int], key: str, logger: logging.Logger,
               what: object) -> int:
    """One dropped input counted in ``stats[key]`` and ``what`` (the error) logged when
    :func:`worth_logging`; the count."""
    n = stats[key] = stats.get(key, 0) + 1
    if worth_logging(n):
        logger.warning("%s (dropped; %d so far)", what, n)
    return n


class LowerbaseError(Exception):
    """Root of every error lowerbase raises on purpose."""


class ConfigError(LowerbaseError):
    """A profile, parameter file, scenario or command-line option is invalid."""


class ProtocolError(LowerbaseError):
    """A frame or byte stream does not follow the wire protocol."""


class UnknownMessageError(ProtocolError):
    """A frame ID or message name that the catalog does not define."""


class FrameLengthError(ProtocolError):
    """A frame whose payload length differs from the catalog's."""


class SignalRangeError(ProtocolError):
    """A signal value outside the range the catalog allows (also NaN and infinities)."""


class EncodeError(ProtocolError):
    """A message that cannot be encoded: a missing, unknown or non-numeric signal."""


class FramingError(ProtocolError):
    """A serial frame that cannot be built (payload too long, ID out of range)."""


class TransportError(LowerbaseError):
    """A bus, serial port or pseudo-terminal cannot be opened or used."""


class DeviceError(LowerbaseError):
    """An emulated device refused a request (the wire-level answer is coded data)."""


class ModbusDeviceError(DeviceError):
    """The BMS Modbus device or link failed."""


class RosUnavailableError(LowerbaseError):
    """rospy or the generated woosh_msgs cannot be imported."""


class MapError(ConfigError):
    """A map that cannot be used: a malformed map file, a bad resolution, an unknown name."""


class WorldError(LowerbaseError):
    """A world request that cannot be met: a pose inside a wall, a sensor outside the base, ..."""


class CampaignError(ConfigError):
    """A campaign file (lowerbase.campaign) is invalid, or one of its runs cannot be built."""
