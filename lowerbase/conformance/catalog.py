"""Facts the suite derives from the catalog (and the one place that knows how
WheelFeedback rows are told apart)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from lowerbase.protocol.codec import Codec, MessageCodec
from lowerbase.protocol.status_codes import StatusBit

# -- catalog-derived facts ----------------------------------------------------------------------

#: signals that tell apart the frames of one cycle (the catalog's comments: one WheelFeedback
#: per wheel, one LedState per submodule of both strips)
ROW_KEYS: dict[str, tuple[str, ...]] = {
    "WheelFeedback": ("Wheel",),
    "LedState": ("Strip", "Submodule"),
}
#: messages sent only while a condition holds, with the StatusCode bit that announces its absence
CONDITIONAL: dict[str, StatusBit] = {
    "BmsPack": StatusBit.BMS_LINK_LOST,
    "BmsCell": StatusBit.BMS_LINK_LOST,
    "BmsCapacity": StatusBit.BMS_LINK_LOST,
    "BmsStatus": StatusBit.BMS_LINK_LOST,
    "BmsLife": StatusBit.BMS_LINK_LOST,
}


@dataclass(frozen=True)
class WheelSample:
    """One wheel's feedback at one reception time."""

    t: float  #: reception time [s] (time.monotonic)
    count: int  #: encoder register [pulses], int32
    velocity: float  #: rim speed [m/s]
    counter: int = -1  #: the frame's rolling Counter (-1: the frame carries none)


#: WheelFeedback's wheel numbers (the catalog: 0 left, 1 right)
WHEELS = {0: "left", 1: "right"}


def wheel_samples(frames: Iterable[tuple[float, Mapping[str, Any]]]
                  ) -> dict[str, list[WheelSample]]:
    """WheelFeedback frames (reception time, decoded values) by wheel name, in order.

    The one place of the suite that knows how WheelFeedback carries the wheels."""
    out: dict[str, list[WheelSample]] = {name: [] for name in WHEELS.values()}
    for t, v in frames:
        side = WHEELS.get(int(v["Wheel"]))
        if side is not None:  # multiplexed: Wheel selects LeftCount.. or RightCount..
            s = "" if "Count" in v else side.title()  # also the older per-frame layout
            out[side].append(WheelSample(t, int(v[f"{s}Count"]), float(v[f"{s}Velocity"]),
                                         int(v.get("Counter", -1))))
    return out


def periodic_lower_messages(codec: Codec) -> list[MessageCodec]:
    """Every periodic message the lower computer sends, in catalog order."""
    return [m for m in codec if m.is_periodic and "Lower" in m.senders]


def shared_counter(msg: MessageCodec) -> bool:
    """Whether the frames of one cycle share the counter (the Counter comment says so)."""
    return msg.has_counter and "shared" in msg.signal("Counter").comment.lower()


def control_period(codec: Codec) -> float:
    """An upper bound of the lower computer's control period [s]: the catalog's shortest
    cycle (a firmware cannot send a frame every 10 ms from a slower loop)."""
    return min(m.cycle_time or float("inf") for m in periodic_lower_messages(codec))


def protocol_version(codec: Codec) -> int:
    """The catalog's protocol version: the last word of its VERSION string."""
    words = (codec.database.version or "").split()
    return int(words[-1]) if words and words[-1].isdigit() else 1


def parameter_index(codec: Codec, name: str) -> int:
    table = codec.message("ParameterRequest").signal("Index").choices
    for index, text in table.items():
        if text == name:
            return index
    raise KeyError(name)


def parameter_limits() -> dict[int, tuple[str, float, float]]:
    """index -> (name, minimum, maximum): the documented parameter ranges."""
    from lowerbase.firmware_model.parameters import SPECS

    return {i: (s.name, s.minimum, s.maximum) for i, s in SPECS.items()}


def _close(a: float, b: float) -> bool:
    """Equal within float32 precision (parameter values travel as float32)."""
    return abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))
