"""/odom_raw and /odom continue without a jump when the lower computer goes away and comes back.

SimLoop on a simulated clock. Across an emulator restart (a new Mcu at the same true pose,
counters from 0) and across a bus that is down for 5 s while a twist is being sent, both poses
may change by at most what the robot truly moved (ground truth) plus a small epsilon: no
backwards jump to 0 (encoder reset taken as motion), no forward jump (the EKF predicting at
the last velocity through the outage).
"""

from __future__ import annotations

import math

import pytest

from lowerbase.driver.core import LinkState
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.simloop.loop import SimLoop

EPS = 0.01  # [m] a wheel cycle or two of motion, EKF smoothing


def ready(loop: SimLoop) -> bool:
    return loop.driver.state == LinkState.READY and loop.mcu.state.name == "ACTIVE"


def poses(loop: SimLoop) -> tuple[tuple[float, float], tuple[float, float]]:
    odo = loop.driver.odometry
    assert odo is not None
    x, y, _ = loop.driver.ekf.pose
    return (odo.x, odo.y), (x, y)


def started(linear: float) -> SimLoop:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    loop.drive(linear, 0.0, 3.0)
    assert loop.mcu.truth.v == pytest.approx(linear, abs=0.02)
    return loop


def restart(loop: SimLoop, gap: float, linear: float) -> None:
    """Kill the emulator (the robot stops where it is), keep the driver running ``gap`` s with
    the twist still published, then start a fresh emulator (boot #1, counters 0) at that pose."""
    truth = loop.mcu.truth
    for k in range(round(gap / 0.01)):
        if k % 5 == 0:
            loop.driver.set_twist(linear, 0.0)
        loop.driver.tick()
        loop.clock.advance(0.01)
    loop._to_mcu.clear()
    loop.mcu = Mcu(loop.profile, loop.clock, loop._from_mcu, bms=None)
    loop.mcu.truth.x, loop.mcu.truth.y, loop.mcu.truth.yaw = truth.x, truth.y, truth.yaw


def moved(before: tuple[float, float], after: tuple[float, float]) -> float:
    return math.dist(before, after)


@pytest.mark.parametrize("gap", [0.0, 0.3, 3.0])
def test_an_emulator_restart_moves_neither_odom_raw_nor_odom(gap: float) -> None:
    loop = started(0.2)
    raw0, odom0 = poses(loop)
    assert raw0[0] > 0.4  # it has driven away from 0: a reset to 0 would show
    restart(loop, gap, 0.2)
    assert loop.run_until(ready, timeout=3.0)
    assert loop.driver.reboots == 1
    loop.run(1.0)  # standing (the twist went stale while it was down)
    raw1, odom1 = poses(loop)
    assert moved(raw0, raw1) <= EPS
    assert moved(odom0, odom1) <= EPS
    # and it goes on counting from there
    start = loop.mcu.truth.distance
    loop.drive(0.2, 0.0, 2.0)
    loop.run(1.0)
    truly = loop.mcu.truth.distance - start
    raw2, odom2 = poses(loop)
    assert raw2[0] - raw1[0] == pytest.approx(truly, abs=0.02)
    assert odom2[0] - odom1[0] == pytest.approx(truly, abs=0.02)


def test_a_bus_down_for_5_s_while_driving_jumps_by_no_more_than_the_true_motion() -> None:
    loop = started(0.2)
    raw0, odom0 = poses(loop)
    truth0 = (loop.mcu.truth.x, loop.mcu.truth.y)
    loop.driver.bus_down("receive failed: device gone")
    for k in range(500):  # 5 s: the MCU runs on, nothing gets through either way
        if k % 5 == 0:
            loop.driver.set_twist(0.2, 0.0)
        loop._to_mcu.clear()
        loop.mcu.step()
        loop._to_driver.clear()
        loop.driver.tick()
        loop.clock.advance(loop.mcu.dt)
    assert loop.driver.state == LinkState.LOST
    truly = moved(truth0, (loop.mcu.truth.x, loop.mcu.truth.y))  # until its watchdog stopped it
    assert 0.05 < truly < 0.3
    assert loop.run_until(ready, timeout=3.0)
    loop.run(0.5)
    raw1, odom1 = poses(loop)
    assert moved(raw0, raw1) <= truly + EPS
    assert moved(odom0, odom1) <= truly + EPS
    assert raw1[0] >= raw0[0] - EPS and odom1[0] >= odom0[0] - EPS  # never backwards
    assert loop.driver.reboots == 0


def test_while_the_link_is_lost_the_ekf_holds_the_pose_and_zeroes_its_velocity() -> None:
    loop = started(0.2)
    loop.driver.bus_down("device gone")
    _, odom0 = poses(loop)
    var0 = loop.driver.ekf.pose_covariance()[0, 0]
    v, w = loop.driver.ekf.twist
    assert v == 0.0 and w == 0.0
    assert loop.driver.ekf.pose_covariance()[0, 0] >= var0
    loop.clock.advance(5.0)
    loop.driver.tick()
    _, odom1 = poses(loop)
    assert odom1 == odom0


