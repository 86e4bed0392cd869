"""Step control (/cmd_vel_control, woosh_msgs/StepControlAction) without ROS.

A goal is a list of steps (woosh_msgs/StepControl: ``executeMode``, ``data``, ``speed``,
``angle``) run one after the other, closed loop on /odom, with a mode (the vendor's spellings):
``EXCUTE`` starts a list, ``PAUSE`` brakes and holds, ``RESUM`` continues, ``CANCEL`` brakes and
ends it. Each step:

- ``STRAIGHT``: drive ``data`` metres (negative: backwards; ``|data| <= 10``) along the heading
  the step starts with, at ``speed`` m/s (0: 0.2), holding that heading and line;
- ``ROTATE``: turn in place by ``data`` radians (negative: clockwise; ``|data| <= 62.8318``,
  ten turns), at ``speed`` rad/s (0: 0.1), counting the turned angle through every wrap;
- ``LATERAL`` and ``DIAGONALIZE`` are refused: a differential drive cannot move sideways.

Speeds follow a trapezoid within the chassis' acceleration limits: the command brakes at
``sqrt(2 a d)`` onto the end, so a step ends within 1 cm / 0.5 deg of its target on /odom;
between steps the robot stands still for ``settle`` s. An empty list, a NaN or infinite value,
a distance, angle or speed out of range, an unknown mode: rejected before any motion, with a
result saying why (``result`` -1). ``useAvoid`` with an ``obstacle_ahead`` check: the robot
waits (zero command) while the check says the way is blocked and continues when it clears.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from lowerbase.navigation.controller import Limits, wrap

# StepControl.action: mode
CANCEL, EXCUTE, PAUSE, RESUM = 0, 1, 2, 3
# StepControl.msg: executeMode
STRAIGHT, ROTATE, LATERAL, DIAGONALIZE = 1, 2, 3, 4
MAX_STRAIGHT = 10.0  #: [m]
MAX_ROTATE = 62.8318  #: [rad]
DEFAULT_SPEED = 0.2  #: [m/s]
DEFAULT_ROTATION = 0.1  #: [rad/s]
# results (StepControlResult.result: 1 succeeded, negative failed)
SUCCEEDED = 1
REJECTED = -1
CANCELLED = -2
#: braking onto the end uses this share of the deceleration limit, and starts as if the robot
#: were LAG seconds further on (command period, driver, motor lag)
BRAKE = 0.5
LAG = 0.15
MODE_NAMES = {CANCEL: "CANCEL", EXCUTE: "EXCUTE", PAUSE: "PAUSE", RESUM: "RESUM"}

ObstacleCheck = Callable[[tuple[float, float, float], float, float], bool]


@dataclass(frozen=True)
class Step:
    """One woosh_msgs/StepControl."""

    execute_mode: int
    data: float
    speed: float = 0.0
    angle: float = 0.0


@dataclass(frozen=True)
class StepResult:
    """StepControlResult: ``result`` (1 / negative), ``execute_mode`` of the last step run,
    ``percent`` of the whole list done; ``message`` says why in words."""

    result: int
    execute_mode: int
    percent: float
    message: str = ""


@dataclass(frozen=True)
class StepFeedback:
    """StepControlFeedback: ``feedback`` (1 running, 2 paused, 3 waiting for an obstacle),
    the running step's ``execute_mode`` and its ``percent`` done."""

    feedback: int
    execute_mode: int
    percent: float


