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
``sqrt(2 a d)`` onto the end, planned from the remaining distance measured on /odom. Then the
robot stops and the step waits until /odom stands still for ``settle`` s plus the measured
latency (first command to first motion on /odom), measures what is left, and corrects it with a
short move at creep speed whose length is counted on the commands sent (so late /odom or late
commands do not change it), stop, settle, measure again, until within ``tolerance`` (3 mm) /
``angle_tolerance`` (0.15 deg) or ``max_corrections`` (5) moves. A step then within
``accept_tolerance`` (2 cm) / ``accept_angle`` (1 deg) is done and the list goes on; one still
further off ends the list with ``result`` -3. A step that makes no progress (its remaining
distance not 5 mm / 0.5 deg shorter) for ``stall_timeout`` (4 s) while driving (not paused, not
waiting for an obstacle), e.g. pushing into a rack, stops: within the accept tolerance it is
measured and finished as above, else the list ends with ``result`` -3 and the reason. ``RESUM``
with a step list (the vendor: after a pause the remaining steps are sent again): the list is
checked like an EXCUTE list and replaces the paused step and those after it, the first new step
measured from where the robot stands; the same remaining list as running (the paused step
included, unchanged) continues the paused step where it is. An empty list, a NaN or
infinite value, a distance, angle or speed out of range, an unknown mode: rejected before any
motion, with a result saying why (``result`` -1). ``useAvoid`` with an ``obstacle_ahead``
check: the robot waits (zero command) while the check says the way is blocked and continues
when it clears.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from lowerbase.errors import ConfigError
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
FAILED = -3  #: a step still off by more than accept_tolerance after its corrections, or stalled
#: braking onto the end uses this share of the deceleration limit, and starts as if the robot
#: were LAG seconds further on (command period, driver, motor lag)
BRAKE = 0.5
LAG = 0.15
#: /odom "stands still" while it stays within these of where it stopped
STILL_DISTANCE = 0.0003  #: [m]
STILL_ANGLE = math.radians(0.02)  #: [rad]
#: a driving step makes progress while its remaining distance gets this much shorter
PROGRESS_DISTANCE = 0.005  #: [m]
PROGRESS_ANGLE = math.radians(0.5)  #: [rad]
MAX_LATENCY = 2.0  #: [s] the measured latency is capped here
# the phases of a step
DRIVE, SETTLE, CORRECT = "drive", "settle", "correct"
MODE_NAMES = {CANCEL: "CANCEL", EXCUTE: "EXCUTE", PAUSE: "PAUSE", RESUM: "RESUM"}

