"""``physics``: physical consistency without ground truth (a robot on blocks, or on the floor).

At rest the accelerometer reads gravity on +z. Then the suite drives two motions, straight
(``speed``, 0) and a spin in place (0, 2 ``speed`` / wheelDistant: the wheels at -speed and
+speed), waits out the ramp and records a window of each. In the windows the signals must agree
with the command and with each other through the parameters the lower computer reports
(wheelPerimeter, wheelDistant, ratioLeft/Right, pulsePerCircle). The tolerances are derived in
docs/conformance.md; the constants below carry them.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from statistics import fmean
from typing import Any

from lowerbase.conformance.catalog import WheelSample, wheel_samples
from lowerbase.conformance.context import STILL, Context
from lowerbase.conformance.core import (
    CheckFailed,
    CheckSkipped,
    Outcome,
    failed,
    passed,
    require,
)

STANDARD_GRAVITY = 9.80665  #: [m/s^2]
#: [m/s^2] |accel| at rest may differ from g by this much: a MEMS accelerometer's zero-g offset
#: (datasheets: +-40..80 mg per axis) and sensitivity error (+-1..3 %), about 0.1 g
GRAVITY_TOLERANCE = 1.0
#: gravity must be on +z: z >= this share of |accel| (a robot on blocks tilted below 25 deg)
GRAVITY_ON_Z = 0.9
REST_WINDOW = 0.5  #: [s] of frames averaged at rest
MEASURE_WINDOW = 1.0  #: [s] of frames averaged per motion
#: windows measured per motion while the lower computer reports that its time slipped in them
#: (Heartbeat.Overruns: a control loop too far behind to catch up, an emulator on a busy host,
#: skips the missed slots of its frames, so their Counters no longer count its time)
WINDOW_TRIES = 3
SETTLE = 0.3  #: [s] the speed controller's settling time, on top of the ramp
#: steady-state speed error allowed of the wheels' controller (relative) ...
SPEED_TOLERANCE = 0.05
#: ... and the absolute part: two resolutions of Velocity (quantisation of the mean and of the
#: command)
VELOCITY_LSB = 0.001
#: the Counter's span of a window against its reception times (relative): beyond this the
#: sender skipped cycles (reception jitter is milliseconds of a 1 s window), and a span off by
#: more would eat up SPEED_TOLERANCE; it was 0.25, which let a 16-cycle gap (0.32 s: the
#: Counter wrapped) through as a 21 % short span
SPAN_DISAGREEMENT = 0.04
#: relative allowance between two signals computed from one measurement in one control step
#: (MotionState from the wheel speeds): sampling skew between frames of one cycle
KINEMATIC_TOLERANCE = 0.02
#: the gyro vs MotionState: the real track differs from wheelDistant (scrub, tyre width), and
#: the gyro's scale error (datasheets: +-1..3 %); on blocks the body does not turn at all
GYRO_TOLERANCE = 0.10
GYRO_BIAS_DRIFT = 0.01  #: [rad/s] bias change allowed between the rest window and a motion
#: the Odometer's rate vs the centre speed from the wheel Counts: both integrate the same
#: encoders, sampled in different frames of one steady motion (windows overlapping but for a
#: cycle at each end): the sampling skew of KINEMATIC_TOLERANCE, of the wheel speed ...
ODOMETER_TOLERANCE = KINEMATIC_TOLERANCE
#: [m] ... plus the resolution of Distance: the difference of two readings is within one
ODOMETER_LSB = 0.001


@dataclass(frozen=True)
class Segment:
    """The frames of one commanded motion's measurement window."""

    name: str
    linear: float  #: commanded [m/s]
    angular: float  #: commanded [rad/s]
    wheels: dict[str, list[WheelSample]]
    motion: list[tuple[float, float]]  #: MotionState (Linear, Angular)
    gyro_z: list[float]  #: ImuGyro Z [rad/s]
    #: Odometer (reception time, Counter, Distance [m])
    odometer: tuple[tuple[float, int, float], ...] = ()

    @property
    def duration(self) -> float:
        ts = [s.t for samples in self.wheels.values() for s in samples]
        return max(ts) - min(ts) if ts else 0.0


