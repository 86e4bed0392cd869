"""SimLoop's batched periods (one ``Mcu.advance`` up to the driver's next possible send) against
the same loop stepped period by period: the same frames each way at the same times, the same
/odom_raw and /odom, the same ground truth, bit for bit.

The stepped reference is the loop's own ``step()`` (``on_step`` given: no batching). Frames
are recorded where they are taken: the driver's ``on_frame`` (with the stamp it is handed and
the time its clock shows then) and the MCU's ``receive`` (with the clock's time, when the MCU
takes a command).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from lowerbase.driver.core import LinkState
from lowerbase.firmware_model.profile import load_profile
from lowerbase.simloop.loop import SimLoop

Frame = tuple[float, int, bytes]


def _recording(loop: SimLoop) -> tuple[list[tuple[float, Frame]], list[Frame], list[Frame]]:
    """(frames the driver was handed, with its clock's time then; frames the MCU took; frames
    the driver sent, at its clock's time), recorded from now on."""
    to_driver: list[tuple[float, Frame]] = []
    to_mcu: list[Frame] = []
    sent: list[Frame] = []
    on_frame, receive, send = loop.driver.on_frame, loop.mcu.receive, loop.driver._send
    advance = loop.mcu.advance

    def driver_gets(frame_id: int, data: bytes, stamp: float | None = None) -> None:
        assert stamp is not None
        to_driver.append((loop.driver.clock.now(), (stamp, frame_id, bytes(data))))
        on_frame(frame_id, data, stamp)

    def mcu_gets(frame_id: int, data: bytes) -> None:
        to_mcu.append((loop.clock.now(), frame_id, bytes(data)))
        receive(frame_id, data)

    def driver_sends(frame_id: int, data: bytes) -> None:
        sent.append((loop.driver.clock.now(), frame_id, bytes(data)))
        send(frame_id, data)

    def mcu_advances(periods: int, incoming: Any = ()) -> None:
        """Mcu.advance: the frames it is handed are taken before their periods (a compiled
        run takes a repeated MotionCommand without ``receive``): recorded at those times."""
        t = loop.clock.now()
        times = []
        for _ in range(periods):
            times.append(t)
            t += loop.mcu.dt  # as the clock advances
        to_mcu.extend((times[k], frame_id, bytes(data)) for k, frame_id, data in incoming)
        loop.mcu.receive = receive  # type: ignore[method-assign]
        try:
            advance(periods, incoming)
        finally:
            loop.mcu.receive = mcu_gets  # type: ignore[method-assign]

    loop.driver.on_frame = driver_gets  # type: ignore[method-assign]
    loop.mcu.receive = mcu_gets  # type: ignore[method-assign]
    loop.mcu.advance = mcu_advances  # type: ignore[method-assign]
    loop.driver._send = driver_sends
    return to_driver, to_mcu, sent


def _state(loop: SimLoop) -> dict[str, Any]:
    """What the driver publishes and the truth, as exact values (floats and array bytes)."""
    odo, ekf, truth = loop.driver.odometry, loop.driver.ekf, loop.mcu.truth
    assert odo is not None
    return {
        "now": loop.now, "driver_now": loop.driver.clock.now(),
        "odom_raw": (odo.x, odo.y, odo.yaw_unwrapped, odo.linear, odo.angular,
                     odo.pose_covariance, odo.twist_covariance),
        "odom": (ekf.kf.x.tobytes(), ekf.kf.P.tobytes(), ekf.yaw_unwrapped, ekf.stamp),
        "truth": (truth.x, truth.y, truth.yaw, truth.v, truth.w, truth.distance),
        "driver_stats": dict(loop.driver.stats), "link": loop.driver.state,
        "imu": loop.driver.imu, "odometer": loop.driver.odometer,
    }


def _script(loop: SimLoop, stepped: bool) -> list[dict[str, Any]]:
    """Start, drive (raw and smoothed twists, turns), let the twist go stale (the driver's
    final stop, the MCU's watchdog), stand, drive again; the state after each part."""
    each: Callable[[SimLoop], None] | None = (lambda lp: None) if stepped else None
    states = []
    loop.run(1.0, on_step=each)
    assert loop.driver.state == LinkState.READY
    for linear, angular, seconds, smoothed in ((0.5, 0.0, 1.5, False), (0.8, 0.4, 2.0, True),
                                               (0.0, -0.6, 1.0, False), (0.3, 0.1, 0.73, True)):
        loop.drive(linear, angular, seconds, smoothed, on_step=each)
        states.append(_state(loop))
    loop.run(2.0, on_step=each)  # no twist: stale after command_timeout, a stop, standing
    states.append(_state(loop))
    loop.drive(0.4, -0.2, 1.0, on_step=each)
    loop.run(0.333, on_step=each)
    states.append(_state(loop))
    return states


@pytest.mark.parametrize("profile_kw", [{}, {"slip": True}])
def test_batched_periods_match_single_steps_bit_for_bit(profile_kw: dict[str, bool]) -> None:
    def make() -> SimLoop:
        p = load_profile()
        if profile_kw.get("slip"):
            import dataclasses

            p = p.replace(truth=dataclasses.replace(
                p.truth, right_radius_error=0.01, accel_slip_threshold=2.0,
                accel_slip_fraction=0.03))
        return SimLoop(p)

    stepped, batched = make(), make()
    rec_s, rec_b = _recording(stepped), _recording(batched)
    states_s = _script(stepped, stepped=True)
    states_b = _script(batched, stepped=False)
    assert rec_b[0] == rec_s[0]  # every frame the driver got, with its stamp and clock
    assert rec_b[1] == rec_s[1]  # every command the MCU took, at its time
    assert rec_b[2] == rec_s[2]  # every frame the driver sent, at its time
    assert len(rec_s[1]) > 100
    for b, s in zip(states_b, states_s, strict=True):
        assert b == s
    assert stepped.batch_stats["periods"] == 0
    # most periods ran in batches, and none had a command sent early
    assert batched.batch_stats["periods"] > 0.8 * round(batched.now / batched.control_dt)
    assert batched.batch_stats["mistimed"] == 0


def test_single_periods_run_as_batches_bit_for_bit() -> None:
    """The lockstep robot's jobs cut many runs to one period: ``advance(1)`` is then a batch of
    one (one compiled run instead of a step), with the frames, commands and state of
    ``step()``, bit for bit, across twist changes, a stale twist and standing."""
    stepped, single = SimLoop(), SimLoop()
    rec_s, rec_b = _recording(stepped), _recording(single)
    for loop in (stepped, single):
        loop.run(1.0, on_step=lambda lp: None)
    assert single.driver.state == LinkState.READY
    states: tuple[list[dict[str, Any]], list[dict[str, Any]]] = ([], [])
    for i in range(900):  # 4.5 s: a twist each 50 ms for 3 s, then none (stale, a stop)
        for loop, out in ((stepped, states[0]), (single, states[1])):
            if i % 10 == 0 and i < 600:
                loop.driver.set_twist(0.6 if i < 400 else 0.0, 0.3 if i % 70 < 40 else -0.4,
                                      i % 200 < 100)
            if loop is stepped:
                loop.step()
            else:
                loop.advance(1)
            if i % 50 == 49:
                out.append(_state(loop))
    assert rec_b == rec_s  # every frame each way, at its time
    assert states[1] == states[0]
    assert stepped.batch_stats["periods"] == 0
    assert single.batch_stats["batches"] == single.batch_stats["periods"] > 700
    assert single.batch_stats["mistimed"] == 0


def test_no_batching_while_something_else_may_send() -> None:
    """A listener (it may send, or read the truth) or a tap keeps the loop stepping."""
    loop = SimLoop()
    loop.run(1.0)
    before = loop.batch_stats["periods"]
    loop.driver.listeners.append(lambda what, core: None)
    loop.drive(0.5, 0.0, 0.5)
    assert loop.batch_stats["periods"] == before
    tapped = SimLoop(tap=lambda t, side, frame_id, data: None)
    tapped.run(1.0)
    tapped.drive(0.5, 0.0, 0.5)
    assert tapped.batch_stats["periods"] == 0


def test_a_send_inside_a_batch_is_counted_and_ends_batching() -> None:
    """The safety net: a driver that sends while handling a frame of a batch's earlier period
    (nothing in the driver does; here a wrapped on_frame) is counted, and the loop steps from
    then on (where the send reaches the MCU when it should)."""
    loop = SimLoop()
    loop.run(1.0)
    loop.drive(0.5, 0.0, 0.2)
    assert loop.batch_stats["mistimed"] == 0 and loop.batch_stats["periods"] > 0
    on_frame = loop.driver.on_frame
    sent: list[float | None] = []

    def sends_once(frame_id: int, data: bytes, stamp: float | None = None) -> None:
        on_frame(frame_id, data, stamp)
        if not sent:
            sent.append(stamp)
            loop.driver.control("FaultClear")

    loop.driver.on_frame = sends_once  # type: ignore[method-assign]
    loop.drive(0.5, 0.0, 0.2)
    assert sent and loop.batch_stats["mistimed"] == 1
    periods = loop.batch_stats["periods"]
    loop.drive(0.5, 0.0, 0.5)
    assert loop.batch_stats["periods"] == periods


def test_a_frame_that_changes_the_ticks_inside_a_batch_is_counted() -> None:
    """The ticks of a batch run before its frames are handled: a frame that would have made
    them send something else (here: an enable wanted, as after a reboot) is counted, and the
    loop steps from then on."""
    loop = SimLoop()
    loop.run(1.0)
    loop.drive(0.5, 0.0, 0.2)
    assert loop.batch_stats["mistimed"] == 0 and loop.batch_stats["periods"] > 0
    on_frame = loop.driver.on_frame

    def wants_enable(frame_id: int, data: bytes, stamp: float | None = None) -> None:
        on_frame(frame_id, data, stamp)
        loop.driver._enable_wanted = True

    loop.driver.on_frame = wants_enable  # type: ignore[method-assign]
    loop.drive(0.5, 0.0, 0.2)
    assert loop.batch_stats["mistimed"] == 1
    periods = loop.batch_stats["periods"]
    loop.drive(0.5, 0.0, 0.5)
    assert loop.batch_stats["periods"] == periods