Pose = tuple[float, float, float]
ObstacleCheck = Callable[[Pose, float, float], bool]


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
                 settle: float = 0.3, settle_timeout: float = 3.0, tolerance: float = 0.003,
                 angle_tolerance: float = math.radians(0.15), max_corrections: int = 5,
                 creep: float = 0.03, creep_rotation: float = 0.1,
                 accept_tolerance: float = 0.02, accept_angle: float = math.radians(1.0),
                 stall_timeout: float = 4.0,
                 obstacle_ahead: ObstacleCheck | None = None) -> None:
        self.limits = limits or Limits()
        self.period = period
        self.settle = settle  #: /odom still this long (plus the latency) ends a stop [s]
        self.settle_timeout = settle_timeout  #: a stop measures after this at the latest [s]
        self.tolerance = tolerance  #: a straight step ends this near its target on /odom [m]
        self.angle_tolerance = angle_tolerance  #: the same for a rotation [rad]
        self.max_corrections = max_corrections  #: creeping moves per step, at most
        self.creep = creep  #: correction speed [m/s]
        self.creep_rotation = creep_rotation  #: correction speed [rad/s]
        #: after max_corrections a step this near its target on /odom is done [m, rad]
        self.accept_tolerance = accept_tolerance
        self.accept_angle = accept_angle
        self.stall_timeout = stall_timeout  #: a driving step without progress this long stops [s]
        self.obstacle_ahead = obstacle_ahead
        for name in ("period", "settle", "settle_timeout", "tolerance", "angle_tolerance",
                     "creep", "creep_rotation", "accept_tolerance", "accept_angle",
                     "stall_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"StepController {name} = {value!r}: expected a number > 0")
        if not (isinstance(max_corrections, int) and max_corrections >= 0):
            raise ConfigError(f"StepController max_corrections = {max_corrections!r}: expected "
                              "an integer >= 0")
        self.latency = LAG  #: measured: first command -> first motion on /odom [s]
        self.corrections = 0  #: corrections of the running step so far
        self.summary = ""  #: how the last step ended (error on /odom, corrections, latency)
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
        self._phase = DRIVE
        self._clock = 0.0
        self._last_now: float | None = None
        self._go: tuple[float, Pose] | None = None
        self._still_at: tuple[float, float | None, Pose] = (0.0, None, (0.0, 0.0, 0.0))
        self._odom_time: float | None = None
        self._settle_from: tuple[float, float | None] = (0.0, None)
        self._creep_speed = 0.0
        self._left = 0.0
        self._progress: tuple[float, float] | None = None  # (clock, best remaining) driving

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
            self.result, self._k, self._start = None, 0, None
            return None
        if mode == PAUSE:
            self.paused = True
            return None
        if mode == RESUM:
            if steps and self.active and list(steps) != self.steps[self._k:]:
                why = self.check(steps)
                if why:
                    return StepResult(REJECTED, steps[0].execute_mode, 0.0, why)
                # the resent list replaces what was left: the paused step's rest and the
                # steps after it; the first new step starts from where the robot stands
                self.steps = self.steps[:self._k] + list(steps)
                self.use_avoid, self._start = bool(use_avoid), None
            self.paused = False
            return None
        if mode == CANCEL:
            if self.active:
                self.result = StepResult(CANCELLED, self.mode, self.percent, "cancelled")
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
    def tick(self, odom: Sequence[float], now: float | None = None,
             odom_time: float | None = None) -> tuple[float, float]:
        """The twist for this period from the /odom pose (x, y, yaw) at time ``now`` [s] (None:
        one ``period`` after the last tick). ``odom_time``: the pose's own time stamp [s, any
        clock]; a stop then also needs ``settle`` s of fresh stamps standing still, so a stalled
        /odom (a pose that stops changing because none arrives) is not taken for a robot at
        rest."""
        x, y, yaw = (float(v) for v in odom)
        dt = self._advance(now)
        self._odom_time = odom_time
        if not self.active:
            return self._ramp(0.0, 0.0)
        step = self.steps[self._k]
        if self._start is None:
            self._start, self._turned, self._last_yaw = (x, y, yaw), 0.0, yaw
            self._phase, self.corrections, self._go = DRIVE, 0, None
            self._progress = None
        self._turned += wrap(yaw - self._last_yaw)
        self._last_yaw = yaw
        self._measure_latency((x, y, yaw))
        remaining, progress = self._remaining(step, x, y)
        self.feedback = StepFeedback(2 if self.paused else 1, step.execute_mode,
                                     100.0 * min(max(progress, 0.0), 1.0))
        if self.paused:
            self._progress = None
            if self._phase != DRIVE:
                self._to_settle((x, y, yaw))
            return self._ramp(0.0, 0.0)
        if self._phase == DRIVE:
            if remaining <= self._tolerance(step):
                self._to_settle((x, y, yaw))
                return self._ramp(0.0, 0.0)
            if self._stalled(step, remaining):
                if abs(remaining) <= self._accept(step):
                    self._to_settle((x, y, yaw))  # measured and finished (or corrected)
                    return self._ramp(0.0, 0.0)
                self.result = StepResult(FAILED, step.execute_mode, self.percent,
                                         f"step {self._k + 1}: no progress for "
                                         f"{self.stall_timeout:g} s while driving (blocked or "
                                         f"stalled?), {self._off(step, remaining)} left")
                return self._ramp(0.0, 0.0)
            command = self._drive(step, (x, y, yaw), remaining)
            if self.feedback is not None and self.feedback.feedback == 3:
                self._progress = None  # waiting for an obstacle: not a stall
            return command
        if self._phase == SETTLE:
            if not self._still((x, y, yaw)):
                return self._ramp(0.0, 0.0)
            if abs(remaining) <= self._tolerance(step):
                return self._next(step, remaining)
            if self.corrections >= self.max_corrections:
                if abs(remaining) <= self._accept(step):
                    return self._next(step, remaining)
                self.result = StepResult(FAILED, step.execute_mode, self.percent,
                                         f"step {self._k + 1}: still {self._off(step, remaining)}"
                                         f" off after {self.corrections} corrections")
                return self._ramp(0.0, 0.0)
            self._plan_correction(step, remaining)
        return self._correct(step, (x, y, yaw), dt)

    @property
    def phase(self) -> str:
        """The running step's phase: ``drive``, ``settle`` (stopped, waiting for /odom to stand
        still) or ``correct`` (a creeping correction)."""
        return self._phase

    @property
    def mode(self) -> int:
        """executeMode of the running (or last) step; 0 without a list."""
        return self.steps[min(self._k, len(self.steps) - 1)].execute_mode if self.steps else 0

    @property
    def percent(self) -> float:
        """Percent of the whole list done."""
        part = (self.feedback.percent / 100.0) if self.feedback is not None else 0.0
        return 100.0 * (self._k + part) / max(len(self.steps), 1)

    def _advance(self, now: float | None) -> float:
        """Move the controller's clock to ``now``; the seconds since the last tick."""
        if now is None or self._last_now is None:
            dt = self.period
        else:
            dt = min(max(now - self._last_now, 0.0), 1.0)
        self._last_now = now
        self._clock += dt
        return dt

    def _remaining(self, step: Step, x: float, y: float) -> tuple[float, float]:
        """(what is left of the step in its own direction [m or rad], share done)."""
        assert self._start is not None
        sx, sy, syaw = self._start
        sign = 1.0 if step.data >= 0 else -1.0
        if step.execute_mode == STRAIGHT:
            done = sign * ((x - sx) * math.cos(syaw) + (y - sy) * math.sin(syaw))
        else:
            done = sign * self._turned
        return abs(step.data) - done, done / max(abs(step.data), 1e-9)

    def _tolerance(self, step: Step) -> float:
        return self.tolerance if step.execute_mode == STRAIGHT else self.angle_tolerance

    def _accept(self, step: Step) -> float:
        return self.accept_tolerance if step.execute_mode == STRAIGHT else self.accept_angle

    @staticmethod
    def _off(step: Step, remaining: float) -> str:
        if step.execute_mode == STRAIGHT:
            return f"{abs(remaining) * 1000:.1f} mm"
        return f"{math.degrees(abs(remaining)):.2f} deg"

    def _stalled(self, step: Step, remaining: float) -> bool:
        """Whether the driving step's remaining distance has not got PROGRESS_DISTANCE /
        PROGRESS_ANGLE shorter (less for a step slower than that in a quarter of the time) for
        ``stall_timeout`` s."""
        if step.execute_mode == STRAIGHT:
            need, speed = PROGRESS_DISTANCE, step.speed or DEFAULT_SPEED
        else:
            need, speed = PROGRESS_ANGLE, step.speed or DEFAULT_ROTATION
        need = min(need, 0.25 * speed * self.stall_timeout)  # a slow step is no stall
        if self._progress is None or remaining <= self._progress[1] - need:
            self._progress = (self._clock, remaining)
            return False
        return self._clock - self._progress[0] >= self.stall_timeout - 1e-9

    def _blocked(self, step: Step, pose: Pose, v: float, w: float) -> bool:
        if not (self.use_avoid and self.obstacle_ahead is not None
                and self.obstacle_ahead(pose, v, w)):
            return False
        self.feedback = StepFeedback(3, step.execute_mode,
                                     self.feedback.percent if self.feedback else 0.0)
        return True

    def _drive(self, step: Step, pose: Pose, remaining: float) -> tuple[float, float]:
        """The trapezoid: cruise, then brake at sqrt(2 a d) onto the end."""
        assert self._start is not None
        sx, sy, syaw = self._start
        x, y, yaw = pose
        sign = 1.0 if step.data >= 0 else -1.0
        if self.v == 0.0 and self.w == 0.0 and self._go is None:
            self._go = (self._clock, pose)  # starting: time the first motion on /odom
        if step.execute_mode == STRAIGHT:
            ahead = max(remaining - abs(self.v) * LAG, 0.0)
            v = sign * min(step.speed or DEFAULT_SPEED,
                           max(math.sqrt(2.0 * self.limits.linear_decel * BRAKE * ahead), 0.01))
            lateral = -(x - sx) * math.sin(syaw) + (y - sy) * math.cos(syaw)
            w = min(max(2.0 * wrap(syaw - yaw) - 2.0 * lateral * sign, -0.3), 0.3)
            if self._blocked(step, pose, v, 0.0):
                return self._ramp(0.0, 0.0)
            return self._ramp(v, w)
        ahead = max(remaining - abs(self.w) * LAG, 0.0)
        w = sign * min(step.speed or DEFAULT_ROTATION,
                       max(math.sqrt(2.0 * self.limits.angular_decel * BRAKE * ahead), 0.04))
        if self._blocked(step, pose, 0.0, w):
            return self._ramp(0.0, 0.0)
        return self._ramp(0.0, w)

    def _to_settle(self, pose: Pose) -> None:
        self._phase = SETTLE
        self._still_at = (self._clock, self._odom_time, pose)
        self._settle_from = (self._clock, self._odom_time)

    def _still(self, pose: Pose) -> bool:
        """Whether /odom has stood still for ``settle`` s plus the measured latency (or the
        wait reached ``settle_timeout``)."""
        t0, s0, anchor = self._still_at
        if math.hypot(pose[0] - anchor[0], pose[1] - anchor[1]) > STILL_DISTANCE or \
                abs(wrap(pose[2] - anchor[2])) > STILL_ANGLE:
            self._still_at = t0, s0, anchor = self._clock, self._odom_time, pose
        c0, o0 = self._settle_from
        return (self._clock - t0 >= self.settle + self.latency - 1e-9 and self._fresh(s0)) or \
            (self._clock - c0 >= self.settle_timeout and self._fresh(o0))

    def _fresh(self, since: float | None) -> bool:
        """Whether /odom stamps ran ``settle`` s on since ``since`` (True without stamps)."""
        return since is None or self._odom_time is None or \
            self._odom_time - since >= self.settle - 1e-9

    def _measure_latency(self, pose: Pose) -> None:
        """The time from a start (first command after standing) to the first motion on /odom:
        command period, driver, motors and /odom's age together."""
        if self._go is None:
            return
        t0, p0 = self._go
        if math.hypot(pose[0] - p0[0], pose[1] - p0[1]) > STILL_DISTANCE or \
                abs(wrap(pose[2] - p0[2])) > STILL_ANGLE:
            self.latency = min(self._clock - t0, MAX_LATENCY)
            self._go = None

    def _plan_correction(self, step: Step, remaining: float) -> None:
        """A short move of exactly ``remaining`` (negative: back) at creep speed: n periods
        at the speed that covers it, counted on the commands sent (latency does not change
        how far they drive)."""
        self.corrections += 1
        creep = self.creep if step.execute_mode == STRAIGHT else self.creep_rotation
        n = max(1, math.ceil(abs(remaining) / (creep * self.period)))
        self._creep_speed = math.copysign(abs(remaining) / (n * self.period), remaining)
        self._left = abs(remaining)
        self._phase = CORRECT
        self._go = None

    def _correct(self, step: Step, pose: Pose, dt: float) -> tuple[float, float]:
        sign = 1.0 if step.data >= 0 else -1.0
        straight = step.execute_mode == STRAIGHT
        self._left -= abs(self.v if straight else self.w) * dt  # what the last command drove
        speed = sign * self._creep_speed
        if self._left <= abs(speed) * self.period / 2:
            self._to_settle(pose)
            return self._ramp(0.0, 0.0)
        if self._blocked(step, pose, speed if straight else 0.0, 0.0 if straight else speed):
            self._to_settle(pose)
            self.corrections -= 1  # not a correction: a wait
            return self._ramp(0.0, 0.0)
        if abs(self.v) + abs(self.w) == 0.0 and self._go is None:
            self._go = (self._clock, pose)
        return self._ramp(speed, 0.0) if straight else self._ramp(0.0, speed)

    def _next(self, step: Step, remaining: float) -> tuple[float, float]:
        self._k += 1
        self._start = None
        off = self._off(step, remaining)
        self.summary = (f"step {self._k} ended {off} off on /odom after {self.corrections} "
                        f"correction(s); latency {self.latency:.2f} s")
        if self._k == len(self.steps):
            self.result = StepResult(SUCCEEDED, step.execute_mode, 100.0,
                                     f"done: {self.summary}")
        return self._ramp(0.0, 0.0)

    def _ramp(self, v: float, w: float) -> tuple[float, float]:
        lim, dt = self.limits, self.period
        dv = lim.linear_accel if abs(v) > abs(self.v) and v * self.v >= 0 else lim.linear_decel
        dw = lim.angular_accel if abs(w) > abs(self.w) and w * self.w >= 0 \
            else lim.angular_decel
        self.v += min(max(v - self.v, -dv * dt), dv * dt)
        self.w += min(max(w - self.w, -dw * dt), dw * dt)
        return self.v, self.w
