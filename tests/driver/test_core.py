"""The ROS-free driver core against the emulated lower computer, on simulated time."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lowerbase.clock import SimClock
from lowerbase.driver.core import DriverConfig, DriverCore, LinkState
from lowerbase.firmware_model.profile import load_profile
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.simloop.loop import SimLoop


def ready(loop: SimLoop) -> bool:
    return loop.driver.state == LinkState.READY and loop.mcu.state.name == "ACTIVE"


def test_reads_parameters_from_the_lower_computer_and_enables_control() -> None:
    p = load_profile()
    p = p.replace(chassis=dataclasses.replace(p.chassis, wheel_distant=0.55, ratio_left=25.0,
                                              ratio_right=25.0))
    loop = SimLoop(p)
    assert loop.run_until(ready, timeout=3.0)
    assert loop.driver.parameters["wheelDistant"] == pytest.approx(0.55)
    assert loop.driver.odometry is not None
    assert loop.driver.odometry.params.ratio_left == pytest.approx(25.0)
    assert loop.driver.versions["movebaseType"] == p.identity.movebase_type
    assert loop.driver.information()["hardwareVersion"] == p.identity.hardware_version


def test_twist_moves_the_robot_and_odometry_follows_the_truth() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(0.5, 0.0, 4.0)
    odo = loop.driver.odometry
    assert odo is not None
    truth = loop.mcu.truth
    assert truth.x > 1.5
    assert odo.x == pytest.approx(truth.x, rel=0.01)
    ex, ey, _ = loop.driver.ekf.pose
    assert math.hypot(ex - truth.x, ey - truth.y) < 0.05
    assert loop.driver.measured_twist[0] == pytest.approx(0.5, abs=0.02)


def test_stale_twist_stops_sending_and_the_robot_stops() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(0.4, 0.0, 1.0)
    sent = loop.driver.stats["tx_MotionCommand"]
    loop.run(2.0)
    assert loop.driver.stats["twist_stale"] == 1
    # one explicit stop after the timeout, then silence
    assert loop.driver.stats["tx_MotionCommand"] <= sent + 0.5 * 50 + 2
    assert loop.mcu.truth.v == pytest.approx(0.0, abs=1e-6)


def test_reboot_is_detected_parameters_reread_and_control_reenabled() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(0.3, 0.0, 1.0)
    x_before = loop.driver.odometry.x  # type: ignore[union-attr]
    loop.driver.control("Reboot")
    loop.run(0.6)  # the first Heartbeat after the reboot carries the new BootCounter
    assert loop.driver.reboots == 1
    assert loop.run_until(ready, timeout=3.0)
    assert loop.driver.reboots == 1
    loop.drive(0.3, 0.0, 1.0)
    odo = loop.driver.odometry
    assert odo is not None and odo.x > x_before + 0.2  # continues, no jump from zeroed counters
    assert odo.x == pytest.approx(loop.mcu.truth.x, abs=0.05)


def test_link_loss_and_return() -> None:
    loop = SimLoop(faults=["silence@3+3"])
    assert loop.run_until(ready, timeout=3.0)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.LOST, timeout=6.0)
    assert 4.0 <= loop.now <= 3.0 + 1.5 + 0.5 + 0.1  # link_timeout after the last Heartbeat
    assert loop.driver.stats["link_lost"] == 1
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=3.0)
    assert loop.now < 6.0 + 0.6


def test_malformed_frames_are_counted_not_fatal() -> None:
    loop = SimLoop(faults=["corrupt:0.2"])
    loop.run(3.0)
    assert loop.driver.stats["malformed"] > 10
    assert loop.driver.state in (LinkState.READY, LinkState.CONFIGURING)


def test_nan_twist_is_refused() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    assert not loop.driver.set_twist(math.nan, 0.0)
    assert loop.driver.set_twist(10.0, 0.0)  # clipped to the catalog range, then the MCU limits
    assert loop.driver.stats["twist_clipped"] == 1


def test_battery_and_status_reach_the_driver() -> None:
    loop = SimLoop(soc=15.0)
    loop.run(3.0)
    battery = loop.driver.bms.battery_fields()
    assert battery is not None
    assert battery["batteryPercentage"] == 15
    assert loop.driver.status_code & StatusBit.LOW_BATTERY


def test_ekf_beats_wheel_odometry_with_slip_and_radius_error() -> None:
    p = load_profile()
    p = p.replace(truth=dataclasses.replace(p.truth, right_radius_error=0.01,
                                            slip_rate_per_km=40.0, slip_fraction=0.5,
                                            slip_duration=0.3))
    loop = SimLoop(p, driver_config=DriverConfig(gyro_sigma=5e-4))
    assert loop.run_until(ready, timeout=3.0)
    loop.run(2.0)  # standstill: the EKF learns the gyro bias
    for _ in range(4):
        loop.drive(0.8, 0.0, 6.0)
        loop.drive(0.0, 0.6, math.pi / 2 / 0.6 + 0.3)
    truth = loop.mcu.truth
    odo = loop.driver.odometry
    assert odo is not None
    raw_heading = abs(math.remainder(odo.yaw_unwrapped - truth.yaw, math.tau))
    ekf_heading = abs(math.remainder(loop.driver.ekf.yaw_unwrapped - truth.yaw, math.tau))
    assert ekf_heading < raw_heading / 2


_IDS = [m.frame_id for m in default_codec()]


@settings(max_examples=300, deadline=None)
@given(frames=st.lists(st.tuples(st.one_of(st.sampled_from(_IDS), st.integers(0, 0x7FF)),
                                 st.binary(max_size=8)), max_size=30))
def test_fuzz_random_frames_never_crash_the_driver(frames: list[tuple[int, bytes]]) -> None:
    sent: list[tuple[int, bytes]] = []
    core = DriverCore(lambda i, d: sent.append((i, d)), SimClock())
    for frame_id, data in frames:
        core.on_frame(frame_id, data)
        core.tick()
    assert core.stats["frames"] == len(frames)


def test_a_frozen_imu_is_no_longer_fused() -> None:
    loop = SimLoop(faults=["imu-freeze@3"])
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(0.3, 0.2, 4.0)
    assert loop.driver.status_code & StatusBit.IMU_FAULT
    fused = loop.driver.ekf.statistics.get("gyro.accepted", 0)
    loop.drive(0.3, 0.2, 1.0)
    assert loop.driver.ekf.statistics.get("gyro.accepted", 0) == fused
    assert loop.driver.odometry is not None


def _count_motion_commands(twist_every: float | None, seconds: float = 10.0,
                           seed: int = 7) -> int:
    """MotionCommands a core sends while ticked at 50 Hz by a jittery loop (ticks up to
    0.5 ms early or late), with a twist every ``twist_every`` s (None: one twist at start)."""
    import random

    rng = random.Random(seed)
    clock = SimClock()
    mc = default_codec().message("MotionCommand").frame_id
    sent: list[float] = []
    core = DriverCore(lambda fid, data: sent.append(clock.now()) if fid == mc else None,
                      clock, DriverConfig(command_timeout=seconds + 1.0))
    events = [(k * 0.02 + rng.uniform(-5e-4, 5e-4), "tick") for k in range(1, 501)]
    if twist_every is None:
        events.append((0.0, "twist"))
    else:
        events += [(k * twist_every + rng.uniform(0.0, 2e-3), "twist")
                   for k in range(round(seconds / twist_every))]
    for t, what in sorted(events):
        clock.sleep_until(t)
        if what == "tick":
            core.tick()
        else:
            core.set_twist(0.2, 0.0)
    return len([t for t in sent if t < seconds])


@pytest.mark.parametrize("twist_every", [None, 0.05, 0.1, 0.033])
def test_motion_commands_keep_the_dbc_cycle_whatever_the_tick_jitter(
        twist_every: float | None) -> None:
    # 20 ms cycle (chassis.dbc): 500 frames in 10 s, one twist or twists at 10..30 Hz
    assert abs(_count_motion_commands(twist_every) - 500) <= 1


def test_motion_commands_resync_after_a_stall_without_a_burst() -> None:
    clock = SimClock()
    sent: list[float] = []
    core = DriverCore(lambda fid, data: sent.append(clock.now()), clock,
                      DriverConfig(command_timeout=5.0))
    core.set_twist(0.2, 0.0)
    clock.advance(1.0)  # the loop stalled for 1 s
    for _ in range(10):
        core.tick()
        clock.advance(0.02)
    assert len(sent) == 1 + 10  # one per tick after the stall, not 50 at once


def _mcu_frames(seconds: float) -> list[tuple[float, int, bytes]]:
    """What an emulated lower computer sends in its first ``seconds`` (no BMS), stamped."""
    from lowerbase.firmware_model.mcu import Mcu

    clock = SimClock()
    frames: list[tuple[float, int, bytes]] = []
    mcu = Mcu(load_profile(), clock, lambda fid, data: frames.append((clock.now(), fid, data)))
    for _ in range(round(seconds / 0.01)):
        mcu.step()
        clock.advance(0.01)
    return frames


def test_frames_before_a_heartbeat_never_flap_the_link() -> None:
    """A driver that starts mid-stream hears SystemStatus (100 ms) before the first Heartbeat
    (500 ms); a link lost by silence comes back with its Heartbeat, not its first frame.
    Neither makes the link flap lost/back on every frame (it did: 'no Heartbeat for inf s')."""
    heartbeat_id = default_codec().message("Heartbeat").frame_id
    clock = SimClock()
    core = DriverCore(lambda fid, data: None, clock)
    states: list[LinkState] = []
    core.listeners.append(lambda what, c: states.append(c.state) if what == "link" else None)

    def feed(frames: list[tuple[float, int, bytes]], start: float) -> None:
        for stamp, fid, data in frames:
            if stamp >= start:
                clock.advance(max(stamp - clock.now(), 0.0))
                core.on_frame(fid, data)
                core.tick()

    frames = _mcu_frames(6.0)
    first_heartbeat = min(s for s, fid, _ in frames if fid == heartbeat_id and s >= 2.01)
    feed([f for f in frames if f[0] < first_heartbeat], 2.01)  # no Heartbeat among them
    assert core.state == LinkState.WAITING and core.stats["link_lost"] == 0
    feed([f for f in frames if f[0] < 3.0], first_heartbeat)
    assert core.state == LinkState.CONFIGURING and core.stats["link_lost"] == 0
    clock.advance(2.0)  # silence
    core.tick()
    assert core.state == LinkState.LOST and core.stats["link_lost"] == 1
    later = [(s + 2.0, fid, data) for s, fid, data in frames if s >= 3.0]
    next_heartbeat = min(s for s, fid, _ in later if fid == heartbeat_id and s >= 5.01)
    feed([f for f in later if f[0] < next_heartbeat], 5.01)
    assert core.state == LinkState.LOST and core.stats["link_lost"] == 1
    feed(later, next_heartbeat)
    assert core.state == LinkState.CONFIGURING and core.stats["link_lost"] == 1
    assert states.count(LinkState.LOST) == 1 and states[-1] == LinkState.CONFIGURING
