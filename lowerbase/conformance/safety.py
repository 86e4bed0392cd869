"""``safety``: reboot, standby, enable, watchdog, e-stop."""

from __future__ import annotations

import itertools
import time

from lowerbase.conformance.catalog import control_period
from lowerbase.conformance.context import (
    ACTIVE,
    BOOT,
    CONTROL_CAN,
    EMERGENCY_STOP,
    STANDBY,
    STILL,
    Context,
)
from lowerbase.conformance.core import CheckFailed, CheckSkipped, Outcome, passed, require
from lowerbase.conformance.lower_client import Received
from lowerbase.protocol.status_codes import StatusBit

# -- safety ---------------------------------------------------------------------------------------


def check_reboot(ctx: Context) -> Outcome:
    before = int(ctx.latest("Heartbeat").values["BootCounter"])
    t, hb = ctx.reboot()
    boot = int(hb.values["BootCounter"])
    require(boot == (before + 1) & 0xFFFF, f"BootCounter {before} -> {boot}, expected +1")
    uptime = float(hb.values["Uptime"])
    require(uptime < 5.0, f"boot-up Heartbeat with uptime {uptime:.1f} s")
    return passed(f"BootCounter {before} -> {boot}, boot-up Heartbeat after {hb.t - t:.2f} s",
                  reboot_s=round(hb.t - t, 3), boot_counter=boot)


def check_standby_after_boot(ctx: Context) -> Outcome:
    try:
        _, hb = ctx.reboot()
    except CheckFailed as exc:
        raise CheckSkipped(f"no reboot ({exc.detail})") from None
    standby = ctx.expect_state(lambda v: v["RobotState"] == STANDBY, hb.t, timeout=3.0)
    require(standby is not None, "no Standby within 3 s of the boot-up Heartbeat")
    assert standby is not None
    for f in ctx.client.frames("SystemStatus", hb.t):
        v = f.values
        if f.t <= standby.t and (v["RobotState"] not in (BOOT, STANDBY) or v["ControlMode"]):
            raise CheckFailed(f"after boot: RobotState {ctx.state_name(v['RobotState'])}, "
                              f"ControlMode {v['ControlMode']}")
    return passed(f"Standby {standby.t - hb.t:.2f} s after the boot-up Heartbeat",
                  standby_s=round(standby.t - hb.t, 3))


def check_standby_ignores_motion(ctx: Context) -> Outcome:
    ctx.require_motion()
    ctx.ensure_standby()
    t0 = time.monotonic()
    with ctx.driving(ctx.settings.speed):
        time.sleep(0.6)
    t1 = time.monotonic()
    time.sleep(0.2)
    fastest = ctx.max_speed(t0)
    states = {int(f.values["RobotState"]) for f in ctx.client.frames("SystemStatus", t0)}
    codes = [int(f.values["Code"]) for f in ctx.client.frames("StatusCode", t0)]
    require(fastest < STILL * ctx.settings.speed,
            f"moved at {fastest:.3f} m/s on MotionCommand in Standby", max_speed=fastest)
    require(states == {STANDBY}, f"RobotState {sorted(map(ctx.state_name, states))} "
            "on MotionCommand in Standby")
    require(any(c & StatusBit.COMMAND_IN_STANDBY for c in codes),
            "StatusCode COMMAND_IN_STANDBY not set")
    return passed(f"{t1 - t0:.1f} s of MotionCommand ignored, COMMAND_IN_STANDBY set",
                  max_speed=fastest)


def check_enable(ctx: Context) -> Outcome:
    ctx.ensure_standby()
    t = ctx.control("EnableCanControl")
    active = ctx.expect_state(lambda v: v["RobotState"] == ACTIVE, t)
    require(active is not None, "EnableCanControl: RobotState did not become Active")
    assert active is not None
    require(active.values["ControlMode"] == CONTROL_CAN,
            f"Active with ControlMode {active.values['ControlMode']}, expected Can")
    latency = active.t - t
    if not ctx.settings.motion:
        return passed(f"Active after {latency:.2f} s (motion not checked: --no-motion)",
                      enable_s=round(latency, 3))
    t = time.monotonic()
    with ctx.driving(ctx.settings.speed):
        moving = ctx.wait_moving()
    require(moving is not None, f"MotionCommand {ctx.settings.speed:g} m/s not followed "
            f"within 2 s (max {ctx.max_speed(t):.3f} m/s)")
    assert moving is not None
    return passed(f"Active after {latency:.2f} s, follows MotionCommand after "
                  f"{moving.t - t:.2f} s", enable_s=round(latency, 3),
                  follow_s=round(moving.t - t, 3))


