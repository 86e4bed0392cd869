"""The BMS as the emulated lower computer (``firmware_model.mcu``) uses it.

The MCU steps the pack with its motors' load, polls the BMS over a :class:`BmsLink`, turns the
reading into StatusCode bits and sends the Bms* frames. This adapter gives it exactly that:
``step(dt, load_current)``, ``poll()``, ``status_bits(snapshot)`` and ``frame(name, snapshot)``.

Three set-ups, one adapter:

* its own pack, polled in process (the default; same register path as Modbus);
* its own pack, also served over Modbus TCP/RTU for other masters (``serve_tcp``/``serve_rtu``);
* an external BMS (another ``lowerbase bms`` or a real one), polled over Modbus from a
  background thread so a silent BMS never stalls the control loop.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping
from typing import Any

from lowerbase.bms.config import battery_config_from_mapping
from lowerbase.bms.device import BmsDevice, BmsServer
from lowerbase.bms.frames import FrameSignals, snapshot_to_frames
from lowerbase.bms.link import BmsLink, InProcessBmsLink
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.snapshot import BmsSnapshot
from lowerbase.bms.status import BmsStatus, ChargeMode, SwitchStatus
from lowerbase.protocol.status_codes import StatusBit

log = logging.getLogger(__name__)

OVER_TEMPERATURE = BmsStatus.CHARGE_OVER_TEMPERATURE | BmsStatus.DISCHARGE_OVER_TEMPERATURE
POLL_PERIOD = 0.5  #: [s] background polling of an external BMS


class BackgroundPoller:
    """Polls a (slow, maybe silent) link in a thread; ``poll()`` returns each new answer once."""

    def __init__(self, link: BmsLink, period: float = POLL_PERIOD) -> None:
        self.link = link
        self.period = period
        self._latest: BmsSnapshot | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bms-poller", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.monotonic()
            snap = self.link.poll()
            if snap is not None:
                with self._lock:
                    self._latest = snap
            self._stop.wait(max(0.0, self.period - (time.monotonic() - t0)))

    def poll(self) -> BmsSnapshot | None:
        with self._lock:
            snap, self._latest = self._latest, None
        return snap

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.link.close()


class McuBmsAdapter:
    """``device`` is stepped (None for an external BMS); ``link`` is polled.

    ``low_soc`` / ``critical_soc`` [%] and ``temp_warning_c`` [degC] are the lower computer's
    own thresholds, not the BMS's.
    """

    def __init__(
        self, device: BmsDevice | None = None, link: BmsLink | None = None, *,
        low_soc: float = 20.0, critical_soc: float = 5.0, temp_warning_c: float = 50.0,
    ) -> None:
        if device is None and link is None:
            device = BmsDevice()
        self.device = device
        self.link: BmsLink = link or InProcessBmsLink(self.device)  # type: ignore[arg-type]
        self.low_soc = low_soc
        self.critical_soc = critical_soc
        self.temp_warning_c = temp_warning_c
        self.server: BmsServer | None = None
        self._frames_of: BmsSnapshot | None = None  # the snapshot _frames were built from
        self._frames: dict[str, FrameSignals] = {}

    @classmethod
    def from_battery_table(
        cls, table: Mapping[str, Any], *, soc: float = 80.0, charger: bool = False,
        unit: int = 1, low_soc: float = 20.0, critical_soc: float = 5.0,
        temp_warning_c: float = 50.0,
    ) -> McuBmsAdapter:
        """Its own pack from a profile's [battery] table (thresholds: see the class)."""
        pack = BatteryPack(battery_config_from_mapping(table), soc=soc)
        device = BmsDevice(pack, unit=unit)
        if charger:
            device.connect_charger(ChargeMode.AUTO)
        return cls(device, low_soc=low_soc, critical_soc=critical_soc,
                   temp_warning_c=temp_warning_c)

    @classmethod
    def from_profile(
        cls, profile: Any, *, soc: float = 80.0, charger: bool = False, unit: int = 1,
    ) -> McuBmsAdapter:
        """Its own pack from the profile's [battery], thresholds from its [power]."""
        power = profile.power
        return cls.from_battery_table(
            profile.battery, soc=soc, charger=charger, unit=unit,
            low_soc=power.low_battery_soc, critical_soc=power.critical_battery_soc,
            temp_warning_c=power.battery_temp_warning)

    @classmethod
    def external(cls, link: BmsLink, profile: Any = None) -> McuBmsAdapter:
        """Poll a BMS that runs elsewhere, in the background (thresholds from the profile's
        [power] when given)."""
        if profile is None:
            return cls(None, BackgroundPoller(link))
        power = profile.power
        return cls(None, BackgroundPoller(link), low_soc=power.low_battery_soc,
                   critical_soc=power.critical_battery_soc,
                   temp_warning_c=power.battery_temp_warning)

    def serve(self, *, tcp: tuple[str, int] | None, rtu: str | None,
              baudrate: int = 19200) -> BmsServer:
        """Also serve the own pack over Modbus (the MCU keeps stepping it)."""
        if self.device is None:
            raise ValueError("an external BMS cannot be served again")
        self.server = BmsServer(self.device, tcp=tcp, rtu=rtu, baudrate=baudrate, clock=None)
        self.server.start()
        return self.server

    def connect_charger(self, mode: ChargeMode = ChargeMode.AUTO) -> None:
        if self.device is not None:
            self.device.connect_charger(mode)

    def disconnect_charger(self) -> None:
        if self.device is not None:
            self.device.disconnect_charger()

    def step(self, dt: float, load_current: float) -> None:
        """Advance the own pack by ``dt`` [s] with the motors drawing ``load_current`` [A]."""
        if self.device is not None:
            self.device.step(dt, max(load_current, 0.0))

    def poll(self) -> BmsSnapshot | None:
        """One BMS poll; None when the link is silent."""
        return self.link.poll()

    def status_bits(self, snapshot: BmsSnapshot) -> StatusBit:
        """The StatusCode bits this reading implies."""
        bits = StatusBit(0)
        if snapshot.soc < self.low_soc:
            bits |= StatusBit.LOW_BATTERY
        if snapshot.soc < self.critical_soc:
            bits |= StatusBit.CRITICAL_BATTERY
        if not snapshot.switch_status & SwitchStatus.DISCHARGE:
            bits |= StatusBit.BMS_PROTECTION
        if snapshot.bms_status & OVER_TEMPERATURE or snapshot.temp_max >= self.temp_warning_c:
            bits |= StatusBit.BATTERY_OVER_TEMPERATURE
        if snapshot.current > 0:
            bits |= StatusBit.CHARGING
        return bits

    def frame(self, name: str, snapshot: BmsSnapshot) -> FrameSignals:
        """Signals of Bms* frame ``name`` (Counter 0: the sender sets it). The five frames of
        one snapshot are built once (the MCU asks for them one by one)."""
        if self._frames_of is not snapshot:
            self._frames = dict(snapshot_to_frames(snapshot))
            self._frames_of = snapshot
        try:
            return dict(self._frames[name])
        except KeyError:
            raise KeyError(f"{name} is not a Bms frame") from None

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
        self.link.close()
