"""``frame.<Message>.<aspect>``: per-frame checks derived from the catalog."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

from lowerbase.conformance.catalog import (
    CONDITIONAL,
    ROW_KEYS,
    control_period,
    periodic_lower_messages,
    shared_counter,
)
from lowerbase.conformance.client import RawFrame
from lowerbase.conformance.context import CheckFunc, Context, overrun_steps
from lowerbase.conformance.core import (
    Check,
    CheckSkipped,
    Outcome,
    failed,
    passed,
    require,
    skipped,
)
from lowerbase.errors import ProtocolError
from lowerbase.protocol.codec import Codec, MessageCodec

# -- frame checks (derived from the catalog) ----------------------------------------------------


def _frames_or_skip(ctx: Context, msg: MessageCodec) -> list[RawFrame]:
    frames = ctx.observation(msg)
    if not frames:
        raise CheckSkipped(f"no {msg.name} frames (see frame.{msg.name}.present)")
    return frames


def check_present(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        frames = ctx.observation(msg)
        if frames:
            return passed(f"{len(frames)} frames in {ctx.settings.observe:g} s",
                          frames=len(frames))
        bit = CONDITIONAL.get(msg.name)
        if bit is not None and ctx.status_code() & bit:
            return skipped(f"not sent while StatusCode has {bit.name}")
        return failed(f"no {msg.name} in {ctx.settings.observe:g} s")
    return run


def dlc_outcome(msg: MessageCodec, frames: Sequence[Any]) -> Outcome:
    """Every frame (``.data``) of ``msg`` has the catalog's length."""
    bad = [len(f.data) for f in frames if len(f.data) != msg.length]
    if bad:
        return failed(f"{len(bad)} of {len(frames)} frames with DLC {sorted(set(bad))} "
                      f"(catalog {msg.length})", wrong=len(bad), frames=len(frames))
    return passed(f"DLC {msg.length} in all {len(frames)} frames", frames=len(frames))


def range_outcome(msg: MessageCodec, frames: Sequence[Any]) -> Outcome:
    """Every frame of ``msg`` with the catalog's length decodes with its signals in range."""
    frames = [f for f in frames if len(f.data) == msg.length]
    errors = []
    for f in frames:
        try:
            msg.decode(f.data)
        except ProtocolError as exc:
            errors.append(str(exc))
    if errors:
        return failed(f"{len(errors)} of {len(frames)} frames out of range: {errors[0]}",
                      out_of_range=len(errors))
    return passed(f"all {len(frames)} frames in range", frames=len(frames))


