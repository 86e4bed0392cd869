"""The charger's contacts (lowerbase.world.charger): ``lowerbase emulate --map`` closes the BMS's
charger input while the robot truly stands on the map's charger pose and opens it when the
robot leaves. Checked on the simulated clock against what the emulator's BMS frames report
(CAN frames as driver_base reads them) and against the truth. ROS-free."""

from __future__ import annotations

import math
from typing import Any

import pytest

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.status import BmsStatus
from lowerbase.cli import build_parser
from lowerbase.cli.emulate import _install_world
from lowerbase.firmware_model.sim import SimRig
from lowerbase.world.charger import CONTACT_TOLERANCE, CONTACT_YAW, ChargerContact, on_charger
from lowerbase.world.localization.poses import compose
from lowerbase.world.places import Charger, load_places
from tests.conftest import Proc, bus_cli_args

CHARGER = load_places("empty_room").charger  # pose (1.0, 4.0, pi), approach (2.0, 4.0, pi)


def test_on_charger_is_the_5_cm_5_deg_rule() -> None:
    c = Charger((1.0, 4.0, math.pi), (2.0, 4.0, math.pi))
    assert on_charger((1.0, 4.0, -math.pi), c)  # the same heading, wrapped
    assert on_charger((1.0 + 0.9 * CONTACT_TOLERANCE, 4.0, math.pi + 0.9 * CONTACT_YAW), c)
    assert not on_charger((1.0 + 1.1 * CONTACT_TOLERANCE, 4.0, math.pi), c)
    assert not on_charger((1.0, 4.0, math.pi + 1.1 * CONTACT_YAW), c)
    assert not on_charger((1.0, 4.0, math.pi), None)


def _bms_frames(rig: SimRig, since: float) -> tuple[list[float], list[int]]:
    """(BmsPack currents [A], BmsStatus bits) sent after ``since`` [s]."""
    current = [float(s.values["Current"]) for s in rig.sent
               if s.name == "BmsPack" and s.t > since]
    status = [int(s.values["Status"]) for s in rig.sent if s.name == "BmsStatus" and s.t > since]
    return current, status


def _drive_to(rig: SimRig, start: tuple[float, float, float], x_goal: float,
              timeout: float) -> tuple[float, float, float]:
    """Drive along the robot's heading (west: yaw pi) until the TRUE map x is ``x_goal``,
    speed proportional to what is left (as a docking move on a perfect localizer)."""
    every = round(0.02 / rig.mcu.dt)
    for k in range(round(timeout / rig.mcu.dt)):
        tr = rig.mcu.truth
        pose = compose(start, (tr.x, tr.y, tr.yaw))
        if k % every == 0:
            ahead = pose[0] - x_goal  # heading west: forward decreases x
            rig.send("MotionCommand", Linear=max(-0.2, min(0.2, 1.5 * ahead)), Angular=0.0,
                     Mode="Raw")
        rig.step()
    tr = rig.mcu.truth
    return compose(start, (tr.x, tr.y, tr.yaw))


def test_emulate_map_closes_the_charger_contact_on_the_charger_pose_and_opens_it_off_it(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert CHARGER is not None
    args = build_parser().parse_args(["emulate", "--map", "empty_room", "--place",
                                      "charger_approach"])
    profile_rig = SimRig()
    bms = McuBmsAdapter.from_profile(profile_rig.profile, soc=50.0)
    rig = SimRig(profile_rig.profile, bms=bms)
    hook = _install_world(rig.mcu, args)
    assert isinstance(hook, ChargerContact)
    assert "the BMS charges while it stands on the charger" in capsys.readouterr().out
    rig.mcu.step = _with_hook(rig.mcu, hook)  # type: ignore[method-assign]
    rig.enable()
    start = CHARGER.approach
    rig.run(3.0)  # on the approach pose, 1 m in front of the charger: no contact
    current, status = _bms_frames(rig, 0.5)
    assert current and status and max(current) <= 0.0
    assert not any(s & BmsStatus.CHARGER_CONNECTED for s in status)

    pose = _drive_to(rig, start, CHARGER.pose[0], 15.0)  # onto the charger pose
    assert on_charger(pose, CHARGER)
    t_docked = rig.now
    rig.run(3.0)
    current, status = _bms_frames(rig, t_docked + 1.0)
    assert current and min(current) > 1.0  # CC charging: amperes into the pack
    assert all(s & BmsStatus.CHARGER_CONNECTED for s in status)
    out = capsys.readouterr().out
    assert out.count("charger contact closed: charging") == 1

    pose = _drive_to(rig, start, CHARGER.pose[0] + 0.5, 10.0)  # back off 0.5 m
    assert not on_charger(pose, CHARGER)
    t_left = rig.now
    rig.run(3.0)
    current, status = _bms_frames(rig, t_left + 1.0)
    assert current and max(current) <= 0.0
    assert not any(s & BmsStatus.CHARGER_CONNECTED for s in status)
    assert capsys.readouterr().out.count("charger contact opened: the robot left") == 1
    assert (hook.closings, hook.openings) == (1, 1)


def _with_hook(mcu: Any, hook: ChargerContact) -> Any:
    """``mcu.step`` followed by the hook, as the runner calls its on_step hooks."""
    inner = mcu.step

    def step() -> None:
        inner()
        hook(mcu)

    return step


def test_emulate_cli_on_the_charger_charges_and_says_so(udp_bus_config: dict[str, Any]) -> None:
    """The real command: started on the charger, the contact closes at the first step."""
    proc = Proc(["emulate", *bus_cli_args(udp_bus_config), "--simulated", "--duration", "3",
                 "--map", "empty_room", "--place", "charger", "--soc", "50", "--print"])
    proc.wait_for("charger contact closed: charging (true pose 1.000, 4.000, ")
    proc.wait_for("'Charging': 1")  # SystemStatus: the MCU sees the BMS charging
    code, err = proc.wait(60.0)
    assert code == 0, err


def test_emulate_without_a_bms_has_no_charger_hook() -> None:
    args = build_parser().parse_args(["emulate", "--map", "empty_room"])
    assert _install_world(SimRig(keep=False).mcu, args) is None
