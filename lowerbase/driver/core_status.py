"""The lower computer's status frames as :class:`~lowerbase.driver.core.DriverCore` keeps
them: versions, IMU acceleration, measured twist, odometer, status code, system status (the
link's standby or ready follows ControlMode), LEDs, the battery's frames."""

from __future__ import annotations

from typing import Any

from lowerbase.bms.frames import BmsFrameAccumulator
from lowerbase.driver.core_defs import _ESTOP_OR_FAULT, _IMU_FAULT, VERSION_FIELDS, LinkState
from lowerbase.driver.ekf import PlanarEkf


class StatusInput:
    """DriverCore's status, version, LED and battery frames kept as its state (a mixin)."""

    state: LinkState
    ekf: PlanarEkf
    bms: BmsFrameAccumulator
    versions: dict[str, str]
    imu: tuple[tuple[float, float, float], tuple[float, float, float]] | None
    imu_stamp: float
    bms_stamp: float | None
    measured_twist: tuple[float, float]
    odometer: float
    status_code: int
    system_status: dict[str, Any]
    leds: dict[tuple[int, int], dict[str, int]]
    _version_parts: dict[int, dict[int, bytes]]
    _control_can: bool | None
    _enable_wanted: bool

    def _notify(self, what: str) -> None:
        raise NotImplementedError

    def _settle(self) -> None:
        raise NotImplementedError

    def _on_VersionResponse(self, v: dict[str, Any], now: float) -> None:
        field_no = int(v["Field"])
        parts = self._version_parts.setdefault(field_no, {})
        parts[int(v["Sequence"])] = int(v["Text"]).to_bytes(6, "little")
        if int(v["Last"]) and len(parts) == int(v["Sequence"]) + 1:
            text = b"".join(parts[i] for i in range(len(parts))).rstrip(b"\0")
            self.versions[VERSION_FIELDS[field_no]] = text.decode("ascii", "replace")
            self._version_parts.pop(field_no, None)
            self._notify("information")

    def _on_ImuAccel(self, v: dict[str, Any], now: float) -> None:
        gyro = self.imu[0] if self.imu is not None else (0.0, 0.0, 0.0)
        self.imu = (gyro, (float(v["X"]), float(v["Y"]), float(v["Z"])))
        self.imu_stamp = now
        self._notify("imu")

    def _on_MotionState(self, v: dict[str, Any], now: float) -> None:
        self.measured_twist = (float(v["Linear"]), float(v["Angular"]))
        self._notify("twist")

    def _on_Odometer(self, v: dict[str, Any], now: float) -> None:
        self.odometer = float(v["Distance"])
        self._notify("odometer")

    def _on_StatusCode(self, v: dict[str, Any], now: float) -> None:
        self.status_code = int(v["Code"])
        if self.status_code & _IMU_FAULT:
            self.ekf.discard_gyro()  # queued samples of a gyro now known to be frozen
        self._notify("status_code")

    def _on_SystemStatus(self, v: dict[str, Any], now: float) -> None:
        previous = self.system_status.get("RobotState")
        self.system_status = v
        self._control_can = v["ControlMode"] in (1, "Can")
        # enabled: done; e-stopped or faulted: standby after that is the operator's decision
        if self._control_can or v["RobotState"] in _ESTOP_OR_FAULT:
            self._enable_wanted = False
        if previous is not None and previous != v["RobotState"]:
            self._notify("system_status")
        if self.state not in (LinkState.LOST, LinkState.WAITING):  # a Heartbeat comes first
            self._settle()

    def _on_LedState(self, v: dict[str, Any], now: float) -> None:
        self.leds[(int(v["Strip"]), int(v["Submodule"]))] = {
            k: int(v[k]) for k in ("Urgency", "Abnormal", "Normal", "Color")}

    def _bms(self, name: str, v: dict[str, Any], now: float) -> None:
        # /battery and /driver_base/bms once a whole 1 Hz burst of five frames is in: the
        # node's tick falling between two frames of one burst gave two, the first torn
        if self.bms.update(name, v) and self.bms.take_burst():
            self.bms_stamp = now  # the burst's last frame: when the pack's figures were read
            self._notify("battery")

    def _on_BmsPack(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsPack", v, now)

    def _on_BmsCell(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsCell", v, now)

    def _on_BmsCapacity(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsCapacity", v, now)

    def _on_BmsStatus(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsStatus", v, now)

    def _on_BmsLife(self, v: dict[str, Any], now: float) -> None:
        self._bms("BmsLife", v, now)
