"""``frame.<Message>.<aspect>`` of the legged robot, derived from ``legged.dbc``: every
periodic body frame on bus 0 (present, DLC, range, cycle, counter), the body controller's
actuator commands on every leg bus (present on each, DLC, range, 1 ms cycle per bus) and the
actuators' MotorReply (present from every actuator, DLC, range).

All of them look at one observation window (``LeggedSettings.observe``) taken in
MOTOR_ENABLED (actuators in motor mode, the robot lying down), which the first of them opens.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from lowerbase.conformance.core import (
    Check,
    CheckSkipped,
    Outcome,
    failed,
    passed,
    require,
    skipped,
)
from lowerbase.conformance.frames import (
    counter_steps,
    cycle_stats,
    dlc_outcome,
    range_outcome,
)
from lowerbase.conformance.legged_context import LeggedCheckFunc, LeggedContext, legged_check
from lowerbase.conformance.legged_link import LegFrame
from lowerbase.protocol.codec import Codec, MessageCodec
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    LEGS,
    N_BUSES,
    REPLY_ID,
    REPLY_PREFIX,
)


def body_messages(codec: Codec) -> list[MessageCodec]:
    """Every periodic message the body controller sends on bus 0, in catalog order."""
    return [m for m in codec if m.is_periodic and "Body" in m.senders
            and m.frame_id not in COMMAND_MESSAGES]


@dataclass(frozen=True)
class Observation:
    start: float
    end: float
    #: (bus, frame id) -> frames
    frames: dict[tuple[int, int], list[LegFrame]]


def observation(ctx: LeggedContext) -> Observation:
    """The observation window (taken once, by the first frame check that asks)."""
    got = ctx.shared.get("observation")
    if got is None:
        require(ctx.state() == 4, "not in MOTOR_ENABLED (see locomotion.motor_enabled): no "
                "observation window")
        ids = [m.frame_id for m in body_messages(ctx.codec)]
        with ctx.capturing():
            start = ctx.now()
            ctx.wait(ctx.settings.observe)
            end = ctx.now()
            ctx.link.flush(end)
            frames = {(b, i): ctx.link.frames(b, i, start, end)
                      for b in range(N_BUSES) for i in (REPLY_ID, *COMMAND_MESSAGES)}
        frames |= {(BODY_BUS, i): ctx.link.frames(BODY_BUS, i, start, end) for i in ids}
        got = ctx.shared["observation"] = Observation(start, end, frames)
    assert isinstance(got, Observation)
    return got


def _streams(ctx: LeggedContext, msg: MessageCodec) -> dict[int, list[LegFrame]]:
    """bus -> frames of ``msg`` in the window (body frames: bus 0 only)."""
    obs = observation(ctx)
    buses = range(N_BUSES) if msg.frame_id in COMMAND_MESSAGES or msg.frame_id == REPLY_ID \
        else (BODY_BUS,)
    return {b: obs.frames.get((b, msg.frame_id), []) for b in buses}


def _all(ctx: LeggedContext, msg: MessageCodec) -> list[LegFrame]:
    frames = [f for fs in _streams(ctx, msg).values() for f in fs]
    if not frames:
        raise CheckSkipped(f"no {msg.name} frames (see frame.{msg.name}.present)")
    return frames


def check_present(msg: MessageCodec) -> LeggedCheckFunc:
    def run(ctx: LeggedContext) -> Outcome:
        streams = _streams(ctx, msg)
        window = ctx.settings.observe
        if msg.frame_id == REPLY_ID:
            missing = [f"{LEGS[b]} {REPLY_PREFIX[m]}" for b, fs in streams.items()
                       for m in REPLY_PREFIX if not any(f.data[:1] == bytes((m,)) for f in fs)]
        else:
            missing = [LEGS[b] for b, fs in streams.items() if not fs]
        n = sum(len(fs) for fs in streams.values())
        if msg.name.startswith("Bms") and not n and not any(
                observation(ctx).frames.get((BODY_BUS, m.frame_id))
                for m in body_messages(ctx.codec) if m.name.startswith("Bms")):
            return skipped("no Bms* frame at all: the lower computer has no BMS link (they "
                           "are sent only while the BMS answers)")
        if missing:
            return failed(f"no {msg.name} in {window:g} s from {', '.join(missing)}",
                          frames=n)
        return passed(f"{n} frames in {window:g} s", frames=n)
    return run


def check_dlc(msg: MessageCodec) -> LeggedCheckFunc:
    def run(ctx: LeggedContext) -> Outcome:
        return dlc_outcome(msg, _all(ctx, msg))
    return run


def check_range(msg: MessageCodec) -> LeggedCheckFunc:
    def run(ctx: LeggedContext) -> Outcome:
        return range_outcome(msg, _all(ctx, msg))
    return run


def check_cycle(msg: MessageCodec) -> LeggedCheckFunc:
    cycle = msg.cycle_time or 0.0

    def run(ctx: LeggedContext) -> Outcome:
        s = ctx.settings
        gap_limit = s.max_gap_cycles * cycle + s.jitter
        worst: tuple[float, float, str] | None = None
        for b, fs in _streams(ctx, msg).items():
            stamps = sorted(f.stamp for f in fs)
            if len(stamps) < 3:
                continue
            mean, gap = cycle_stats(stamps)
            if worst is None or abs(mean - cycle) / cycle > abs(worst[0] - cycle) / cycle \
                    or gap > worst[1]:
                worst = (mean, gap, LEGS[b])
        if worst is None:
            return skipped(f"fewer than 3 frames in {s.observe:g} s")
        mean, gap, leg = worst
        where = f" ({leg} bus)" if msg.frame_id in COMMAND_MESSAGES else ""
        measured = {"cycle_ms": round(cycle * 1e3, 3), "mean_ms": round(mean * 1e3, 3),
                    "max_gap_ms": round(gap * 1e3, 3)}
        text = f"mean {mean * 1e3:.2f} ms (catalog {cycle * 1e3:g} ms), max gap " \
               f"{gap * 1e3:.1f} ms{where}"
        if abs(mean - cycle) > s.cycle_tolerance * cycle:
            return failed(f"{text}: mean off by more than {s.cycle_tolerance:.0%}", **measured)
        if gap > gap_limit:
            return failed(f"{text}: gap above {gap_limit * 1e3:.1f} ms", **measured)
        return passed(text, **measured)
    return run


def check_counter(msg: MessageCodec) -> LeggedCheckFunc:
    def run(ctx: LeggedContext) -> Outcome:
        counters = [int(msg.decode(f.data, strict=False)["Counter"]) for f in _all(ctx, msg)
                    if len(f.data) == msg.length]
        steps, bad, example = counter_steps(counters)
        require(steps >= 1, "fewer than 2 frames of the catalog length")
        if bad:
            return failed(f"{bad} of {steps} steps not +1 mod 16 (e.g. {example})",
                          bad_steps=bad, steps=steps)
        return passed(f"+1 mod 16 over {steps} frames", steps=steps)
    return run


def _aspects(msg: MessageCodec, what: str) -> list[Check]:
    return [
        legged_check(f"frame.{msg.name}.present", f"{msg.name} is sent {what}",
                     check_present(msg)),
        legged_check(f"frame.{msg.name}.dlc", f"{msg.name} has DLC {msg.length}",
                     check_dlc(msg)),
        legged_check(f"frame.{msg.name}.range", f"every {msg.name} value is within the "
                     "catalog range", check_range(msg)),
    ]


def legged_frame_checks(codec: Codec) -> list[Check]:
    """The per-frame checks, in catalog order (see the module)."""
    checks: list[Check] = []
    messages: Sequence[MessageCodec] = [
        codec.message(REPLY_ID), *(codec.message(i) for i in COMMAND_MESSAGES),
        *body_messages(codec)]
    for msg in messages:
        if msg.frame_id == REPLY_ID:
            checks += _aspects(msg, "by every actuator")
            continue
        where = "on every leg bus" if msg.frame_id in COMMAND_MESSAGES else "on bus 0"
        checks += _aspects(msg, where)
        cycle = f"{(msg.cycle_time or 0) * 1e3:g} ms"
        checks.append(legged_check(f"frame.{msg.name}.cycle", f"{msg.name} every {cycle}",
                                   check_cycle(msg)))
        if msg.has_counter:
            checks.append(legged_check(f"frame.{msg.name}.counter",
                                       f"{msg.name} counter +1 mod 16 per frame",
                                       check_counter(msg)))
    return checks