def check_dlc(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        return dlc_outcome(msg, _frames_or_skip(ctx, msg))
    return run


def check_range(msg: MessageCodec) -> CheckFunc:
    def run(ctx: Context) -> Outcome:
        return range_outcome(msg, _frames_or_skip(ctx, msg))
    return run


def cycle_stats(stamps: Sequence[float]) -> tuple[float, float]:
    """(mean interval, largest gap) [s] of increasing timestamps (at least two)."""
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    return (stamps[-1] - stamps[0]) / len(gaps), max(gaps)


def bursts(stamps: Sequence[float], cycle: float) -> list[float]:
    """Start times of the bursts of a message sent as several frames per cycle: a frame
    more than half a cycle after the start of the current burst starts the next one."""
    starts: list[float] = []
    for t in stamps:
        if not starts or t - starts[-1] > cycle / 2:
            starts.append(t)
    return starts


def slips_between(heartbeats: Sequence[tuple[float, dict[str, Any]]], a: float, b: float
                  ) -> int | None:
    """How many slips of its time (Heartbeat.Overruns steps, mod 16) the lower computer
    reports between bus time ``a`` and ``b``: its last Heartbeat at or before ``a`` against its
    first at or after ``b`` (``heartbeats``: (stamp, values) in stamp order). None when they are
    not both there, or a reboot lies between them."""
    before = [v for t, v in heartbeats if t <= a]
    after = [v for t, v in heartbeats if t >= b]
    return overrun_steps(before[-1], after[0]) if before and after else None


def _heartbeats(ctx: Context) -> list[tuple[float, dict[str, Any]]]:
    """Every Heartbeat of the run so far as (bus stamp, values), in stamp order."""
    msg = ctx.codec.message("Heartbeat")
    return sorted(((f.stamp, dict(msg.decode(f.data, strict=False)))
                   for f in ctx.client.raw_frames(msg.frame_id) if len(f.data) == msg.length),
                  key=lambda x: x[0])


def check_cycle(msg: MessageCodec) -> CheckFunc:
    """Mean interval within the tolerance of the catalog's cycle, and no gap above
    ``max_gap_cycles`` cycles plus the host's jitter. A gap across which the lower computer
    reports that its time slipped (Heartbeat.Overruns moved: it fell behind real time, and says
    so) is shown, not judged, as frame.Heartbeat.uptime does: neither the gap nor its interval
    counts in the mean."""
    cycle = msg.cycle_time or 0.0

    def run(ctx: Context) -> Outcome:
        # every frame counts, also one of the wrong length: it was sent on time
        stamps = sorted(f.stamp for f in _frames_or_skip(ctx, msg))
        if msg.name in ROW_KEYS:
            stamps = bursts(stamps, cycle)
        s = ctx.settings
        if len(stamps) < 3:
            return skipped(f"fewer than 3 cycles in {s.observe:g} s (raise --observe)")
        gap_limit = s.max_gap_cycles * cycle + s.jitter
        pairs = list(itertools.pairwise(stamps))
        heartbeats = _heartbeats(ctx) if any(b - a > gap_limit for a, b in pairs) else []
        slipped: list[float] = []
        judged: list[float] = []
        for a, b in pairs:
            late = b - a > gap_limit and bool(slips_between(heartbeats, a, b))
            (slipped if late else judged).append(b - a)
        if not judged:
            return skipped(f"every interval lies across a slip the lower computer reported "
                           f"in {s.observe:g} s (raise --observe)")
        worst_mean, worst_gap = sum(judged) / len(judged), max(judged)
        measured = {"cycle_ms": round(cycle * 1e3, 3), "mean_ms": round(worst_mean * 1e3, 3),
                    "max_gap_ms": round(worst_gap * 1e3, 3), "slipped_gaps": len(slipped)}
        text = (f"mean {worst_mean * 1e3:.1f} ms (catalog {cycle * 1e3:g} ms), "
                f"max gap {worst_gap * 1e3:.1f} ms")
        if slipped:
            text += (f"; {len(slipped)} gap{'s' if len(slipped) != 1 else ''} up to "
                     f"{max(slipped) * 1e3:.0f} ms across a slip the lower computer reported "
                     "(Heartbeat.Overruns) not judged")
        if abs(worst_mean - cycle) > s.cycle_tolerance * cycle:
            return failed(f"{text}: mean off by more than {s.cycle_tolerance:.0%}", **measured)
        if worst_gap > gap_limit:
            return failed(f"{text}: gap above {gap_limit * 1e3:.0f} ms", **measured)
        return passed(text, **measured)
    return run


def counter_steps(counters: Sequence[int]) -> tuple[int, int, str]:
    """(steps, steps that are not +1 mod 16, an example) of a counter sequence."""
    bad, example = 0, ""
    for a, b in itertools.pairwise(counters):
        if b != (a + 1) & 0xF:
            bad += 1
            example = example or f"{a} -> {b}"
    return max(0, len(counters) - 1), bad, example


def shared_cycles(rows: Sequence[tuple[Any, int]]) -> tuple[list[int], int]:
    """Group (row key, counter) frames into cycles that share one counter.

    A new cycle starts when the counter changes or a row repeats. Returns the counter of each
    cycle and the number of inner cycles (not the first or last) that miss a row.
    """
    cycles: list[tuple[int, set[Any]]] = []
    for key, counter in rows:
        if not cycles or cycles[-1][0] != counter or key in cycles[-1][1]:
            cycles.append((counter, set()))
        cycles[-1][1].add(key)
    everyone = set().union(*(keys for _, keys in cycles)) if cycles else set()
    incomplete = sum(keys != everyone for _, keys in cycles[1:-1])
    return [c for c, _ in cycles], incomplete


def check_counter(msg: MessageCodec) -> CheckFunc:
    keys = ROW_KEYS.get(msg.name, ())
    shared = shared_counter(msg)

    def run(ctx: Context) -> Outcome:
        # a frame of the wrong length (frame.*.dlc) hides its counter: restart the sequence
        segments: list[list[dict[str, Any]]] = [[]]
        for f in _frames_or_skip(ctx, msg):
            if len(f.data) == msg.length:
                segments[-1].append(dict(msg.decode(f.data, strict=False)))
            elif segments[-1]:
                segments.append([])
        steps = bad = incomplete = 0
        example = ""
        for seg in segments:
            if shared:
                counters, missing = shared_cycles(
                    [(tuple(v[k] for k in keys), int(v["Counter"])) for v in seg])
                incomplete += missing
            else:
                counters = [int(v["Counter"]) for v in seg]
            n, b, e = counter_steps(counters)
            steps, bad, example = steps + n, bad + b, example or e
        require(steps >= 1, "fewer than 2 frames of the catalog length")
        what = "cycles" if shared else "frames"
        if incomplete:
            return failed(f"{incomplete} cycles whose frames do not share one counter",
                          incomplete=incomplete)
        if bad:
            return failed(f"{bad} of {steps} steps between {what} not +1 mod 16 "
                          f"(e.g. {example})", bad_steps=bad, steps=steps)
        return passed(f"+1 mod 16 over {steps} {what}" + (" (shared per cycle)" if shared
                                                          else ""), steps=steps)
    return run


def check_uptime(ctx: Context) -> Outcome:
    """Heartbeat Uptime advances by one Heartbeat cycle per cycle between two frames: the lower
    computer's clock against its own schedule. The cycles between two frames are the Counter's
    step; where it disagrees with the reception times rounded to whole cycles (a stuck
    Counter, a sender that skips cycles: the counter and cycle checks' findings) the rounded
    reception times are used, and a pair across which the lower computer reports a slip
    (Overruns changed: its time fell behind real time) is not judged. A frame may go out up to
    one control period off its slot: the allowance per step is two control periods plus the
    resolution of Uptime."""
    msg = ctx.codec.message("Heartbeat")
    cycle = msg.cycle_time or 0.0
    require(cycle > 0 and msg.has_counter, "Heartbeat has no cycle time or no Counter")
    allowance = 2 * control_period(ctx.codec) + 2 * msg.signal("Uptime").scale
    frames = [(f.stamp, dict(msg.decode(f.data, strict=False)))
              for f in _frames_or_skip(ctx, msg) if len(f.data) == msg.length]
    problems: list[str] = []
    judged, overruns, counted, advanced = 0, 0, 0.0, 0.0
    for (ta, a), (tb, b) in itertools.pairwise(frames):
        slipped = overrun_steps(a, b)
        if slipped is None:
            continue  # a reboot restarts Uptime
        overruns += slipped
        if slipped:
            continue
        by_counter = (int(b["Counter"]) - int(a["Counter"])) % 16
        by_clock = round((tb - ta) / cycle)
        n = by_counter if by_counter and by_counter == by_clock % 16 else by_clock
        got = float(b["Uptime"]) - float(a["Uptime"])
        judged, counted, advanced = judged + 1, counted + n * cycle, advanced + got
        if abs(got - n * cycle) > allowance and not problems:
            problems.append(f"Uptime {float(a['Uptime']):.3f} -> {float(b['Uptime']):.3f} s "
                            f"over {n} Heartbeat cycle{'s' if n != 1 else ''} "
                            f"({n * cycle:g} s +- {allowance:.3f})")
    measured = {"steps": judged, "counted_s": round(counted, 3),
                "uptime_advanced_s": round(advanced, 3), "overruns": overruns}
    if judged < 2:
        return skipped(f"fewer than 2 Heartbeat steps without a reboot or a slip in "
                       f"{ctx.settings.observe:g} s (raise --observe)", **measured)
    if problems:
        return failed(f"{problems[0]}: the Uptime clock does not run at 1 s/s against the "
                      "Heartbeat schedule", **measured)
    slips = (f"; {overruns} slip{'s' if overruns != 1 else ''} (Overruns) not judged"
             if overruns else "")
    return passed(f"Uptime advanced {advanced:.3f} s over {counted:g} s of Heartbeat "
                  f"cycles{slips}", **measured)


def frame_checks(codec: Codec) -> list[Check]:
    """The per-frame checks of every periodic message the lower computer sends."""
    checks = []
    for msg in periodic_lower_messages(codec):
        cycle = f"{(msg.cycle_time or 0) * 1e3:g} ms"
        checks += [
            Check(f"frame.{msg.name}.present", f"{msg.name} is sent", check_present(msg)),
            Check(f"frame.{msg.name}.dlc", f"{msg.name} has DLC {msg.length}", check_dlc(msg)),
            Check(f"frame.{msg.name}.range", f"every {msg.name} value is within the catalog "
                  "range", check_range(msg)),
            Check(f"frame.{msg.name}.cycle", f"{msg.name} every {cycle}", check_cycle(msg)),
        ]
        if msg.has_counter:
            checks.append(Check(
                f"frame.{msg.name}.counter",
                f"{msg.name} counter +1 mod 16 per "
                + ("cycle, shared by the cycle's frames" if shared_counter(msg) else "frame"),
                check_counter(msg)))
        if msg.name == "Heartbeat" and "Uptime" in msg.signal_names:
            checks.append(Check("frame.Heartbeat.uptime", "Heartbeat Uptime advances one "
                                f"cycle ({cycle}) per Counter step", check_uptime))
    return checks
