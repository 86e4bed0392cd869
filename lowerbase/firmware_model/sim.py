"""An emulated lower computer on a simulated clock, wired to a frame log, for tests and benches.

``SimRig`` plays the upper computer by hand: ``send`` encodes a frame and hands it to the MCU,
``run`` advances time in control periods, ``drive`` keeps MotionCommand coming at its cycle
time, and every frame the MCU sends is kept decoded with its timestamp.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lowerbase.clock import SimClock
from lowerbase.firmware_model.faults import Fault
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.protocol.codec import default_codec


@dataclass(frozen=True)
class Sent:
    t: float  #: [s] simulated time
    name: str
    values: dict[str, Any]
    data: bytes


class SimRig:
    def __init__(
        self,
        profile: Profile | None = None,
        *,
        params_path: str | Path | None = None,
        faults: Iterable[Fault | str] = (),
        bms: Any = None,
        keep: bool = True,
    ) -> None:
        self.codec = default_codec()
        self.clock = SimClock()
        self.sent: list[Sent] = []
        self.keep = keep
        self.profile = profile or load_profile()
        self.mcu = Mcu(self.profile, self.clock, self._on_send, params_path=params_path,
                       faults=faults, bms=bms)
        self._counter = 0

    def _on_send(self, frame_id: int, data: bytes) -> None:
        if self.keep:
            name, values = self.codec.decode(frame_id, data, strict=False)
            self.sent.append(Sent(self.clock.now(), name, values, data))

    @property
    def now(self) -> float:
        return self.clock.now()

    def send(self, name: str, **values: Any) -> None:
        """Send one frame to the MCU (Counter filled in when the message has one)."""
        msg = self.codec.message(name)
        if msg.has_counter and "Counter" not in values:
            values["Counter"] = self._counter
            self._counter = (self._counter + 1) & 0xF
        self.mcu.receive(msg.frame_id, msg.encode(values))

    def step(self) -> None:
        self.mcu.step()
        self.clock.advance(self.mcu.dt)

    def run(self, seconds: float) -> None:
        self.mcu.advance(round(seconds / self.mcu.dt))

    def enable(self) -> None:
        """Wait out the boot, then enable CAN control."""
        while self.now < 0.35:
            self.step()
        self.send("ControlCommand", Command="EnableCanControl")

    def drive(self, linear: float, angular: float, seconds: float, smoothed: bool = False,
              period: float = 0.02) -> None:
        """Send MotionCommand every ``period`` [s] for ``seconds`` while time runs."""
        every = max(1, round(period / self.mcu.dt))
        total = round(seconds / self.mcu.dt)
        for k in range(0, total, every):
            self.send("MotionCommand", Linear=linear, Angular=angular,
                      Mode="Smoothed" if smoothed else "Raw")
            self.mcu.advance(min(every, total - k))

    def frames(self, name: str, since: float = -1.0) -> list[Sent]:
        return [s for s in self.sent if s.name == name and s.t >= since]

    def last(self, name: str) -> dict[str, Any]:
        found = self.frames(name)
        if not found:
            raise AssertionError(f"no {name} frame sent yet")
        return found[-1].values

    def status(self) -> int:
        return int(self.last("StatusCode")["Code"])