def wheels(loop: SimLoop, stamp: float, counter: int, left: int, right: int) -> None:
    """One WheelFeedback cycle (both wheels) straight into the driver at ``stamp``."""
    wf = loop.driver.codec.message("WheelFeedback")
    for wheel, side, count in ((0, "Left", left), (1, "Right", right)):
        loop.driver.on_frame(wf.frame_id, wf.encode(
            {"Wheel": wheel, f"{side}Count": count, f"{side}Velocity": 0.0,
             f"{side}Current": 0.0, f"{side}DriverStatus": 0, "Counter": counter & 0xF}),
            stamp)


def last_cycle(loop: SimLoop) -> tuple[float, int, int, int]:
    """Time, Counter and counts of the last wheel cycle the driver took (no MCU steps after)."""
    enc = loop.mcu._encoders
    t, counter = loop.driver._last_wheel  # type: ignore[misc]
    return t, counter, enc["left"].count, enc["right"].count


@pytest.fixture
def stopped() -> SimLoop:
    loop = started(0.2)
    loop.run(1.5)  # at rest, the EKF's standstill reached; then the MCU is no longer stepped
    return loop


def metres_per_pulse(loop: SimLoop) -> float:
    odo = loop.driver.odometry
    assert odo is not None
    return odo.params.metres_per_pulse_left


def test_lost_cycles_with_a_consistent_counter_are_integrated(stopped: SimLoop) -> None:
    loop = stopped
    t, c, left, right = last_cycle(loop)
    raw0, _ = poses(loop)
    n = 2000  # 10 cycles lost: the counts still add up
    wheels(loop, t + 0.22, c + 11, left + n, right + n)
    raw1, _ = poses(loop)
    assert raw1[0] - raw0[0] == pytest.approx(n * metres_per_pulse(loop), rel=1e-6)
    assert loop.driver.stats["odometry_rebaselined"] == 0


@pytest.mark.parametrize("dt, step", [(0.3, 15), (1.0, 50), (0.02, 9), (0.04, 6)])
def test_a_gap_or_a_counter_discontinuity_is_a_new_baseline(
        stopped: SimLoop, dt: float, step: int) -> None:
    """A reboot whose Heartbeat was lost: counters back near 0 (a plausible small jump)."""
    loop = stopped
    t, c, _, _ = last_cycle(loop)
    raw0, odom0 = poses(loop)
    wheels(loop, t + dt, c + step, 40, 40)  # -left pulses: backwards if integrated
    assert poses(loop) == (raw0, odom0)
    assert loop.driver.stats["odometry_rebaselined"] == 1
    wheels(loop, t + dt + 0.02, c + step + 1, 140, 140)  # then on from the new baseline
    raw2, _ = poses(loop)
    assert raw2[0] - raw0[0] == pytest.approx(100 * metres_per_pulse(loop), rel=1e-6)


def test_a_suspected_reboot_makes_the_next_sample_a_baseline(stopped: SimLoop) -> None:
    loop = stopped
    t, c, left, right = last_cycle(loop)
    raw0, odom0 = poses(loop)
    hb = loop.driver.codec.message("Heartbeat")
    loop.driver.on_frame(hb.frame_id, hb.encode(
        {"Uptime": 0.0, "BootCounter": 1, "Counter": 0,
         "ProtocolVersion": 1, "Overruns": 0}), t + 0.01)
    wheels(loop, t + 0.02, c + 1, left - 10, right - 10)  # 10 pulses back: plausible motion
    assert poses(loop) == (raw0, odom0)


def test_frames_lost_past_the_counters_wrap_are_integrated_over_their_true_interval(
        stopped: SimLoop) -> None:
    """21 cycles with no sample while driving at 0.5 m/s: the Counter says 5 (21 mod 16);
    the counts and the last speed say 21. Integrated over 21 cycles: the distance all there,
    the speed 0.5 m/s, not 2.1 (issue 22 items 1 and 2)."""
    loop = stopped
    mpp = metres_per_pulse(loop)
    per_cycle = round(0.5 * 0.02 / mpp)  # pulses per 20 ms at 0.5 m/s
    t, c, left, right = last_cycle(loop)
    for k in range(1, 11):  # 10 cycles at 0.5 m/s: the wheels' speed is known
        wheels(loop, t + 0.02 * k, c + k, left + k * per_cycle, right + k * per_cycle)
    raw0, _ = poses(loop)
    t, c, left, right = t + 0.2, c + 10, left + 10 * per_cycle, right + 10 * per_cycle
    wheels(loop, t + 21 * 0.02, c + 21, left + 21 * per_cycle, right + 21 * per_cycle)
    raw1, _ = poses(loop)
    odo = loop.driver.odometry
    assert odo is not None
    assert raw1[0] - raw0[0] == pytest.approx(21 * per_cycle * mpp, rel=1e-6)
    assert odo.linear == pytest.approx(0.5, rel=0.02)
    assert loop.driver.stats["odometry_rebaselined"] == 0
