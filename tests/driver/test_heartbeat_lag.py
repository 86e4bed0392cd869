"""Heartbeats handled late on the driver's clock (``lowerbase robot --sim-time --speed 8``): the
driver compares each Heartbeat's Uptime with its ROS time (/clock, the emulator's own time),
and a backlog of frames in the driver puts Heartbeats up to ~2 s of sim time behind /clock.
That is not a reboot, a jump or a second lower computer; with ``allow_receive_lag`` (the node
under /use_sim_time) the core takes them as one timeline, and still sees real reboots. ROS-free,
on a simulated clock."""

from __future__ import annotations

from lowerbase.clock import SimClock
from lowerbase.driver.core import DriverCore

#: late [s of the driver's clock] of each Heartbeat in turn: the K=8 run's pattern (driver.log:
#: "rebooted (boot #1, up 65.5 s)" handled at ROS time 66.83)
LAGS = [0.0, 0.0, 1.3, 1.0, 0.2, 0.0, 1.2, 0.4, 0.0, 1.4, 0.0, 0.9, 0.0]


def _core() -> tuple[DriverCore, SimClock]:
    clock = SimClock()
    return DriverCore(lambda fid, data: None, clock), clock


def _feed(core: DriverCore, clock: SimClock, uptimes: list[float], lags: list[float],
          t0: float = 0.0, boot: int = 1) -> None:
    """Heartbeats sent at emulator time ``t0 + uptime``, handled ``lag`` later, in order."""
    msg = core.codec.message("Heartbeat")
    for k, (uptime, lag) in enumerate(zip(uptimes, lags, strict=True)):
        handled = max(clock.now(), t0 + uptime + lag)
        clock.advance(handled - clock.now())
        core.on_frame(msg.frame_id, msg.encode({"Uptime": uptime, "BootCounter": boot,
                                                "Counter": (round(uptime / 0.5)) % 16,
                                                "ProtocolVersion": 1, "Overruns": 0}))
        assert k == 0 or core.boot_counter == boot


def _uptimes(start: float, n: int) -> list[float]:
    return [start + 0.5 * k for k in range(n)]


def test_without_the_allowance_late_heartbeats_read_as_reboots() -> None:
    """What the K=8 run logged: the old check on a lagging delivery."""
    core, clock = _core()
    _feed(core, clock, _uptimes(10.0, len(LAGS)), LAGS, t0=0.0)
    assert core.stats["heartbeat_off_timeline"] > 0
    assert core.reboots + core.stats["heartbeat_timeline_jump"] > 0


def test_with_the_allowance_late_heartbeats_are_one_timeline() -> None:
    core, clock = _core()
    core.allow_receive_lag(1.5)
    _feed(core, clock, _uptimes(10.0, len(LAGS)), LAGS)
    assert core.reboots == 0
    assert core.stats["heartbeat_off_timeline"] == 0
    assert core.stats["heartbeat_timeline_jump"] == 0
    assert core.stats["two_lower_computers"] == 0


def test_with_the_allowance_a_restart_is_still_a_reboot_however_short_the_run() -> None:
    for ran in (0.5, 1.0, 3.0, 30.0):  # the old run's Uptime when it was restarted
        core, clock = _core()
        core.allow_receive_lag(1.5)
        first = _uptimes(10.0 - ran, round(ran / 0.5) + 1)  # up to Uptime `ran`... at t = 10
        _feed(core, clock, [u - (10.0 - ran) for u in first], [0.0] * len(first),
              t0=10.0 - ran)
        restart = clock.now()
        _feed(core, clock, _uptimes(0.0, 4), [0.0] * 4, t0=restart)  # boot #1 again, from 0
        assert core.reboots == 1, ran


def test_the_allowance_never_narrows_the_defaults() -> None:
    core, _ = _core()
    core.allow_receive_lag(0.1)
    assert core.uptime_slack == 0.5 and core.peers.tolerance == 0.3


def _slipping(core: DriverCore, clock: SimClock, slip_at: int, slip: float,
              overruns_move: bool) -> None:
    """A lower computer whose time slipped ``slip`` s behind real time before its Heartbeat
    ``slip_at`` (issue 22 item 3): it reports the slip in Overruns, or (a defect) does not."""
    msg = core.codec.message("Heartbeat")
    for k in range(12):
        uptime = 10.0 + 0.5 * k
        handled = uptime + (slip if k >= slip_at else 0.0)
        clock.advance(handled - clock.now())
        overruns = 1 if overruns_move and k >= slip_at else 0
        core.on_frame(msg.frame_id, msg.encode({"Uptime": uptime, "BootCounter": 1,
                                                "Counter": k % 16, "ProtocolVersion": 1,
                                                "Overruns": overruns}))


def test_a_slip_the_lower_computer_reports_is_followed_not_a_reboot() -> None:
    core, clock = _core()
    _slipping(core, clock, 5, 1.2, overruns_move=True)
    assert core.reboots == 0 and core.boot_counter == 1
    assert core.stats["lower_computer_slips"] == 1
    assert core.stats["heartbeat_off_timeline"] == 0
    assert core.stats["two_lower_computers"] == 0


def test_the_same_lag_unreported_is_still_off_the_timeline() -> None:
    core, clock = _core()
    _slipping(core, clock, 5, 1.2, overruns_move=False)
    assert core.stats["lower_computer_slips"] == 0
    assert core.stats["heartbeat_off_timeline"] > 0
