"""A deterministic bench for the task machine: a fake navigation (go-to-goal on a perfect
unicycle, or a scripted outcome) and fake chassis inputs (a charger contact where the robot
stands on the charger pose, a battery that charges at a fixed rate)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from lowerbase.navigation.navigator import NavigationError
from lowerbase.tasks.machine import TaskMachine
from lowerbase.tasks.model import Pose, TaskRequest, TaskResponse
from lowerbase.tasks.plan import TaskConfig
from lowerbase.tasks.status import Chassis
from lowerbase.world.places import Charger, Places

PLACES = Places(storage={"S1": (4.0, 0.0, 0.0), "S2": (4.0, 3.0, math.pi / 2)},
                charger=Charger((0.0, -2.0, -math.pi / 2), (0.0, -1.0, -math.pi / 2)),
                poses={"start": (0.0, 0.0, 0.0)})
DT = 0.05


@dataclass
class Fb:
    linear: float
    angular: float
    state: Any
    status: str = ""
    reason: str = ""


@dataclass(frozen=True)
class State:
    name: str


class FakeNav:
    """Turn to the target, drive to it, turn to its heading; or ``force`` a goal state."""

    def __init__(self) -> None:
        self.goals: list[tuple[Pose, tuple[Pose, ...], float]] = []
        self.cancels: list[float] = []
        self.goal: Pose | None = None
        self.force: str | None = None
        self.status = ""
        self.reason = ""

    def send_goal(self, target: Pose, poses: Sequence[Pose] = (), execution_mode: int = 0,
                  now: float = 0.0) -> None:
        if not -50 < target[0] < 50:
            raise NavigationError(f"the goal ({target[0]:.2f}, {target[1]:.2f}) is off the map")
        self.goals.append((target, tuple(poses), now))
        self.goal = target

    def cancel(self, now: float) -> None:
        self.cancels.append(now)
        self.goal = None

    def tick(self, now: float, pose: Pose) -> Fb:
        if self.force is not None:
            return Fb(0.0, 0.0, State(self.force), self.status, self.reason)
        if self.goal is None:
            return Fb(0.0, 0.0, State("PENDING"))
        gx, gy, gyaw = self.goal
        dx, dy = gx - pose[0], gy - pose[1]
        dist = math.hypot(dx, dy)
        if dist > 0.005:
            turn = _wrap(math.atan2(dy, dx) - pose[2])
            if abs(turn) > 0.01:
                return Fb(0.0, max(-1.0, min(1.0, turn / DT)), State("ACTIVE"))
            return Fb(min(1.0, dist / DT), turn / DT, State("ACTIVE"))
        turn = _wrap(gyaw - pose[2])
        if abs(turn) > 0.001:
            return Fb(0.0, max(-1.0, min(1.0, turn / DT)), State("ACTIVE"))
        self.goal = None
        return Fb(0.0, 0.0, State("SUCCEEDED"), "", "")


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class Bench:
    """Ticks the machine at 20 Hz; the chassis follows its twist exactly (unicycle)."""

    def __init__(self, config: TaskConfig | None = None, places: Places = PLACES,
                 soc: float = 80.0, charge_rate: float = 1.0) -> None:
        self.nav = FakeNav()
        self.machine = TaskMachine(self.nav, places, config or TaskConfig(
            load_time=3.0, unload_time=2.0, dock_timeout=1.0))
        self.now = 0.0
        self.pose: Pose = (0.0, 0.0, 0.0)
        self.soc = soc
        self.charge_rate = charge_rate  #: [%/s] while on the charger
        self.charger_works = True
        self.ch = Chassis(pose=self.pose, odom=self.pose, soc=soc)
        #: the share of the travel that odometry reports (< 1: it loses motion, as a driver
        #: dropping wheel samples does); the localization stays the true pose
        self.odom_scale = 1.0
        self.odom: Pose = self.pose
        #: a wall at this y (the robot is held above it, wheels and odometry stopped), or None
        self.wall_y: float | None = None
        self.twists: list[tuple[float, float] | None] = []

    def set(self, **kw: Any) -> None:
        self.soc = kw.get("soc", self.soc)
        self.ch = replace(self.ch, **kw)

    def on_charger(self) -> bool:
        c = self.machine.places.charger
        return c is not None and self.charger_works and math.hypot(self.pose[0] - c.pose[0],
                                                 self.pose[1] - c.pose[1]) < 0.02

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            contact = self.on_charger()
            if contact:
                self.soc = min(100.0, self.soc + self.charge_rate * DT)
            pose = self.pose if self.ch.localized else None
            self.ch = replace(self.ch, pose=pose, odom=self.odom, charging=contact,
                              soc=self.soc)
            twist = self.machine.tick(self.now, self.ch)
            self.twists.append(twist)
            if twist is not None:
                v, w = twist
                x, y, yaw = self.pose
                if self.wall_y is not None and y + v * DT * math.sin(yaw) < self.wall_y:
                    v = w = 0.0  # held by the wall, as the emulator does
                self.pose = (x + v * DT * math.cos(yaw), y + v * DT * math.sin(yaw),
                             _wrap(yaw + w * DT))
                ox, oy, oyaw = self.odom
                d = v * DT * self.odom_scale
                self.odom = (ox + d * math.cos(oyaw), oy + d * math.sin(oyaw),
                             _wrap(oyaw + w * DT))
            self.now = round(self.now + DT, 9)

    def until(self, cond: Any, timeout: float = 60.0) -> bool:
        end = self.now + timeout
        while self.now < end:
            if cond():
                return True
            self.tick()
        return bool(cond())

    def send(self, exect: int, task_id: int, task_type: int = 0, **kw: Any) -> TaskResponse:
        return self.machine.request(TaskRequest(exect, task_id, task_type, **kw), self.now)

    @property
    def status(self) -> Any:
        return self.machine.tracker.current