@dataclass(frozen=True)
class Geometry:
    perimeter: float  #: wheelPerimeter [m]
    track: float  #: wheelDistant [m]
    ratio: dict[str, float]  #: ratioLeft/Right
    pulses: float  #: pulsePerCircle (per motor revolution)

    def metres_per_pulse(self, side: str) -> float:
        return self.perimeter / (self.pulses * self.ratio[side])

    def wheel_speeds(self, linear: float, angular: float) -> dict[str, float]:
        half = 0.5 * angular * self.track
        return {"left": linear - half, "right": linear + half}


def geometry(ctx: Context) -> Geometry:
    return Geometry(ctx.parameter("wheelPerimeter"), ctx.parameter("wheelDistant"),
                    {"left": ctx.parameter("ratioLeft"), "right": ctx.parameter("ratioRight")},
                    ctx.parameter("pulsePerCircle"))


def _window(ctx: Context, seconds: float) -> tuple[float, float]:
    t0 = time.monotonic()
    time.sleep(seconds)
    return t0, time.monotonic()


def _steady_window(ctx: Context) -> tuple[float, float]:
    """A window of MEASURE_WINDOW s (reception times) in which the lower computer reports no
    slip of its time: Heartbeat.Overruns the same in its last Heartbeat before the window and
    its first after it (waited for, two cycles at most). Up to WINDOW_TRIES windows while the
    motion goes on; the last one when each slipped (judged all the same: the frame checks and
    frame.Heartbeat.uptime count the slips), or the first one when no Heartbeat comes."""
    for _ in range(WINDOW_TRIES):
        t0, t1 = _window(ctx, MEASURE_WINDOW)
        if not ctx.time_slipped(t0, t1):
            break
    return t0, t1


def _motion_began(ctx: Context, linear: float, angular: float, sent: float) -> float:
    """When [s, time.monotonic] the lower computer began the motion commanded at ``sent``:
    the reception of its first MotionState with the commanded component (Linear, or Angular
    for a spin) past STILL of its command. The ramp is waited from there, so a command or
    frames the host delayed (a busy host's proxy, driver, scheduler) do not put the ramp
    into the window; how fast the firmware answers a MotionCommand is safety.enable's
    finding. ``sent`` when no such frame comes within reply_timeout (the window then shows
    what the firmware did)."""
    key, want = ("Linear", linear) if angular == 0.0 else ("Angular", angular)
    limit = STILL * abs(want)
    got = ctx.client.expect("MotionState", lambda v: math.copysign(1.0, want) * v[key] >= limit,
                            timeout=ctx.settings.reply_timeout, since=sent)
    return sent if got is None else got.t


def _between(ctx: Context, name: str, t0: float, t1: float) -> list[dict[str, Any]]:
    return [f.values for f in ctx.client.frames(name, t0) if f.t <= t1]


def _cached(ctx: Context, key: str, measure: Callable[[Context], Any]) -> Any:
    """Measure once per run; a failure is remembered and raised again."""
    if key not in ctx.shared:
        try:
            ctx.shared[key] = measure(ctx)
        except (CheckFailed, CheckSkipped) as exc:
            ctx.shared[key] = exc
    got = ctx.shared[key]
    if isinstance(got, Exception):
        raise got
    return got


def _measure_rest(ctx: Context) -> dict[str, Any]:
    ctx.ensure_standby()
    still = ctx.wait_still(time.monotonic(), timeout=2.0)
    require(still is not None, "not at rest: MotionState does not reach standstill in Standby")
    t0, t1 = _window(ctx, REST_WINDOW)
    accel, gyro = _between(ctx, "ImuAccel", t0, t1), _between(ctx, "ImuGyro", t0, t1)
    require(accel and gyro, f"no ImuAccel or ImuGyro in {REST_WINDOW:g} s at rest")
    return {"accel": [fmean(float(v[a]) for v in accel) for a in "XYZ"],
            "gyro_z": fmean(float(v["Z"]) for v in gyro)}