#: [s] how much longer than its limit the suite waits for a late watchdog, to report by how much
LATE_REPORT = 1.0


def watchdog_limits(ctx: Context, timeout: float, speed: float) -> dict[str, float]:
    """After the last MotionCommand [s]: WatchdogStop in SystemStatus, braking seen in
    MotionState, standstill (docs/conformance.md derives them).

    The lower computer notices the missing command at its first control step after
    commandTimeout (one control period, at most the catalog's shortest cycle), and the next
    frame of each message shows it (one cycle); the host's timestamps add ``jitter``. Braking
    from ``speed`` to standstill takes at most speed / linearDecelLimit on top."""
    codec, jitter = ctx.codec, ctx.settings.jitter
    react = timeout + control_period(codec) + jitter
    decel = ctx.parameter("linearDecelLimit")
    brake = react + (codec.message("MotionState").cycle_time or 0.0)
    return {"flag": react + (codec.message("SystemStatus").cycle_time or 0.0),
            "brake": brake, "still": brake + (1.0 - STILL) * speed / decel}


#: tries of the watchdog measurement: a late one the host disturbed is measured again
WATCHDOG_TRIES = 3


def host_disturbance(ctx: Context, t0: float, t1: float) -> str:
    """Why reception times in [t0, t1] do not show the lower computer's timing ('' when they
    do): a gap in MotionState's reception of more than two cycles (the lower computer or this
    process stalled: its frames came late, in a burst), or a slip of the lower computer's time
    (Heartbeat.Overruns changed, its own count of falling behind real time)."""
    cycle = ctx.codec.message("MotionState").cycle_time or 0.02
    times = [f.t for f in ctx.client.frames("MotionState", t0 - cycle) if f.t <= t1]
    gap = max((b - a for a, b in itertools.pairwise(times)), default=0.0)
    if gap > 2 * cycle:
        return f"MotionState came {gap:.3f} s apart (cycle {cycle:g} s)"
    if ctx.time_slipped(t0, t1):
        return "the lower computer's Heartbeat counted Overruns (its time slipped)"
    return ""


def check_watchdog(ctx: Context) -> Outcome:
    """Times after the last MotionCommand, by reception. A try that is late where the host
    disturbed the reception (:func:`host_disturbance`) is repeated, up to
    :data:`WATCHDOG_TRIES`; the limits stay. The last try is judged as measured."""
    ctx.require_motion()
    timeout = ctx.parameter("commandTimeout")
    limits = watchdog_limits(ctx, timeout, ctx.settings.speed)
    measured = {"command_timeout_s": timeout, **{f"limit_{k}_s": round(v, 3)
                                                 for k, v in limits.items()}}
    disturbed: list[str] = []
    for attempt in range(1, WATCHDOG_TRIES + 1):
        t_stop, got = _watchdog_try(ctx, limits)
        late = [(name, what, f) for name, (what, f) in got.items()
                if f is None or f.t - t_stop > limits[name]]
        if not late:
            break
        ends = [f.t for _, _, f in late if f is not None]
        why = host_disturbance(ctx, t_stop, max(ends, default=time.monotonic()))
        if not why or attempt == WATCHDOG_TRIES:
            break
        disturbed.append(why)
    n = len(disturbed)
    retried = {"host_disturbed_tries": n} if n else {}
    note = f" (measured again after {n} tr{'y' if n == 1 else 'ies'} the host disturbed: " \
        f"{disturbed[-1]})" if n else ""
    if late:
        name, what, f = late[0]
        when = "never" if f is None else f"after {f.t - t_stop:.3f} s"
        raise CheckFailed(f"{what} {when}, limit {limits[name]:.3f} s after the last "
                          f"MotionCommand (commandTimeout {timeout:g} s){note}",
                          **measured, **retried)
    flag, braking, still = (got[k][1] for k in ("flag", "brake", "still"))
    assert flag is not None and braking is not None and still is not None
    bit = ctx.client.expect("StatusCode", lambda v: v["Code"] & StatusBit.WATCHDOG_STOP,
                            since=t_stop, timeout=0.5)
    require(bit is not None, "SystemStatus WatchdogStop without StatusCode WATCHDOG_STOP")
    latency = flag.t - t_stop
    require(latency >= timeout - 0.05,
            f"WatchdogStop after {latency:.3f} s, before commandTimeout {timeout:g} s")
    return passed(f"WatchdogStop {latency:.3f} s (limit {limits['flag']:.3f}), braking "
                  f"{braking.t - t_stop:.3f} s, standstill {still.t - t_stop:.3f} s after "
                  f"the last MotionCommand (commandTimeout {timeout:g} s){note}",
                  watchdog_s=round(latency, 3), brake_s=round(braking.t - t_stop, 3),
                  stop_s=round(still.t - t_stop, 3), **measured, **retried)


