"""Ask the world about contact only where contact is possible: :class:`ContactGate`.

The emulator's ground-truth integrator asks its installed
:class:`~lowerbase.firmware_model.truth.Surroundings` before every move; with surroundings
installed its lean control period runs in Python (the compiled period cannot call the world:
docs/emulator.md). Most of a shift, though, the robot is far from every wall and obstacle, and
:meth:`WorldSurroundings.allowed` answers yes and records no contact without a polygon test.

:class:`ContactGate` installs the world's surroundings in the emulator only while a move could
touch something, and takes them out while it provably cannot, so those periods run compiled.
"Provably" is a bound, not a guess: from a pose where the cheap test finds nothing
(:meth:`WorldSurroundings.free_space`: how far the footprint's circle is from the walls, the
map's edge and each obstacle's bounding circle, and how fast the people walk) and the fastest
the robot can truly move in one period (the larger of each wheel's speed, setpoint and motor
limit, times the larger true radius: a first-order lag toward a ramp bounded by these never
exceeds them, and slip only slows a wheel), every move until the robot has used up that slack
would be allowed and record nothing, exactly as if the surroundings had been asked. A robot
standing nearer a wall than that (docked on the charger) gets the footprint's own distance to
the cells, boxes and people around it instead (:meth:`WorldSurroundings.polygon_free_space`),
against the most a footprint point moves per period (the base's move plus the turn times the
circumscribed radius); there the surroundings would have run their polygon test and found
nothing, so only their ``checks`` count differs. The gate
checks before each period (one distance and a few comparisons) and installs them again as
soon as the next move might reach the slack, or when the obstacles are replaced, a slip
event is scheduled or a wheel's limits change. The robot's path, contacts and frames are the
same bits either way (tests/world/test_contact_gate.py); only who computes the period changes.

The world must be stepped through :meth:`WorldSim.step` (which calls :meth:`ContactGate.check`
first), as it is for its sensors, or :meth:`WorldSim.run_periods`, which runs a batch of
periods only after :meth:`ContactGate.clear_run` found the free space covering all of them
(the run's reach is the periods times one period's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from lowerbase.firmware_model.kinematics import motor_rpm_to_wheel_rad_s

if TYPE_CHECKING:
    from lowerbase.simloop.loop import SimLoop
    from lowerbase.world.truth import WorldSurroundings

#: [m] kept back from every slack (rounding of the distance transform and the poses)
MARGIN = 1e-6
#: periods the surroundings stay installed after a pose with no slack, before looking again
BACKOFF = 8


@dataclass(frozen=True)
class FreeSpace:
    """Measured at ``t`` [s] with the robot at (``x``, ``y``, ``yaw``) (the emulator's truth
    frame): the footprint's circle (``arm`` 0) or the footprint itself (``arm``: its
    circumscribed radius, what a turn moves its points by per radian) may move ``static`` [m]
    before the walls, the map's edge or a box could touch it, and ``moving`` [m] minus what the
    people walk at up to ``speed`` [m/s] before a person could; a point of it moves at most
    ``reach`` [m] per period; it holds while ``inputs`` (obstacles, geometries) are the same
    objects."""

    x: float
    y: float
    yaw: float
    arm: float
    t: float
    static: float
    moving: float
    speed: float
    reach: float
    inputs: tuple[object, ...]

    def holds(self, x: float, y: float, yaw: float, t_end: float) -> bool:
        """Can the move from (x, y, yaw) ending at ``t_end`` touch nothing?"""
        d = math.hypot(x - self.x, y - self.y) + self.arm * abs(yaw - self.yaw) + self.reach
        return d < self.static and d + self.speed * (t_end - self.t) < self.moving


class ContactGate:
    """Installs ``surroundings`` in ``loop``'s emulator only while a move may touch something
    (see the module docstring); ``enabled=False``: always installed (the reference)."""

    def __init__(self, loop: SimLoop, surroundings: WorldSurroundings,
                 enabled: bool = True) -> None:
        self.loop = loop
        self.surroundings = surroundings
        self.enabled = enabled
        self.skipped = 0  #: periods run without asking the surroundings
        self._free: FreeSpace | None = None
        self._wait = 0  #: periods left before the free space is measured again
        loop.surroundings = surroundings

    def _inputs(self) -> tuple[object, ...]:
        mcu = self.loop.mcu
        ml, mr = mcu.motors["left"], mcu.motors["right"]
        return (self.surroundings.obstacles.items, mcu.truth.geometry, ml.geometry,
                mr.geometry)

    def _reach(self, arm: float = 0.0) -> float:
        """[m] the most the base centre (``arm`` 0) or a point ``arm`` [m] from it can truly
        move in one control period, now and for as long as the wheels' geometries stay (see
        the module docstring; a turn is at most the wheels' speed difference over the track)."""
        mcu = self.loop.mcu
        w = 0.0
        for m in mcu.motors.values():
            g = m.geometry
            w = max(w, abs(m.omega), abs(m.setpoint), motor_rpm_to_wheel_rad_s(g.max_rpm, g.ratio))
        tg = mcu.truth.geometry
        v = w * max(tg.radius_left, tg.radius_right) * mcu.dt
        return v + arm * 2.0 * v / tg.track

    def _standing(self) -> bool:
        return all(m.setpoint == 0.0 for m in self.loop.mcu.motors.values())

    def check(self) -> None:
        """Before a control period: take the surroundings out if the coming move cannot touch
        anything, else install them."""
        loop = self.loop
        mcu = loop.mcu
        truth = mcu.truth
        if self.enabled and not mcu.slip.events:
            t_end = loop.now + mcu.dt
            f = self._free
            if f is not None and f.inputs == self._inputs() \
                    and f.holds(truth.x, truth.y, truth.yaw, t_end):
                truth.surroundings = None
                self.skipped += 1
                return
            self._free = None
            if self._wait > 0:
                self._wait -= 1
            else:
                f = self._measure()
                if f is not None and f.holds(truth.x, truth.y, truth.yaw, t_end):
                    self._free = f
                    truth.surroundings = None
                    self.skipped += 1
                    return
                self._wait = BACKOFF
        else:
            self._free = None
        truth.surroundings = self.surroundings

    def clear_run(self, periods: int) -> bool:
        """Take the surroundings out for the next ``periods`` periods at once if the free space
        measured covers them all (the run's last period ends at most ``periods`` reaches from
        the robot's pose now, and the people walk at most until then), as :meth:`check` before
        each of them would have: True and out, else False and nothing changed."""
        loop = self.loop
        mcu = loop.mcu
        f = self._free
        if not self.enabled or mcu.slip.events or f is None or f.inputs != self._inputs():
            return False
        truth = mcu.truth
        d = math.hypot(truth.x - f.x, truth.y - f.y) + f.arm * abs(truth.yaw - f.yaw) \
            + periods * f.reach
        t_end = loop.now + periods * mcu.dt * (1.0 + 1e-9)
        if not (d < f.static and d + f.speed * (t_end - f.t) < f.moving):
            return False
        truth.surroundings = None
        self.skipped += periods
        return True

    def _measure(self) -> FreeSpace | None:
        """The free space around the robot now: the circle's, else (standing, e.g. docked
        near a wall) the footprint's."""
        truth = self.loop.mcu.truth
        sur = self.surroundings
        if sur.contact is not None:
            return None  # touching: the next move is the surroundings' to judge
        t = self.loop.now
        pose = (truth.x, truth.y, truth.yaw)
        space = sur.free_space(pose, t)
        if space is None:
            return None
        arm, reach = 0.0, self._reach()
        if min(space[0], space[1]) <= reach and self._standing():
            arm = sur.footprint.radius
            space = sur.polygon_free_space(pose, t)
            if space is None:
                return None
            reach = self._reach(arm)
        static, moving, speed = space
        return FreeSpace(truth.x, truth.y, truth.yaw, arm, t, static - MARGIN, moving - MARGIN,
                         speed, reach, self._inputs())
