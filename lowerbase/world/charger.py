"""The charging station's contacts: closed while the robot truly stands on the charger pose.

One rule for every simulation: the contacts touch when the robot's TRUE pose is within
:data:`CONTACT_TOLERANCE` (position) and :data:`CONTACT_YAW` (heading) of the map's charger
pose (the places sidecar's ``charger.pose``). Closing them is the emulator's charger input
(``mcu.bms.connect_charger``): the BMS then charges CC-CV and reports the charger in its
frames, which is all driver_base and the task machine see.

- :func:`on_charger`: the rule (``TaskSim`` asks it in process).
- :class:`ChargerContact`: the same rule as an MCU runner ``on_step`` hook, for ``lowerbase
  emulate --map`` (which has the map, its places and the true pose): it closes the contact
  when the robot arrives and opens it when it leaves, with one line each time. It reads the
  truth and writes only the BMS's charger input (the firmware model never imports the world).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from lowerbase.bms.status import ChargeMode
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.localization.poses import Pose2D, compose, wrap_scalar
from lowerbase.world.places import Charger, load_places

#: [m] how far the robot's centre may be from the charger pose with the contacts touching
CONTACT_TOLERANCE = 0.05
#: [rad] how far its heading may be from the charger pose's
CONTACT_YAW = math.radians(5.0)


def on_charger(pose: Pose2D, charger: Charger | None, tolerance: float = CONTACT_TOLERANCE,
               yaw_tolerance: float = CONTACT_YAW) -> bool:
    """Does the robot at ``pose`` (map frame, true) stand on ``charger``'s contacts?"""
    if charger is None:
        return False
    x, y, yaw = pose
    cx, cy, cyaw = charger.pose
    return math.hypot(x - cx, y - cy) <= tolerance and abs(wrap_scalar(yaw - cyaw)) <= yaw_tolerance


class ChargerContact:
    """MCU runner ``on_step`` hook: the BMS's charger input follows :func:`on_charger` of the
    robot's true pose (``mcu.truth``, placed on the map by ``map_from_truth``).

    Acts only on changes: a charger connected otherwise (``lowerbase emulate --charger``) stays
    connected until the robot has stood on the charger and left it. ``announce`` gets one line
    per change; ``closings`` / ``openings`` count them."""

    def __init__(self, charger: Charger, map_from_truth: Pose2D = (0.0, 0.0, 0.0),
                 announce: Callable[[str], None] | None = None) -> None:
        self.charger = charger
        self.map_from_truth = map_from_truth
        self.announce = announce
        self.closed = False
        self.closings = 0
        self.openings = 0

    def __call__(self, mcu: Any) -> None:
        tr = mcu.truth
        pose = compose(self.map_from_truth, (tr.x, tr.y, tr.yaw))
        on = on_charger(pose, self.charger)
        if on == self.closed:
            return
        self.closed = on
        bms = mcu.bms
        if on:
            self.closings += 1
            if bms is not None:
                bms.connect_charger(ChargeMode.AUTO)
        else:
            self.openings += 1
            if bms is not None:
                bms.disconnect_charger()
        if self.announce is not None:
            what = "closed: charging" if on else "opened: the robot left the charger"
            self.announce(f"charger contact {what} (true pose {pose[0]:.3f}, {pose[1]:.3f}, "
                          f"{math.degrees(pose[2]):.1f} deg; at {mcu.clock.now():.2f} s)")

    def close(self) -> None:
        """Nothing to release (the runner hooks' interface)."""


def contact_for(mcu: Any, map_ref: str, grid: OccupancyGrid, map_from_truth: Pose2D,
                announce: Callable[[str], None] | None = None) -> ChargerContact | None:
    """The hook for an emulator on the map ``map_ref`` (its places sidecar's charger), or None
    when the map has no charger or the MCU no BMS of its own (nothing to close)."""
    charger = load_places(map_ref, grid).charger
    if charger is None or mcu.bms is None or getattr(mcu.bms, "device", True) is None:
        return None  # no charger on the map, no BMS, or an external one (lowerbase bms)
    return ChargerContact(charger, map_from_truth, announce)
