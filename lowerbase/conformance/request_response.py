"""``link``, ``param``, ``version`` and ``led``: the request/response pairs."""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from typing import Any

from lowerbase.conformance.catalog import (
    _close,
    parameter_index,
    parameter_limits,
    protocol_version,
)
from lowerbase.conformance.context import Context
from lowerbase.conformance.core import Outcome, failed, passed, require
from lowerbase.conformance.lower_client import Received

# -- link -----------------------------------------------------------------------------------------


def check_link(ctx: Context) -> Outcome:
    if not ctx.linked:
        return failed(f"nothing from the lower computer in {ctx.settings.link_timeout:g} s")
    hb = ctx.latest("Heartbeat")
    want = protocol_version(ctx.codec)
    got = int(hb.values["ProtocolVersion"])
    require(got == want, f"ProtocolVersion {got}, the catalog is version {want}")
    return passed(f"Heartbeat: boot #{hb.values['BootCounter']}, uptime "
                  f"{hb.values['Uptime']:.1f} s, protocol {got}",
                  boot_counter=hb.values["BootCounter"], uptime_s=hb.values["Uptime"],
                  protocol_version=got)


# -- parameters -----------------------------------------------------------------------------------

RESULT_ACK, RESULT_UNKNOWN_INDEX, RESULT_OUT_OF_RANGE = 0, 1, 2
#: the parameter the suite writes: it limits only the remote controller, never CAN motion
WRITE_PARAMETER = "joystickMaxLinear"


def _result_name(ctx: Context, result: int) -> str:
    return ctx.codec.message("ParameterResponse").signal("Result").choices.get(
        result, str(result))


def check_param_read(ctx: Context) -> Outcome:
    limits = parameter_limits()
    table = ctx.codec.message("ParameterRequest").signal("Index").choices
    values: dict[str, float] = {}
    problems: list[str] = []
    misses = 0
    for index, name in sorted(table.items()):
        reply = ctx.parameter_request(index)
        if reply is None:
            problems.append(f"{name}: no answer")
            misses += 1
            require(misses < 3, "no answer to 3 ParameterRequests: " + "; ".join(problems))
            continue
        result, value = int(reply.values["Result"]), float(reply.values["Value"])
        if result != RESULT_ACK:
            problems.append(f"{name}: {_result_name(ctx, result)}")
            continue
        ctx.param_cache[index] = value
        values[name] = value
        if index in limits:
            _, lo, hi = limits[index]
            if not lo <= value <= hi:
                problems.append(f"{name} = {value:g} outside [{lo:g}, {hi:g}]")
    if problems:
        return failed("; ".join(problems), **values)
    return passed(f"{len(values)} parameters acked, all in range", **values)


def _write_value(current: float, lo: float, hi: float) -> float:
    """A valid value other than ``current``: halfway towards the farther limit."""
    target = hi if current - lo < hi - current else lo
    return round((current + target) / 2, 3)


def check_param_write(ctx: Context) -> Outcome:
    index = parameter_index(ctx.codec, WRITE_PARAMETER)
    _, lo, hi = parameter_limits()[index]
    original = ctx.parameter(WRITE_PARAMETER)
    new = _write_value(original, lo, hi)
    ctx.to_restore.setdefault(index, original)
    reply = ctx.parameter_request(index, new)
    require(reply is not None, f"write {WRITE_PARAMETER} = {new:g}: no answer")
    assert reply is not None
    result, value = int(reply.values["Result"]), float(reply.values["Value"])
    require(result == RESULT_ACK, f"write {WRITE_PARAMETER} = {new:g}: "
            f"{_result_name(ctx, result)}")
    require(_close(value, new), f"write {WRITE_PARAMETER} = {new:g} answered {value:g}")
    back = ctx.parameter_request(index)
    require(back is not None and _close(float(back.values["Value"]), new),
            f"read back {WRITE_PARAMETER}: expected {new:g}, got "
            f"{back.values['Value'] if back else 'no answer'}")
    restore = ctx.parameter_request(index, original)
    require(restore is not None and restore.values["Result"] == RESULT_ACK
            and _close(float(restore.values["Value"]), original),
            f"restore {WRITE_PARAMETER} = {original:g} failed")
    ctx.to_restore.pop(index, None)
    return passed(f"{WRITE_PARAMETER}: {original:g} -> {new:g} -> {original:g}",
                  original=original, written=new)


def check_param_out_of_range(ctx: Context) -> Outcome:
    index = parameter_index(ctx.codec, WRITE_PARAMETER)
    _, lo, hi = parameter_limits()[index]
    original = ctx.parameter(WRITE_PARAMETER)
    bad = hi + (hi - lo)
    ctx.to_restore.setdefault(index, original)
    reply = ctx.parameter_request(index, bad)
    require(reply is not None, f"write {WRITE_PARAMETER} = {bad:g}: no answer")
    assert reply is not None
    result, value = int(reply.values["Result"]), float(reply.values["Value"])
    require(result == RESULT_OUT_OF_RANGE,
            f"write {WRITE_PARAMETER} = {bad:g} (limit {hi:g}): {_result_name(ctx, result)}, "
            "expected OutOfRange", result=result, value=value)
    require(_close(value, original),
            f"nack carries {value:g}, expected the value in force {original:g}")
    back = ctx.parameter_request(index)
    require(back is not None and _close(float(back.values["Value"]), original),
            f"{WRITE_PARAMETER} changed by a refused write")
    ctx.to_restore.pop(index, None)
    return passed(f"{WRITE_PARAMETER} = {bad:g} -> OutOfRange, {original:g} kept")