def _watchdog_try(ctx: Context, limits: dict[str, float]
                  ) -> tuple[float, dict[str, tuple[str, Received | None]]]:
    """Drive, stop sending, and wait for the watchdog's three signs (waiting
    :data:`LATE_REPORT` past each limit, to report by how much it was late): the last
    MotionCommand's time and, per limit, what was seen and its first frame (None: never)."""
    ctx.ensure_active()
    try:
        with ctx.driving(ctx.settings.speed) as sender:
            require(ctx.wait_moving() is not None, "did not move on MotionCommand")
            time.sleep(0.1)  # past the ramp: braking is a drop from the speed reached
        t_stop = sender.last_sent
        cruise = abs(ctx.latest("MotionState").values["Linear"])

        def within(limit: float) -> float:
            return limit + LATE_REPORT - (time.monotonic() - t_stop)

        flag = ctx.expect_state(lambda v: v["WatchdogStop"] == 1, t_stop,
                                timeout=within(limits["flag"]))
        braking = ctx.client.expect("MotionState", lambda v: abs(v["Linear"]) < 0.9 * cruise,
                                    since=t_stop, timeout=within(limits["brake"]))
        still = ctx.wait_still(t_stop, timeout=within(limits["still"]))
        return t_stop, {"flag": ("SystemStatus WatchdogStop", flag),
                        "brake": ("MotionState braking", braking),
                        "still": ("MotionState standstill", still)}
    finally:
        ctx.client.send("MotionCommand", Linear=0.0, Angular=0.0, Mode="Raw")
        ctx.control("Standby")


def check_estop(ctx: Context) -> Outcome:
    s = ctx.settings
    ctx.ensure_active()
    set_sent = False
    try:
        with ctx.driving(s.speed if s.motion else 0.0):
            if s.motion:
                require(ctx.wait_moving() is not None, "did not move on MotionCommand")
            t = ctx.control("EStopSet")
            set_sent = True
            stopped = ctx.expect_state(
                lambda v: v["RobotState"] == EMERGENCY_STOP and v["EStop"] == 1, t)
            require(stopped is not None, "EStopSet: no EmergencyStop with EStop 1 "
                    f"(RobotState {ctx.state_name(ctx.state())})")
            assert stopped is not None
            require(ctx.client.expect("StatusCode",
                                      lambda v: v["Code"] & StatusBit.ESTOP_COMMAND, since=t,
                                      timeout=s.reply_timeout),
                    "EStopSet: StatusCode ESTOP_COMMAND not set")
            if s.motion:
                still = ctx.wait_still(t, timeout=1.5)
                require(still is not None, "EStopSet: still moving after 1.5 s while "
                        "MotionCommands keep coming")
            t_enable = ctx.control("EnableCanControl")
            time.sleep(0.5)
            states = {int(f.values["RobotState"])
                      for f in ctx.client.frames("SystemStatus", t_enable)}
            require(states == {EMERGENCY_STOP}, "EnableCanControl released the e-stop "
                    f"(RobotState {sorted(map(ctx.state_name, states))})")
            if s.motion:
                fastest = ctx.max_speed(t_enable + 0.1)
                require(fastest < STILL * s.speed,
                        f"moved at {fastest:.3f} m/s while e-stopped")
        t_release = ctx.control("EStopRelease")
        released = ctx.expect_state(
            lambda v: v["RobotState"] == STANDBY and v["EStop"] == 0, t_release)
        require(released is not None, "EStopRelease: no Standby with EStop 0 "
                f"(RobotState {ctx.state_name(ctx.state())})")
        set_sent = False
        code = ctx.status_code(since=time.monotonic())
        require(not code & (StatusBit.ESTOP_BUTTON | StatusBit.ESTOP_COMMAND),
                f"StatusCode {code:#x} still has an e-stop bit after EStopRelease")
        return passed(f"stopped in {stopped.t - t:.2f} s, latched against EnableCanControl, "
                      "released to Standby", estop_s=round(stopped.t - t, 3))
    finally:
        if set_sent:
            ctx.control("EStopRelease")
        ctx.control("Standby")


def check_standby(ctx: Context) -> Outcome:
    ctx.ensure_active()
    t = ctx.control("Standby")
    got = ctx.expect_state(lambda v: v["RobotState"] == STANDBY and v["ControlMode"] == 0, t)
    require(got is not None, "ControlCommand Standby: no Standby with ControlMode None")
    assert got is not None
    return passed(f"Standby after {got.t - t:.2f} s", standby_s=round(got.t - t, 3))
