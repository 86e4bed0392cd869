"""A legged scenario on the simulated loop (:class:`~lowerbase.simloop.legged.LeggedSimLoop`):
its timeline, its trace and its expectations."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from lowerbase.legged.profile import LeggedProfile
from lowerbase.protocol.legged import JOINT_NAMES, LocomotionState
from lowerbase.scenarios.expect import Outcome
from lowerbase.scenarios.legged import (
    GOAL_ACTIONS,
    PUBLISH_PERIOD,
    Answer,
    LeggedAction,
    LeggedExpectation,
    LeggedScenario,
    LeggedTrace,
)
from lowerbase.simloop.legged import LeggedSimLoop, LeggedTap


@dataclass
class LeggedRunResult:
    scenario: LeggedScenario
    trace: LeggedTrace
    outcomes: list[tuple[LeggedExpectation, Outcome]]
    mode: str  #: "simulated" or "realtime"
    wall_time: float  #: [s]
    events: list[tuple[float, str]] = field(default_factory=list)
    answers: list[Answer] = field(default_factory=list)
    interrupted: bool = False

    @property
    def passed(self) -> bool:
        return not self.interrupted and all(o.passed for _, o in self.outcomes)


def sample(loop: LeggedSimLoop) -> dict[str, float]:
    """One trace row: robot_state as the driver has it, the follower, the model's truth."""
    d, body = loop.driver, loop.lower.body
    f = d.follower
    s: dict[str, float] = {
        "t": loop.now, "state": float(d.state), "fault": float(d.fault),
        "x": d.base_pos[0], "y": d.base_pos[1], "z": d.base_pos[2],
        "vx": d.base_lin_vel[0], "vy": d.base_lin_vel[1], "wz": d.base_ang_vel[2],
        "cmd_vx": d.last_command[0], "cmd_vy": d.last_command[1], "cmd_wz": d.last_command[2],
        "truth_x": body.x, "truth_y": body.y, "voltage": d.voltage, "current": d.current,
        "body_temperature": d.body_temperature, "joy_listen_type": float(
            d.joystick.listen_type),
        "laps_done": float(f.laps_done), "laps_left": float(f.laps_left),
        "current_index": float(f.current_index), "mission_active": float(f.active),
    }
    for a in d.actuators:
        s[f"temp_{a.name}"] = a.temperature
        s[f"status_{a.name}"] = float(a.status)
    return s


class _Publisher:
    """cmd_vel and Joy streams: the latest of each kind is published every PUBLISH_PERIOD."""

    def __init__(self) -> None:
        self.active: dict[str, LeggedAction] = {}
        self.next_at: dict[str, float] = {}

    def start(self, action: LeggedAction, now: float) -> None:
        self.active[action.kind], self.next_at[action.kind] = action, now

    def publish(self, loop: LeggedSimLoop, now: float) -> None:
        for kind, action in list(self.active.items()):
            if now >= action.end - 1e-9:
                del self.active[kind]
                continue
            if now < self.next_at[kind] - 1e-9:
                continue
            self.next_at[kind] += PUBLISH_PERIOD
            a = action.args
            if kind == "velocity":
                loop.driver.set_velocity(a["vx"], a["vy"], a["yaw_rate"])
            else:
                loop.driver.on_joy(a["topic"], a["axes"])


def _fire(action: LeggedAction, loop: LeggedSimLoop, publisher: _Publisher,
          answers: list[Answer]) -> None:
    a, d, now = action.args, loop.driver, loop.now
    kind = action.kind
    if kind in GOAL_ACTIONS:
        loop.set_goal(GOAL_ACTIONS[kind])
    elif kind == "request":
        d.request_state(LocomotionState(a["state"]))
    elif kind in ("velocity", "joy"):
        publisher.start(action, now)
    elif kind == "heat":  # fault injection: the winding is this hot now
        loop.lower.body.actuators[JOINT_NAMES.index(a["joint"])].temperature = a["temperature"]
    else:
        if kind == "set_waypoints":
            ok, msg = d.set_waypoints(a["waypoints"], a["repetition"], a["current_index"])
        elif kind == "append_waypoint":
            ok, msg = d.append_waypoint(a["waypoint"])
        elif kind == "get_waypoints":
            ok, msg, _, left, index = d.get_waypoints()
            msg = f"{msg} (laps left {left}, index {index})"
        else:
            ok, msg = d.set_listen(a["data"])
        answers.append(Answer(action.at, kind, ok, msg))


def load_profile_of(scenario: LeggedScenario) -> LeggedProfile:
    from lowerbase.legged.profile import load_legged_profile

    return load_legged_profile(scenario.profile)


def run_legged_scenario(scenario: LeggedScenario, *, realtime: bool = False,
                        tap: LeggedTap | None = None,
                        progress: Callable[[float], None] | None = None) -> LeggedRunResult:
    """Run ``scenario`` on a :class:`LeggedSimLoop` (paced to the wall clock with
    ``realtime``); evaluate its expectations. Ctrl-C ends it early (``interrupted``)."""
    wall0 = time.monotonic()
    loop = LeggedSimLoop(load_profile_of(scenario), soc=scenario.soc, tap=tap)
    trace, pending = LeggedTrace(), list(scenario.timeline)
    publisher = _Publisher()
    events: list[tuple[float, str]] = []
    answers: list[Answer] = []
    next_sample, interrupted = 0.0, False
    try:
        while True:
            now = loop.now
            while pending and pending[0].at <= now + 1e-9:
                action = pending.pop(0)
                events.append((now, action.label()))
                _fire(action, loop, publisher, answers)
            publisher.publish(loop, now)
            if now >= next_sample - 1e-9:
                trace.append(sample(loop))
                next_sample += scenario.sample_period
                if progress is not None:
                    progress(now)
            if now >= scenario.duration - 1e-9:
                break
            loop.step()
            if realtime:
                delay = wall0 + loop.now - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        loop.close()
    outcomes = [(e, e.evaluate(trace, answers)) for e in scenario.expectations]
    return LeggedRunResult(scenario, trace, outcomes, "realtime" if realtime else "simulated",
                           time.monotonic() - wall0, events, answers, interrupted)
