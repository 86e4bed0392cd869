"""driver_base's services without ROS: the table and send_control against the emulated MCU
(SimLoop, simulated clock). The ROS side (std_srvs over a real master) is in test_node_ros.py."""

from __future__ import annotations

from lowerbase.driver.core import LinkState
from lowerbase.driver.services import ESTOP, TRIGGERS, send_control
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.simloop.loop import SimLoop


def ready(loop: SimLoop) -> bool:
    return loop.driver.state == LinkState.READY and loop.mcu.state.name == "ACTIVE"


def test_every_service_names_a_control_command_of_the_catalog() -> None:
    loop = SimLoop()
    choices = set(loop.driver.codec.message("ControlCommand").signal("Command").choices.values())
    assert {*TRIGGERS.values(), *ESTOP[1:]} <= choices
    assert len({*TRIGGERS, ESTOP[0]}) == 6


def test_estop_release_and_enable_let_the_robot_drive_again() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    assert send_control(loop.driver, "EStopSet") == (True, "EStopSet sent")
    loop.run(0.3)
    assert loop.mcu.status & StatusBit.ESTOP_COMMAND
    assert send_control(loop.driver, "EStopRelease")[0]
    loop.run(0.3)
    assert not loop.mcu.status & StatusBit.ESTOP_COMMAND
    loop.drive(0.3, 0.0, 0.5)
    assert loop.mcu.truth.v == 0.0  # released into standby: not driving until enabled
    assert send_control(loop.driver, "EnableCanControl")[0]
    loop.drive(0.3, 0.0, 1.0)
    assert loop.mcu.truth.v > 0.2


def test_refused_while_the_link_is_not_up() -> None:
    loop = SimLoop()
    assert loop.driver.state == LinkState.WAITING
    sent = loop.driver.stats["tx_ControlCommand"]
    ok, message = send_control(loop.driver, "Reboot")
    assert not ok and "link is waiting" in message and "\n" not in message
    assert loop.driver.stats["tx_ControlCommand"] == sent
    assert loop.driver.stats["service_refused"] == 1


def test_an_estopped_chassis_rebooted_through_the_service_stays_held_until_enabled() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    assert send_control(loop.driver, "EStopSet")[0]
    loop.run(0.3)
    assert send_control(loop.driver, "Reboot")[0]
    assert loop.run_until(lambda lp: lp.driver.reboots == 1
                          and lp.driver.state == LinkState.STANDBY, timeout=3.0)
    loop.drive(0.3, 0.0, 2.0)  # the hold survives the reboot: no automatic enable
    assert loop.mcu.truth.v == 0.0 and loop.mcu.state.name == "STANDBY"
    assert loop.driver.state == LinkState.STANDBY
    assert send_control(loop.driver, "EnableCanControl") == (True, "EnableCanControl sent")
    loop.drive(0.3, 0.0, 1.0)
    assert loop.mcu.truth.v > 0.2


def test_enable_is_refused_while_estopped_and_allowed_right_after_the_release() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    assert send_control(loop.driver, "EStopSet")[0]
    loop.run(0.3)
    refused = loop.driver.stats["service_refused"]
    assert send_control(loop.driver, "EnableCanControl") == (
        False, "e-stopped: call ~estop false first")
    assert loop.driver.stats["service_refused"] == refused + 1
    loop.drive(0.3, 0.0, 0.5)
    assert loop.mcu.truth.v == 0.0
    # `rosservice call ~estop false && rosservice call ~enable`: no wait for the status
    assert send_control(loop.driver, "EStopRelease")[0]
    assert send_control(loop.driver, "EnableCanControl")[0]
    loop.drive(0.3, 0.0, 1.0)
    assert loop.mcu.truth.v > 0.2


def test_a_pressed_estop_button_also_refuses_enable() -> None:
    loop = SimLoop()
    assert loop.run_until(ready, timeout=3.0)
    loop.mcu.inject("estop@0+5")
    loop.run(0.3)
    assert loop.mcu.status & StatusBit.ESTOP_BUTTON
    assert send_control(loop.driver, "EnableCanControl")[1].startswith("e-stopped")