def _measure_motions(ctx: Context) -> list[Segment]:
    ctx.require_motion()
    _cached(ctx, "rest", _measure_rest)  # the gyro's bias, before the wheels turn
    geo = geometry(ctx)
    speed = ctx.settings.speed
    spin = min(2.0 * speed / geo.track, 0.8 * ctx.parameter("maxAngular"))
    ramp_v = speed / ctx.parameter("linearAccelLimit")
    # the spin starts while the straight motion brakes
    ramp_w = max(spin / ctx.parameter("angularAccelLimit"),
                 speed / ctx.parameter("linearDecelLimit"))
    ctx.ensure_active()
    segments = []
    try:
        for name, linear, angular, ramp in (("straight", speed, 0.0, ramp_v),
                                            ("spin", 0.0, spin, ramp_w)):
            with ctx.driving(linear, angular):
                began = _motion_began(ctx, linear, angular, time.monotonic())
                time.sleep(max(0.0, began + ramp + SETTLE - time.monotonic()))
                t0, t1 = _steady_window(ctx)
            wheels = wheel_samples((f.t, f.values) for f in ctx.client.frames("WheelFeedback", t0)
                                   if f.t <= t1)
            motion = [(float(v["Linear"]), float(v["Angular"]))
                      for v in _between(ctx, "MotionState", t0, t1)]
            gyro = [float(v["Z"]) for v in _between(ctx, "ImuGyro", t0, t1)]
            odometer = tuple((f.t, int(f.values["Counter"]), float(f.values["Distance"]))
                             for f in ctx.client.frames("Odometer", t0) if f.t <= t1)
            require(all(len(s) >= 2 for s in wheels.values()) and motion and gyro,
                    f"{name}: no WheelFeedback of both wheels, MotionState or ImuGyro in "
                    f"{MEASURE_WINDOW:g} s")
            segments.append(Segment(name, linear, angular, wheels, motion, gyro, odometer))
    finally:
        ctx.client.send("MotionCommand", Linear=0.0, Angular=0.0, Mode="Raw")
        ctx.control("Standby")
    return segments


def _report(problems: list[str], ok: str, **measured: Any) -> Outcome:
    if problems:
        return failed("; ".join(problems), **measured)
    return passed(ok, **measured)


def check_gravity(ctx: Context) -> Outcome:
    rest = _cached(ctx, "rest", _measure_rest)
    ax, ay, az = rest["accel"]
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    measured = {"accel_norm": round(norm, 4), "accel_z": round(az, 4)}
    problems = []
    if abs(norm - STANDARD_GRAVITY) > GRAVITY_TOLERANCE:
        problems.append(f"|accel| {norm:.3f} m/s^2 at rest, expected {STANDARD_GRAVITY:.2f} "
                        f"+- {GRAVITY_TOLERANCE:g}")
    if az < GRAVITY_ON_Z * norm:
        problems.append(f"gravity not on +z: accel ({ax:.2f}, {ay:.2f}, {az:.2f}) m/s^2")
    return _report(problems, f"|accel| {norm:.3f} m/s^2 at rest, on +z", **measured)


def check_wheel_velocity(ctx: Context) -> Outcome:
    segments = _cached(ctx, "motions", _measure_motions)
    geo = geometry(ctx)
    problems, measured = [], {}
    for seg in segments:
        want = geo.wheel_speeds(seg.linear, seg.angular)
        for side, samples in seg.wheels.items():
            got = fmean(s.velocity for s in samples)
            measured[f"{seg.name}_{side}_m_s"] = round(got, 4)
            tol = SPEED_TOLERANCE * abs(want[side]) + 2 * VELOCITY_LSB
            if abs(got - want[side]) > tol:
                problems.append(f"{seg.name}: {side} Velocity {got:.4f} m/s, commanded "
                                f"{want[side]:.4f} +- {tol:.4f}")
    return _report(problems, "wheel Velocity follows the commanded wheel speeds "
                   f"({', '.join(s.name for s in segments)})", **measured)


def _int32_delta(new: int, old: int) -> int:
    return (new - old + (1 << 31)) % (1 << 32) - (1 << 31)


def _firmware_span(ctx: Context, samples: list[WheelSample], message: str = "WheelFeedback"
                   ) -> float:
    """The time [s] between the first and last sample on the lower computer's own time base:
    the cycles of ``message`` counted by the rolling Counter (gaps under 16 cycles resolved)
    times the catalog cycle. Reception times would add the host's scheduling jitter, which a
    firmware is not to blame for; without a Counter they are all there is."""
    msg = ctx.codec.message(message)
    cycle = msg.cycle_time
    if not cycle or any(s.counter < 0 for s in samples):
        return samples[-1].t - samples[0].t
    modulo = 1 << msg.signal("Counter").length
    steps = [(b.counter - a.counter) % modulo for a, b in itertools.pairwise(samples)]
    received = samples[-1].t - samples[0].t
    span = sum(steps) * cycle
    # a counter that stalls or disagrees with the clock by more than reception jitter (a
    # sender that skipped cycles: its Counter counts frames sent, not the time between them;
    # a 16-cycle gap wraps it) is the counter check's finding (frame.<message>.counter), not
    # this one's: fall back to reception times. For a slow message a skipped cycle is more
    # than the relative allowance, and so is the reception jitter of a loaded host: half a
    # cycle tells them apart
    if 0 in steps or abs(span - received) > max(SPAN_DISAGREEMENT * received, cycle / 2):
        return received
    return span


