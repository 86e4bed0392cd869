"""Reboots of the lower computer, decided from consistent evidence (SimLoop, simulated time).

A restarted emulator that says BootCounter 1 again is a reboot (its Uptime went backwards);
a forged or garbled Heartbeat with a changed BootCounter while the Uptime keeps counting is
not, and never re-enables a chassis put in standby on purpose. ``ready`` means the chassis
takes commands.
"""

from __future__ import annotations

import logging

import pytest

from lowerbase.driver.core import LinkState
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.simloop.loop import SimLoop


def ready(loop: SimLoop) -> bool:
    return loop.driver.state == LinkState.READY and loop.mcu.state.name == "ACTIVE"


def restart(loop: SimLoop, gap: float) -> None:
    """Kill the emulator, keep the driver running ``gap`` s, start a fresh one (boot #1)."""
    for _ in range(round(gap / 0.01)):
        loop.driver.tick()
        loop.clock.advance(0.01)
    loop.mcu = Mcu(loop.profile, loop.clock, loop._from_mcu, bms=None)


def heartbeat(loop: SimLoop, uptime: float, boot: int, counter: int = 0) -> None:
    msg = loop.driver.codec.message("Heartbeat")
    loop.driver.on_frame(msg.frame_id, msg.encode(
        {"Uptime": uptime, "BootCounter": boot, "Counter": counter,
         "ProtocolVersion": 1, "Overruns": 0}))


def test_restarted_emulator_with_the_same_boot_counter_is_re_enabled_ten_times_of_ten() -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    for n, gap in enumerate([0.0, 3.0] * 5, start=1):
        restart(loop, gap)
        assert loop.mcu.boot_counter == 1  # no parameter file: it says 1 again
        ready_but_ignoring = 0.0

        def watch(lp: SimLoop) -> bool:
            nonlocal ready_but_ignoring
            if lp.driver.state == LinkState.READY and lp.mcu.state.name != "ACTIVE":
                ready_but_ignoring += lp.mcu.dt
            return ready(lp)

        assert loop.run_until(watch, timeout=3.0), n
        assert loop.driver.reboots == n
        assert ready_but_ignoring <= 0.11  # at most until the next SystemStatus (100 ms)
        loop.drive(0.3, 0.0, 0.5)
        assert loop.mcu.truth.v > 0.1  # the robot obeys again


def test_a_silence_and_a_small_uptime_is_a_reboot_shown_as_lost_then_standby() -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    seen: list[str] = []
    loop.driver.listeners.append(lambda what, core: seen.append(core.state.value))
    restart(loop, 3.0)
    assert loop.driver.state == LinkState.LOST
    assert loop.run_until(ready, timeout=3.0)
    states = [s for i, s in enumerate(seen) if i == 0 or s != seen[i - 1]]
    assert states[0] == "lost" and states[-1] == "ready"
    assert "ready" not in states[1:-1]  # never "ready" while the rebooted chassis is in standby


def test_forged_heartbeats_never_enable_a_chassis_put_in_standby() -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    loop.driver.control("Standby")
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.STANDBY, timeout=1.0)
    assert loop.mcu.state.name == "STANDBY"
    enables = loop.driver.stats["tx_ControlCommand"]
    uptime = loop.now - loop.mcu.boot_time
    heartbeat(loop, uptime, loop.mcu.boot_counter + 7)  # changed BootCounter, Uptime counting
    loop.run(1.0)
    heartbeat(loop, 0.2, loop.mcu.boot_counter)  # one garbled Uptime: suspected, unconfirmed
    loop.run(3.0)
    assert loop.driver.reboots == 0
    assert loop.driver.stats["tx_ControlCommand"] == enables
    assert loop.mcu.state.name == "STANDBY"
    assert loop.driver.state == LinkState.STANDBY
    assert loop.driver.stats["heartbeat_inconsistent"] >= 1


def test_a_real_reboot_of_a_chassis_put_in_standby_on_purpose_keeps_it_in_standby() -> None:
    """The operator's hold (Standby, EStopSet) survives a reboot; EnableCanControl ends it."""
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    loop.driver.control("Standby")
    loop.run(1.0)
    loop.driver.control("Reboot")
    assert loop.run_until(lambda lp: lp.driver.reboots == 1, timeout=3.0)
    loop.run(2.0)
    assert loop.driver.state == LinkState.STANDBY and loop.mcu.state.name == "STANDBY"
    loop.driver.control("EnableCanControl")
    assert loop.run_until(ready, timeout=1.0)


def test_a_real_reboot_of_an_active_chassis_is_re_enabled() -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    loop.driver.control("Reboot")
    assert loop.run_until(lambda lp: lp.driver.reboots == 1, timeout=3.0)
    assert loop.run_until(ready, timeout=3.0)


def test_a_lost_enable_is_retried_until_the_chassis_is_in_can_control() -> None:
    loop = SimLoop(bms=None)
    dropped: list[bytes] = []
    send = loop.driver._send

    def lossy(frame_id: int, data: bytes) -> None:
        if frame_id == 0x010 and not dropped:  # the first EnableCanControl is lost
            dropped.append(data)
            return
        send(frame_id, data)

    loop.driver._send = lossy
    assert loop.run_until(ready, timeout=3.0)
    assert dropped and loop.driver.stats["tx_ControlCommand"] >= 2


def test_bus_down_is_lost_at_once_and_frames_bring_the_link_back_without_re_enabling() -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    commands = loop.driver.stats["tx_ControlCommand"]
    loop.driver.bus_down("receive failed: device gone")
    assert loop.driver.state == LinkState.LOST
    assert loop.run_until(ready, timeout=1.0)
    assert loop.driver.stats["tx_ControlCommand"] == commands
    assert loop.driver.reboots == 0


def test_a_second_lower_computer_on_the_bus_is_warned_once(
        caplog: pytest.LogCaptureFixture) -> None:
    loop = SimLoop(bms=None)
    assert loop.run_until(ready, timeout=3.0)
    other = Mcu(loop.profile, loop.clock, loop._from_mcu, bms=None)  # on the same bus
    with caplog.at_level(logging.WARNING, logger="lowerbase.driver.core"):
        loop.run(5.0, on_step=lambda lp: other.step())
    assert loop.driver.stats["two_lower_computers"] == 1
    warnings = [r.getMessage() for r in caplog.records if "two lower computers" in r.getMessage()]
    assert len(warnings) == 1 and "stop one" in warnings[0]