class StepController:
    """Runs step lists closed loop on /odom; :meth:`tick` once per control period."""

    def __init__(self, limits: Limits | None = None, *, period: float = 0.05,
                 settle: float = 0.3, obstacle_ahead: ObstacleCheck | None = None) -> None:
        self.limits = limits or Limits()
        self.period = period
        self.settle = settle
        self.obstacle_ahead = obstacle_ahead
        self.steps: list[Step] = []
        self.use_avoid = False
        self.paused = False
        self.result: StepResult | None = None
        self.feedback: StepFeedback | None = None
        self.v = self.w = 0.0
        self._k = 0
        self._start: tuple[float, float, float] | None = None
        self._turned = 0.0
        self._last_yaw = 0.0
        self._hold = 0.0

    @property
    def active(self) -> bool:
        return bool(self.steps) and self.result is None

    # -- goals ----------------------------------------------------------------------------------
    def goal(self, mode: int, steps: Sequence[Step] = (), use_avoid: bool = False
             ) -> StepResult | None:
        """A StepControlGoal. EXCUTE: a new list (None when accepted, else the rejection);
        PAUSE/RESUM/CANCEL act on the running list."""
        if mode == EXCUTE:
            why = self.check(steps)
            if why:
                return StepResult(REJECTED, steps[0].execute_mode if steps else 0, 0.0, why)
            self.steps, self.use_avoid, self.paused = list(steps), bool(use_avoid), False
            self.result, self._k, self._start, self._hold = None, 0, None, 0.0
            return None
        if mode == PAUSE:
            self.paused = True
            return None
        if mode == RESUM:
            self.paused = False
            return None
        if mode == CANCEL:
            if self.active:
                self.result = StepResult(CANCELLED, self._mode(), self._percent(),
                                         "cancelled")
            return None
        return StepResult(REJECTED, 0, 0.0, f"unknown mode {mode}: one of "
                          + ", ".join(f"{k} {n}" for k, n in MODE_NAMES.items()))

    def check(self, steps: Sequence[Step]) -> str:
        """Why ``steps`` cannot run (empty string: they can)."""
        if not steps:
            return "the step list is empty: give at least one STRAIGHT or ROTATE step"
        lim = self.limits
        for i, s in enumerate(steps, 1):
            if not all(math.isfinite(v) for v in (s.data, s.speed, s.angle)):
                return f"step {i}: data, speed and angle must be finite numbers"
            if s.execute_mode in (LATERAL, DIAGONALIZE):
                return (f"step {i}: executeMode {s.execute_mode} (LATERAL/DIAGONALIZE) needs a "
                        "holonomic base; this differential drive only does STRAIGHT and ROTATE")
            if s.execute_mode == STRAIGHT:
                if abs(s.data) > MAX_STRAIGHT:
                    return f"step {i}: STRAIGHT {s.data} m is beyond +-{MAX_STRAIGHT} m"
                if s.speed < 0 or s.speed > lim.max_linear:
                    return f"step {i}: speed {s.speed} m/s is outside 0..{lim.max_linear:g}"
            elif s.execute_mode == ROTATE:
                if abs(s.data) > MAX_ROTATE:
                    return f"step {i}: ROTATE {s.data} rad is beyond +-{MAX_ROTATE} rad"
                if s.speed < 0 or s.speed > lim.max_angular:
                    return f"step {i}: speed {s.speed} rad/s is outside 0..{lim.max_angular:g}"
            else:
                return f"step {i}: executeMode {s.execute_mode} is not 1 STRAIGHT or 2 ROTATE"
        return ""

    # -- running --------------------------------------------------------------------------------
    def tick(self, odom: Sequence[float]) -> tuple[float, float]:
        """The twist for this period from the /odom pose (x, y, yaw)."""
        x, y, yaw = (float(v) for v in odom)
        if not self.active:
            return self._ramp(0.0, 0.0)
        if self._hold > 0:  # standing still between steps
            self._hold -= self.period
            return self._ramp(0.0, 0.0)
        step = self.steps[self._k]
        if self._start is None:
            self._start, self._turned, self._last_yaw = (x, y, yaw), 0.0, yaw
        self._turned += wrap(yaw - self._last_yaw)
        self._last_yaw = yaw
        sx, sy, syaw = self._start
        sign = 1.0 if step.data >= 0 else -1.0
        if step.execute_mode == STRAIGHT:
            along = (x - sx) * math.cos(syaw) + (y - sy) * math.sin(syaw)
            lateral = -(x - sx) * math.sin(syaw) + (y - sy) * math.cos(syaw)
            remaining = abs(step.data) - sign * along
            done = remaining <= 0.002
            speed = step.speed or DEFAULT_SPEED
            progress = sign * along / max(abs(step.data), 1e-9)
        else:
            remaining = abs(step.data) - sign * self._turned
            done = remaining <= math.radians(0.1)
            speed = step.speed or DEFAULT_ROTATION
            progress = sign * self._turned / max(abs(step.data), 1e-9)
        self.feedback = StepFeedback(2 if self.paused else 1, step.execute_mode,
                                     100.0 * min(max(progress, 0.0), 1.0))
        if done:
            self._k += 1
            self._start = None
            self._hold = self.settle
            if self._k == len(self.steps):
                self.result = StepResult(SUCCEEDED, step.execute_mode, 100.0, "done")
            return self._ramp(0.0, 0.0)
        if self.paused:
            return self._ramp(0.0, 0.0)
        if step.execute_mode == STRAIGHT:
            ahead = max(remaining - abs(self.v) * LAG, 0.0)
            v = sign * min(speed, max(math.sqrt(2.0 * self.limits.linear_decel * BRAKE * ahead),
                                      0.01))
            w = 2.0 * wrap(syaw - yaw) - 2.0 * lateral * sign
            w = min(max(w, -0.3), 0.3)
            if self.use_avoid and self.obstacle_ahead is not None and \
                    self.obstacle_ahead((x, y, yaw), v, 0.0):
                self.feedback = StepFeedback(3, step.execute_mode, self.feedback.percent)
                return self._ramp(0.0, 0.0)
            return self._ramp(v, w)
        ahead = max(remaining - abs(self.w) * LAG, 0.0)
        w = sign * min(speed, max(math.sqrt(2.0 * self.limits.angular_decel * BRAKE * ahead),
                                  0.04))
        if self.use_avoid and self.obstacle_ahead is not None and \
                self.obstacle_ahead((x, y, yaw), 0.0, w):
            self.feedback = StepFeedback(3, step.execute_mode, self.feedback.percent)
            return self._ramp(0.0, 0.0)
        return self._ramp(0.0, w)

    def _mode(self) -> int:
        return self.steps[min(self._k, len(self.steps) - 1)].execute_mode if self.steps else 0

    def _percent(self) -> float:
        part = (self.feedback.percent / 100.0) if self.feedback is not None else 0.0
        return 100.0 * (self._k + part) / max(len(self.steps), 1)

    def _ramp(self, v: float, w: float) -> tuple[float, float]:
        lim, dt = self.limits, self.period
        dv = lim.linear_accel if abs(v) > abs(self.v) and v * self.v >= 0 else lim.linear_decel
        dw = lim.angular_accel if abs(w) > abs(self.w) and w * self.w >= 0 \
            else lim.angular_decel
        self.v += min(max(v - self.v, -dv * dt), dv * dt)
        self.w += min(max(w - self.w, -dw * dt), dw * dt)
        return self.v, self.w