def check_param_unknown(ctx: Context) -> Outcome:
    known = ctx.codec.message("ParameterRequest").signal("Index").choices
    index = next(i for i in range(256) if i not in known)
    for value in (None, 1.0):
        reply = ctx.parameter_request(index, value)
        op = "read" if value is None else "write"
        require(reply is not None, f"{op} index {index}: no answer")
        assert reply is not None
        result = int(reply.values["Result"])
        require(result == RESULT_UNKNOWN_INDEX,
                f"{op} index {index}: {_result_name(ctx, result)}, expected UnknownIndex")
    return passed(f"read and write of index {index} -> UnknownIndex")


# -- versions -----------------------------------------------------------------------------------


def _assemble(frames: Iterable[Received]) -> dict[int, list[tuple[int, bool, bytes]]]:
    pieces: dict[int, list[tuple[int, bool, bytes]]] = {}
    for f in frames:
        v = f.values
        text = int(v["Text"]).to_bytes(6, "little")
        pieces.setdefault(int(v["Field"]), []).append((int(v["Sequence"]), bool(v["Last"]),
                                                       text))
    return pieces


def version_string(pieces: Sequence[tuple[int, bool, bytes]]) -> str | None:
    """The string of one field's pieces, or None while incomplete."""
    by_seq = {seq: (last, text) for seq, last, text in pieces}
    lasts = [seq for seq, (last, _) in by_seq.items() if last]
    if not lasts or set(by_seq) != set(range(lasts[0] + 1)):
        return None
    raw = b"".join(by_seq[i][1] for i in range(lasts[0] + 1))
    return raw.rstrip(b"\0").decode("ascii", errors="replace")


def _request_versions(ctx: Context, field_no: int, want: set[int]
                      ) -> dict[int, list[tuple[int, bool, bytes]]]:
    t = time.monotonic()
    ctx.client.send("VersionRequest", Field=field_no)

    def complete() -> bool:
        got = _assemble(ctx.client.frames("VersionResponse", t))
        return all(f in got and version_string(got[f]) is not None for f in want)

    ctx.wait_until(complete, 2 * ctx.settings.reply_timeout)
    time.sleep(0.1)  # late or duplicate pieces would show up now
    return _assemble(ctx.client.frames("VersionResponse", t))


def _check_pieces(field_name: str, pieces: list[tuple[int, bool, bytes]]) -> str:
    seqs = [p[0] for p in pieces]
    require(len(seqs) == len(set(seqs)), f"{field_name}: repeated pieces {sorted(seqs)}")
    text = version_string(pieces)
    require(text is not None, f"{field_name}: incomplete (pieces {sorted(seqs)})")
    assert text is not None
    require(text and text.isprintable() and text.isascii(),
            f"{field_name}: not printable ASCII: {text!r}")
    return text


def check_version_all(ctx: Context) -> Outcome:
    names = ctx.codec.message("VersionResponse").signal("Field").choices
    got = _request_versions(ctx, 0, set(names))
    missing = [names[f] for f in names if f not in got]
    require(not missing, f"no {', '.join(missing)}")
    for f, pieces in sorted(got.items()):
        require(f in names, f"unknown Field {f}")
        ctx.versions[f] = _check_pieces(names[f], pieces)
    shown = {names[f]: text for f, text in sorted(ctx.versions.items())}
    return passed(", ".join(shown.values()), **shown)


def check_version_field(ctx: Context) -> Outcome:
    names = ctx.codec.message("VersionResponse").signal("Field").choices
    field_no = 2  # SoftwareVersion
    got = _request_versions(ctx, field_no, {field_no})
    require(field_no in got, f"no {names[field_no]}")
    others = sorted(names.get(f, str(f)) for f in got if f != field_no)
    require(not others, f"asked for {names[field_no]}, also got {', '.join(others)}")
    text = _check_pieces(names[field_no], got[field_no])
    if field_no in ctx.versions:
        require(text == ctx.versions[field_no],
                f"{text!r} differs from {ctx.versions[field_no]!r} of VersionRequest All")
    return passed(f"{names[field_no]} only: {text}", text=text)


# -- LEDs -----------------------------------------------------------------------------------------

LED_SIGNALS = ("Urgency", "Abnormal", "Normal", "Color")


def check_led(ctx: Context) -> Outcome:
    strip, sub = 0, 8
    state = ctx.codec.message("LedState")
    wait = 2.5 * (state.cycle_time or 1.0)

    def row(v: dict[str, Any]) -> bool:
        return bool(v["Strip"] == strip and v["Submodule"] == sub)

    before = ctx.client.expect("LedState", row, since=0.0, timeout=wait)
    require(before is not None, f"no LedState of strip {strip} submodule {sub}")
    assert before is not None
    want = {"Urgency": 0, "Abnormal": 0, "Normal": 128, "Color": 0x123456}  # Forward, a colour
    if all(before.values[k] == want[k] for k in LED_SIGNALS):
        want["Color"] = 0x654321
    t = time.monotonic()
    ctx.client.send("LedCommand", Strip=strip, Submodule=sub, **want)
    shown = ctx.client.expect(
        "LedState", lambda v: row(v) and all(v[k] == want[k] for k in LED_SIGNALS), since=t,
        timeout=wait)
    latency = shown.t - t if shown else None
    old = {k: before.values[k] for k in LED_SIGNALS}
    t = time.monotonic()
    ctx.client.send("LedCommand", Strip=strip, Submodule=sub, **old)
    require(shown is not None, f"LedCommand {want} not shown by LedState within {wait:g} s")
    restored = ctx.client.expect(
        "LedState", lambda v: row(v) and all(v[k] == old[k] for k in LED_SIGNALS), since=t,
        timeout=wait)
    require(restored is not None, "LedState did not return to its previous value")
    return passed(f"strip {strip} submodule {sub} shown after {latency:.2f} s and restored",
                  latency_s=round(latency or 0.0, 3))
