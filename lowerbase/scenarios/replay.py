"""Recording the bus in the formats other tools open, and replaying a recording offline.

* :class:`BusRecorder`: every frame of a run (SimLoop's tap, or a live bus) written through
  python-can's writers (``can.Logger`` picks the format from the suffix: candump ``.log``,
  Vector ``.asc`` and ``.blf``, ``.csv``, ``.trc``, ...). Frames from the lower computer are
  marked received (Rx), the upper computer's transmitted (Tx): the bus as the upper computer
  sees it. Timestamps are the run's time (simulated seconds from the start on a SimLoop).
* :func:`replay`: feed a recording into a ROS-free :class:`DriverCore` on a simulated clock
  that follows the recording's timestamps, reproducing /odom_raw and /odom offline. On a
  recording of a simulated run the odometry is the original's to float rounding.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError

#: suffixes python-can writes and reads back (``can.Logger`` / ``can.LogReader``)
SNAP = 1e-6  #: [s] timestamps this close to the replay's tick grid are on it
FORMATS = (".log", ".asc", ".blf", ".csv", ".trc")
CHANNEL = "can0"  #: channel name written in recordings (candump needs one)


def check_recording_path(path: str | Path, *, must_exist: bool = False) -> Path:
    """A recording path with a supported suffix; ConfigError otherwise."""
    p = Path(path)
    if p.suffix.lower() not in FORMATS:
        raise ConfigError(f"{p}: unsupported recording format {p.suffix or '(no suffix)'!r}; "
                          f"use one of {', '.join(FORMATS)}")
    if must_exist and not p.is_file():
        raise ConfigError(f"no such recording: {p}")
    return p


class BusRecorder:
    """Write frames to a python-can log file; use as a SimLoop tap: ``rec(t, dir, id, data)``."""

    def __init__(self, path: str | Path) -> None:
        import can

        self.path = check_recording_path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._writer: Any = can.Logger(str(self.path))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"cannot write {self.path}: {exc}") from None
        self._message = can.Message
        self.frames = 0

    def __call__(self, t: float, direction: str, frame_id: int, data: bytes) -> None:
        self._writer.on_message_received(self._message(
            timestamp=t, arbitration_id=frame_id, data=data, is_extended_id=False,
            is_rx=direction == "lower", channel=CHANNEL))
        self.frames += 1

    def close(self) -> None:
        self._writer.stop()

    def __enter__(self) -> BusRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_frames(path: str | Path) -> Iterator[tuple[float, int, bytes, bool]]:
    """(timestamp [s], frame id, data, is_rx) of every frame of a recording, in order."""
    import can

    p = check_recording_path(path, must_exist=True)
    try:
        reader = can.LogReader(str(p))
        for msg in reader:
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            yield float(msg.timestamp), int(msg.arbitration_id), bytes(msg.data), bool(msg.is_rx)
    except (ValueError, OSError, EOFError) as exc:
        raise ConfigError(f"cannot read {p}: {exc}") from None


# -- replay ------------------------------------------------------------------------------------


@dataclass
class ReplayResult:
    trace: Any  #: lowerbase.scenarios.expect.Trace (no truth, no commanded twist)
    frames: int  #: frames fed to the driver
    start: float  #: [s] the recording's first timestamp (trace times are relative to it)
    driver: Any  #: the DriverCore, as it ended


def replay(path: str | Path, *, pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
           sample_period: float = 0.05, tick_period: float = 0.005) -> ReplayResult:
    """Feed the lower computer's frames of a recording into a DriverCore; sample its state.

    The driver's clock jumps to each frame's timestamp; between frames it ticks every
    ``tick_period`` [s] (the SimLoop's control period), so a recording of a simulated run
    reproduces its odometry exactly. What the driver sends is dropped: the answers it would
    get are in the recording already. ``pose`` [m, m, rad] is the initial pose of the run.
    """
    from lowerbase.clock import SimClock
    from lowerbase.driver.core import DriverCore
    from lowerbase.scenarios.expect import Trace
    from lowerbase.scenarios.timeline import LINK_STATES

    frames = read_frames(path)
    first = next(frames, None)
    trace = Trace()
    if first is None:
        raise ConfigError(f"{path}: no frames")
    start = first[0]
    clock = SimClock(start)
    driver = DriverCore(lambda frame_id, data: None, clock)
    x0, y0, yaw0 = pose
    if (x0, y0, yaw0) != (0.0, 0.0, 0.0):
        driver.ekf.reset(x0, y0, yaw0)
        placed: list[bool] = []

        def _place(what: str, core: DriverCore) -> None:
            if what == "ready" and core.odometry is not None and not placed:
                core.odometry.reset(x0, y0, yaw0)
                placed.append(True)

        driver.listeners.append(_place)
    count = 0
    next_sample = start

    def sample(t: float) -> None:
        nonlocal next_sample
        if t < next_sample - 1e-9:
            return
        odo = driver.odometry
        s: dict[str, float] = {"t": t - start}
        if odo is not None and odo.has_baseline:
            s.update(raw_x=odo.x, raw_y=odo.y, raw_yaw=odo.yaw)
            s.update(zip(("ekf_x", "ekf_y", "ekf_yaw"), driver.ekf.pose, strict=True))
        s["meas_v"], s["meas_w"] = driver.measured_twist
        battery = driver.bms.battery_fields()
        if battery is not None:
            s["soc"] = float(battery["batteryPercentage"])
            s["voltage"] = float(battery["batteryVoltage"])
            s["current"] = float(battery["batteryCurrent"])
        s["status"] = float(driver.status_code)
        s["robot_state"] = float(driver.system_status.get("RobotState", -1))
        s["link"] = float(LINK_STATES.index(driver.state.value))
        s["reboots"] = float(driver.reboots)
        trace.append(s)
        while next_sample <= t + 1e-9:
            next_sample += sample_period

    def begin(t: float) -> None:
        """An instant of the control loop: sample what the driver publishes, then frames."""
        clock.sleep_until(t)
        sample(t)

    # The run's instants lie on a grid start + k * tick_period, accumulated as the SimClock
    # does; a timestamp within SNAP of the grid is taken as the grid's exact float (file
    # formats round timestamps to microseconds), so the EKF sees the very same time steps.
    instant = start
    begin(instant)
    for stamp, frame_id, data, _is_rx in _chain(first, frames):
        if stamp > instant + SNAP:
            driver.tick()  # after all frames of an instant, as in the run
            grid = instant + tick_period
            while grid < stamp - SNAP:
                begin(grid)
                driver.tick()
                grid += tick_period
            instant = grid if abs(grid - stamp) <= SNAP else stamp
            begin(instant)
        driver.on_frame(frame_id, data, instant)
        count += 1
    driver.tick()
    return ReplayResult(trace, count, start, driver)


def _chain(first: tuple[float, int, bytes, bool],
           rest: Iterator[tuple[float, int, bytes, bool]]
           ) -> Iterator[tuple[float, int, bytes, bool]]:
    yield first
    yield from rest
