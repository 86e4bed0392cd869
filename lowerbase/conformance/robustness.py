"""``robust``: unknown IDs, extended IDs, wrong lengths and out-of-range values."""

from __future__ import annotations

import struct
import time

import can

from lowerbase.conformance.context import Context
from lowerbase.conformance.core import Outcome, passed, require, skipped
from lowerbase.protocol.status_codes import StatusBit

# -- robustness -----------------------------------------------------------------------------------

UNKNOWN_IDS = (0x001, 0x123, 0x555, 0x7FF)


def _snapshot(ctx: Context) -> tuple[int, int, int]:
    """(BootCounter, RobotState, StatusCode) now."""
    return (int(ctx.latest("Heartbeat").values["BootCounter"]), ctx.state(),
            ctx.status_code(since=time.monotonic()))


def _survived(ctx: Context, before: tuple[int, int, int], since: float,
              allowed_bits: int = 0) -> tuple[int, int, int]:
    """Require Heartbeats after ``since`` with the same BootCounter and no state change."""
    hb_cycle = ctx.codec.message("Heartbeat").cycle_time or 0.5
    hb = ctx.client.expect("Heartbeat", since=since, timeout=2.5 * hb_cycle + 0.5)
    require(hb is not None, "Heartbeat stopped")
    assert hb is not None
    boot, state, code = before
    require(int(hb.values["BootCounter"]) == boot,
            f"rebooted (BootCounter {boot} -> {hb.values['BootCounter']})")
    now_state = ctx.state()
    require(now_state == state,
            f"RobotState {ctx.state_name(state)} -> {ctx.state_name(now_state)}")
    new_code = ctx.status_code(since=time.monotonic())
    appeared = new_code & ~code & ~allowed_bits
    require(not appeared, f"StatusCode gained {StatusBit(appeared)!r}")
    return int(hb.values["BootCounter"]), now_state, new_code


def _clear_rejected(ctx: Context) -> None:
    """FaultClear, and require COMMAND_REJECTED to be gone afterwards."""
    t = ctx.control("FaultClear")
    got = ctx.client.expect(
        "StatusCode", lambda v: not v["Code"] & StatusBit.COMMAND_REJECTED, since=t + 0.01,
        timeout=ctx.settings.reply_timeout)
    require(got is not None, "FaultClear did not clear COMMAND_REJECTED")


def _expect_rejected(ctx: Context, since: float, what: str) -> None:
    got = ctx.client.expect("StatusCode", lambda v: v["Code"] & StatusBit.COMMAND_REJECTED,
                            since=since, timeout=ctx.settings.reply_timeout)
    require(got is not None, f"{what}: StatusCode COMMAND_REJECTED not set")


def check_unknown_ids(ctx: Context) -> Outcome:
    before = _snapshot(ctx)
    t = time.monotonic()
    for i in range(10):
        for frame_id in UNKNOWN_IDS:
            ctx.client.send_raw(frame_id, bytes([0xFF, i, 0x00, 0x55, 0xAA, 0x01, 0x02, 0x7F]))
        time.sleep(0.005)
    hz = len(ctx.client.frames("SystemStatus", t))
    _survived(ctx, before, t)
    return passed(f"{10 * len(UNKNOWN_IDS)} frames on IDs "
                  f"{', '.join(f'{i:#05x}' for i in UNKNOWN_IDS)} ignored", frames=hz)


def check_extended_ids(ctx: Context) -> Outcome:
    """Extended frames whose 29-bit IDs equal catalog IDs belong to other devices."""
    before = _snapshot(ctx)
    control = ctx.codec.message("ControlCommand")
    t = time.monotonic()
    try:
        for command in ("Reboot", "EStopSet"):
            number = control.choice_number("Command", command)
            ctx.client.send_raw(control.frame_id, bytes([number]), extended=True)
    except can.CanOperationError as exc:  # the serial framing carries 11-bit IDs only
        return skipped(f"this transport cannot send extended frames ({exc})")
    _survived(ctx, before, t)
    return passed("extended frames with the IDs of ControlCommand Reboot and EStopSet ignored")


def check_bad_dlc(ctx: Context) -> Outcome:
    _clear_rejected(ctx)
    before = _snapshot(ctx)
    motion = ctx.codec.message("MotionCommand")
    good = motion.encode({"Linear": 0.0, "Angular": 0.0, "Mode": 0, "Counter": 0})
    t = time.monotonic()
    ctx.client.send_raw(motion.frame_id, good[:-1])
    ctx.client.send_raw(motion.frame_id, good + b"\0\0")
    _expect_rejected(ctx, t, f"MotionCommand with DLC {len(good) - 1} and {len(good) + 2}")
    ctx.client.send_raw(ctx.codec.message("ControlCommand").frame_id, b"")
    ctx.client.send_raw(ctx.codec.message("ParameterRequest").frame_id, b"\x00\x00")
    ctx.client.send_raw(ctx.codec.message("VersionRequest").frame_id, bytes(8))
    _survived(ctx, before, t, allowed_bits=StatusBit.COMMAND_REJECTED)
    _clear_rejected(ctx)
    return passed("wrong-length MotionCommand flagged COMMAND_REJECTED; ControlCommand, "
                  "ParameterRequest, VersionRequest of wrong length survived")


def check_out_of_range(ctx: Context) -> Outcome:
    _clear_rejected(ctx)
    before = _snapshot(ctx)
    motion = ctx.codec.message("MotionCommand")
    data = bytearray(motion.encode({"Linear": 0.0, "Angular": 0.0, "Mode": 0, "Counter": 0}))
    struct.pack_into("<h", data, 0, 0x7FFF)  # Linear 32.767 m/s, beyond the catalog's 3 m/s
    t = time.monotonic()
    ctx.client.send_raw(motion.frame_id, bytes(data))
    _expect_rejected(ctx, t, "MotionCommand Linear 32.767 m/s")
    control = ctx.codec.message("ControlCommand").frame_id
    ctx.client.send_raw(control, b"\x00")  # Command 0 and 255: outside [1, 7]
    ctx.client.send_raw(control, b"\xff")
    ctx.client.send_raw(ctx.codec.message("VersionRequest").frame_id, b"\x09")
    _survived(ctx, before, t, allowed_bits=StatusBit.COMMAND_REJECTED)
    _clear_rejected(ctx)
    return passed("MotionCommand out of range flagged COMMAND_REJECTED; ControlCommand 0 and "
                  "255, VersionRequest 9 survived")
