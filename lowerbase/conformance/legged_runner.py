"""``lowerbase conformance --robot legged``: the legged suite's registry, its robustness
checks and the runner (the report and JUnit XML are the wheeled suite's)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

from lowerbase.conformance.core import (
    Check,
    CheckResult,
    Outcome,
    Report,
    passed,
    require,
)
from lowerbase.conformance.legged_checks import (
    SETTLE,
    check_comm_enabled,
    check_enter_motor_mode,
    check_exit_motor_mode,
    check_link,
    check_motor_enabled,
    check_motor_ready,
    check_not_allowed,
    check_refused,
    check_reply_per_command,
    check_sit,
    check_stand,
    check_start,
    check_stop,
    check_test_mode,
    check_velocity,
    check_velocity_timeout,
    check_zero_position,
)
from lowerbase.conformance.legged_context import LeggedContext, LeggedSettings, legged_check
from lowerbase.conformance.legged_frames import legged_frame_checks
from lowerbase.conformance.legged_link import LeggedLink
from lowerbase.conformance.runner import run_in_order
from lowerbase.protocol.legged import BODY_BUS, LocomotionState, legged_codec

S = LocomotionState
UNKNOWN_IDS = (0x004, 0x123, 0x555, 0x7FF)


def _unchanged(ctx: LeggedContext, what: str, send: Callable[[], None],
               keys: tuple[str, ...] = ("State", "LastRequest")) -> Outcome:
    """Send (``send``) in COMM_DISABLED: Heartbeats go on with the same BootCounter, the
    LocomotionStatus ``keys`` do not change."""
    hb = ctx.codec.message("Heartbeat")
    before = ctx.status(ctx.now() - 0.05)
    require(int(before["State"]) == S.COMM_DISABLED, "not in COMM_DISABLED (see "
            "locomotion.stop)")
    boot = hb.decode(ctx.body_frames(hb)[-1].data, strict=False)["BootCounter"]
    t = ctx.now()
    send()
    period = hb.cycle_time or 0.5
    require(ctx.wait_until(lambda: bool(ctx.body_frames(hb, t + SETTLE)),
                           2.5 * period + ctx.settings.jitter),
            f"no Heartbeat within 2.5 cycles after {what}")
    after_hb = hb.decode(ctx.body_frames(hb, t + SETTLE)[-1].data, strict=False)
    after = ctx.status(ctx.now())
    require(after_hb["BootCounter"] == boot, f"BootCounter {boot} -> "
            f"{after_hb['BootCounter']} after {what} (rebooted)")
    changed = [f"{k} {before[k]} -> {after[k]}" for k in keys if before[k] != after[k]]
    require(not changed, f"after {what}: {', '.join(changed)}")
    return passed(f"{what}: ignored, Heartbeats go on")


def check_unknown_ids(ctx: LeggedContext) -> Outcome:
    def send() -> None:
        for _ in range(10):
            for bus in (BODY_BUS, 2):
                for i in UNKNOWN_IDS:
                    ctx.link.send(bus, i, bytes(8))
            ctx.wait(0.002)
    return _unchanged(ctx, f"80 frames on IDs {', '.join(f'0x{i:03X}' for i in UNKNOWN_IDS)}",
                      send)


def check_wrong_bus(ctx: LeggedContext) -> Outcome:
    req = ctx.codec.message("LocomotionRequest")
    data = req.encode({"Request": int(S.COMM_ENABLED), "Counter": 0})

    def send() -> None:
        for bus in (1, 2, 3):
            ctx.link.send(bus, req.frame_id, data)
    return _unchanged(ctx, "LocomotionRequest COMM_ENABLED on the FL, RR, RL buses", send)


def check_bad_dlc(ctx: LeggedContext) -> Outcome:
    req = ctx.codec.message("LocomotionRequest")
    data = req.encode({"Request": int(S.COMM_ENABLED), "Counter": 0})

    def send() -> None:
        for payload in (data[:1], data + bytes(6), b""):
            ctx.link.send(BODY_BUS, req.frame_id, payload)
    return _unchanged(ctx, "LocomotionRequest COMM_ENABLED with DLC 1, 8 and 0", send)


def check_out_of_range(ctx: LeggedContext) -> Outcome:
    req = ctx.codec.message("LocomotionRequest")

    def send() -> None:
        for value in (10, 12, 15):  # Request is 4 bits; the table ends at 9
            ctx.link.send(BODY_BUS, req.frame_id, bytes((value, 0)))
    return _unchanged(ctx, "LocomotionRequest 10, 12, 15", send, keys=("State",))


def legged_registry() -> list[Check]:
    """Every legged check, in run order."""
    c = legged_check
    return [
        c("link.heartbeat", "the lower computer is on bus 0 and speaks legged.dbc", check_link),
        c("locomotion.start", "brought to COMM_DISABLED: no actuator traffic there",
          check_start),
        c("locomotion.not_allowed", "requests outside the state table are refused "
          "NotAllowed", check_not_allowed),
        c("locomotion.comm_enabled", "COMM_ENABLED: 1 kHz commands with zero gains",
          check_comm_enabled),
        c("locomotion.motor_ready", "MOTOR_READY accepted", check_motor_ready),
        c("locomotion.motor_enabled", "MOTOR_ENABLED through MOTOR_COMMUTATION",
          check_motor_enabled),
        c("actuator.enter_motor_mode", "one enter-motor-mode frame per actuator, answered",
          check_enter_motor_mode),
        *legged_frame_checks(legged_codec()),
        c("actuator.reply_per_command", "every actuator answers every command once",
          check_reply_per_command),
        c("actuator.test_mode", "IN_TEST_MODE: the body falls silent, upper commands and "
          "special frames are answered", check_test_mode),
        c("actuator.zero_position", "zero-position: the actuator then reports 0",
          check_zero_position),
        c("actuator.refused_outside_test_mode", "upper commands outside IN_TEST_MODE are "
          "not obeyed", check_refused),
        c("body.stand", "STANDING_MODE stands up (Busy meanwhile), then IN_CONTROL",
          check_stand),
        c("body.velocity", "BodyVelocityCommand is walked; BasePosition integrates "
          "BaseVelocity", check_velocity),
        c("body.velocity_timeout", "without BodyVelocityCommand for commandTimeout: zero "
          "velocity, still IN_CONTROL", check_velocity_timeout),
        c("body.sit", "SITDOWN_MODE sits down (Busy meanwhile), then MOTOR_ENABLED", check_sit),
        c("actuator.exit_motor_mode", "MOTOR_DISABLED: one exit-motor-mode frame per "
          "actuator, answered", check_exit_motor_mode),
        c("locomotion.stop", "COMM_DISABLED: the actuator traffic stops", check_stop),
        c("robust.unknown_id", "frames on unknown IDs are ignored", check_unknown_ids),
        c("robust.wrong_bus", "body requests on a leg bus other than 0 are ignored",
          check_wrong_bus),
        c("robust.bad_dlc", "a LocomotionRequest of the wrong length is ignored",
          check_bad_dlc),
        c("robust.out_of_range", "a LocomotionRequest outside the value table changes "
          "nothing", check_out_of_range),
    ]


def run_legged_suite(
    link: LeggedLink, checks: Sequence[Check], settings: LeggedSettings | None = None,
    on_result: Callable[[CheckResult], None] | None = None,
) -> Report:
    """Run ``checks`` in order against the legged lower computer behind ``link``; the robot
    is left in COMM_DISABLED."""
    settings = settings or LeggedSettings()
    start = time.monotonic()
    ctx = LeggedContext(link, settings)
    try:
        if not any(c.id == "link.heartbeat" for c in checks):
            check_link(ctx)
        results = run_in_order(checks, ctx, on_result)  # type: ignore[arg-type]  # a LeggedContext
    finally:
        if ctx.linked:
            ctx.go_to(S.COMM_DISABLED)
    return Report(tuple(results), time.monotonic() - start, linked=ctx.linked)
