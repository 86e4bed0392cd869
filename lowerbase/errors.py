"""One exception hierarchy for everything lowerbase raises on purpose.

Programming errors stay ordinary Python exceptions; everything a user or the wire can cause is a
:class:`LowerbaseError`, so callers catch one root and the CLI prints one clear line.
"""

from __future__ import annotations


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