def _one_cycle_pairs(ctx: Context, samples: list[WheelSample]
                     ) -> tuple[int, float, float] | None:
    """(pulses, integrated Velocity [m], span [s]) over the consecutive samples exactly one
    cycle apart on the sender's own time base: the Counter advanced by 1 and the frame
    arrived within 1.5 cycles of the last (a pair across skipped cycles, or one the host
    delivered late, is left out; leaving a pair out biases nothing). The lower computer's
    own clock, whatever the receiving host's delays and bursts; None when the Counter is
    absent or fewer than a quarter of the pairs (or 10) qualify."""
    msg = ctx.codec.message("WheelFeedback")
    cycle = msg.cycle_time
    if not cycle or len(samples) < 2 or any(s.counter < 0 for s in samples):
        return None
    modulo = 1 << msg.signal("Counter").length
    pulses, metres, n = 0, 0.0, 0
    for a, b in itertools.pairwise(samples):
        if (b.counter - a.counter) % modulo == 1 and b.t - a.t <= 1.5 * cycle:
            pulses += _int32_delta(b.count, a.count)
            metres += 0.5 * (a.velocity + b.velocity) * cycle
            n += 1
    if n < max(10, (len(samples) - 1) // 4):
        return None
    return pulses, metres, n * cycle


def check_wheel_count(ctx: Context) -> Outcome:
    segments = _cached(ctx, "motions", _measure_motions)
    geo = geometry(ctx)
    problems, measured = [], {}
    for seg in segments:
        for side, samples in seg.wheels.items():
            pairs = _one_cycle_pairs(ctx, samples)
            if pairs is not None:
                pulses, by_velocity, span = pairs
            else:
                pulses = _int32_delta(samples[-1].count, samples[0].count)
                span = _firmware_span(ctx, samples)
                by_velocity = fmean(s.velocity for s in samples) * span
            by_count = pulses * geo.metres_per_pulse(side)
            measured[f"{seg.name}_{side}_count_m"] = round(by_count, 4)
            measured[f"{seg.name}_{side}_velocity_m"] = round(by_velocity, 4)
            tol = (SPEED_TOLERANCE * abs(by_velocity) + VELOCITY_LSB * span
                   + 2 * geo.metres_per_pulse(side))
            if abs(by_count - by_velocity) > tol:
                problems.append(f"{seg.name}: {side} Count moved {by_count:.4f} m "
                                f"({pulses} pulses), Velocity integrates to {by_velocity:.4f} "
                                f"+- {tol:.4f} m")
    return _report(problems, "Count deltas agree with the integrated wheel Velocity through "
                   "wheelPerimeter / (pulsePerCircle x ratio)", **measured)


def check_motion_state(ctx: Context) -> Outcome:
    segments = _cached(ctx, "motions", _measure_motions)
    geo = geometry(ctx)
    problems, measured = [], {}
    for seg in segments:
        vl = fmean(s.velocity for s in seg.wheels["left"])
        vr = fmean(s.velocity for s in seg.wheels["right"])
        want = ((vl + vr) / 2, (vr - vl) / geo.track)
        got = (fmean(m[0] for m in seg.motion), fmean(m[1] for m in seg.motion))
        # quantisation: half an LSB of MotionState plus half of each wheel's mean
        tols = (KINEMATIC_TOLERANCE * abs(want[0]) + 2 * VELOCITY_LSB,
                KINEMATIC_TOLERANCE * abs(want[1]) + VELOCITY_LSB + 2 * VELOCITY_LSB / geo.track)
        for i, (what, unit) in enumerate((("Linear", "m/s"), ("Angular", "rad/s"))):
            measured[f"{seg.name}_{what.lower()}"] = round(got[i], 4)
            if abs(got[i] - want[i]) > tols[i]:
                problems.append(f"{seg.name}: MotionState {what} {got[i]:.4f} {unit}, wheel "
                                f"kinematics (wheelDistant {geo.track:g} m) give "
                                f"{want[i]:.4f} +- {tols[i]:.4f}")
    return _report(problems, "MotionState agrees with the wheel kinematics", **measured)


def check_gyro(ctx: Context) -> Outcome:
    segments = _cached(ctx, "motions", _measure_motions)
    bias = _cached(ctx, "rest", _measure_rest)["gyro_z"]
    problems, measured, stands = [], {}, set()
    for seg in segments:
        turn = fmean(m[1] for m in seg.motion)
        gyro = fmean(seg.gyro_z) - bias
        measured[f"{seg.name}_gyro_z"] = round(gyro, 4)
        measured[f"{seg.name}_motion_angular"] = round(turn, 4)
        tol = GYRO_TOLERANCE * abs(turn) + GYRO_BIAS_DRIFT
        if abs(gyro - turn) <= tol:
            stands.add("ground" if abs(turn) > tol else "either")
        elif abs(gyro) <= tol:
            stands.add("blocks")
        else:
            problems.append(f"{seg.name}: gyro z {gyro:.4f} rad/s (bias {bias:.4f} removed), "
                            f"MotionState Angular {turn:.4f}: neither the same (on the floor) "
                            f"nor 0 (on blocks), +- {tol:.4f}")
    stands.discard("either")
    if len(stands) > 1:
        problems.append("the gyro turned with the wheels in one motion and not in another")
    where = "on blocks" if stands == {"blocks"} else "on the floor"
    return _report(problems, f"integrated gyro z consistent with MotionState ({where})",
                   **measured)


def check_odometer(ctx: Context) -> Outcome:
    """Odometer Distance (the centre's distance travelled, |ds| summed) grows at the centre
    speed the wheel Counts give: (left + right) / 2 over the straight motion, about 0 in the
    spin in place (the wheels' distances cancel). Both rates are taken on the lower
    computer's own time base (each message's Counter x its catalog cycle)."""
    segments = _cached(ctx, "motions", _measure_motions)
    geo = geometry(ctx)
    problems, measured = [], {}
    for seg in segments:
        odo = [WheelSample(t, 0, distance, counter) for t, counter, distance in seg.odometer]
        require(len(odo) >= 3, f"{seg.name}: {len(odo)} Odometer frames in "
                f"{MEASURE_WINDOW:g} s (see frame.Odometer.present)")
        distances = [s.velocity for s in odo]
        drops = [f"{a:.3f} -> {b:.3f}" for a, b in itertools.pairwise(distances) if b < a]
        if drops:
            problems.append(f"{seg.name}: Odometer Distance decreased ({drops[0]} m) with no "
                            "OdometerReset")
        odo_span = _firmware_span(ctx, odo, "Odometer")
        odo_rate = (distances[-1] - distances[0]) / odo_span
        wheel_rates = []
        for side, samples in seg.wheels.items():
            pulses = _int32_delta(samples[-1].count, samples[0].count)
            wheel_rates.append(pulses * geo.metres_per_pulse(side)
                               / _firmware_span(ctx, samples))
        centre = abs(fmean(wheel_rates))
        measured[f"{seg.name}_odometer_m_s"] = round(odo_rate, 4)
        measured[f"{seg.name}_counts_m_s"] = round(centre, 4)
        # the relative allowance scales with the wheels' speed (not the centre's: the spin's
        # centre speed is a difference of two wheel speeds), the resolutions of Distance and
        # of Count at both ends of their windows
        wheel_speed = fmean(abs(r) for r in wheel_rates)
        span = min(odo_span, *(_firmware_span(ctx, s) for s in seg.wheels.values()))
        tol = (ODOMETER_TOLERANCE * wheel_speed + ODOMETER_LSB / odo_span
               + 2 * max(geo.metres_per_pulse(s) for s in seg.wheels) / span)
        if abs(odo_rate - centre) > tol:
            problems.append(f"{seg.name}: Odometer Distance grows at {odo_rate:.4f} m/s, the "
                            f"wheel Counts move the centre at {centre:.4f} +- {tol:.4f} m/s")
    return _report(problems, "Odometer Distance grows at the centre speed of the wheel Counts "
                   f"({', '.join(s.name for s in segments)})", **measured)
