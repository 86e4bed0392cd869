"""The legged robot's behaviour checks: the locomotion state table, the MIT special frames
and test mode, standing, walking, the BodyVelocityCommand timeout, and robustness.

They run in order and bring the robot along the table: COMM_DISABLED, COMM_ENABLED,
MOTOR_READY, MOTOR_ENABLED (via MOTOR_COMMUTATION), IN_TEST_MODE and back, STANDING_MODE,
IN_CONTROL, SITDOWN_MODE, MOTOR_DISABLED, COMM_DISABLED. A check that finds the robot in
the wrong state fails; the next checks request their own starting state again.
"""

from __future__ import annotations

import itertools
from statistics import fmean

from lowerbase.conformance.catalog import protocol_version
from lowerbase.conformance.core import Outcome, failed, passed, require
from lowerbase.conformance.legged_context import SETTLE, LeggedContext
from lowerbase.legged.body import ALLOWED
from lowerbase.protocol.legged import (
    BODY_BUS,
    COMMAND_MESSAGES,
    LEGS,
    N_BUSES,
    LocomotionState,
    RequestResult,
    Special,
    parse_special,
    special_frame,
)

S = LocomotionState
ACCEPTED = int(RequestResult.ACCEPTED)
QUIET = 0.1  #: [s] a window without actuator traffic that counts as silence (100 periods)


def _name(state: int) -> str:
    return S(state).name if 0 <= state <= 9 else str(state)


def check_link(ctx: LeggedContext) -> Outcome:
    hb = ctx.codec.message("Heartbeat")
    ctx.linked = ctx.wait_until(lambda: bool(ctx.body_frames(hb)), ctx.settings.link_timeout)
    if not ctx.linked:
        heard = " (other frames were heard)" if ctx.link.heard_anything() else ""
        return failed(f"no Heartbeat on bus 0 in {ctx.settings.link_timeout:g} s{heard}")
    values = hb.decode(ctx.body_frames(hb)[-1].data, strict=False)
    want = protocol_version(ctx.codec)
    require(int(values["ProtocolVersion"]) == want,
            f"ProtocolVersion {values['ProtocolVersion']}, the catalog's is {want}")
    return passed(f"Heartbeat, ProtocolVersion {want}, BootCounter {values['BootCounter']}")


def _traffic(ctx: LeggedContext, seconds: float) -> dict[str, int]:
    """Frames of the actuator traffic by kind over ``seconds``."""
    with ctx.capturing():
        start = ctx.now()
        ctx.wait(seconds)
        end = ctx.now()
        ctx.link.flush(end)
        out = {"commands": 0, "replies": 0}
        for b in range(N_BUSES):
            out["commands"] += sum(len(ctx.commands_of(b, m, start, end))
                                   for m in COMMAND_MESSAGES)
            out["replies"] += len(ctx.replies_of(b, None, start, end))
    return out


def _require_quiet_comm_disabled(ctx: LeggedContext) -> None:
    """COMM_DISABLED reached, and after SETTLE no actuator command or reply for QUIET."""
    state = ctx.go_to(S.COMM_DISABLED)
    require(state == S.COMM_DISABLED, f"could not reach COMM_DISABLED (in {_name(state)})")
    ctx.wait(SETTLE)
    seen = _traffic(ctx, QUIET)
    require(not any(seen.values()), f"COMM_DISABLED, but {seen['commands']} actuator commands "
            f"and {seen['replies']} replies in {QUIET:g} s", **seen)


def check_start(ctx: LeggedContext) -> Outcome:
    _require_quiet_comm_disabled(ctx)
    return passed(f"COMM_DISABLED, no actuator traffic for {QUIET:g} s")


def check_not_allowed(ctx: LeggedContext) -> Outcome:
    start = ctx.state()
    require(start == S.COMM_DISABLED, f"in {_name(start)}, not COMM_DISABLED")
    refused = sorted(set(S) - ALLOWED[S.COMM_DISABLED] - {S.COMM_DISABLED})
    wrong = []
    for want in refused:
        got = ctx.request(want)
        if int(got["RequestResult"]) != RequestResult.NOT_ALLOWED or \
                int(got["LastRequest"]) != want or int(got["State"]) != start:
            wrong.append(f"{want.name}: {ctx.result_name(got)} -> {_name(int(got['State']))}")
            ctx.go_to(S.COMM_DISABLED)
    require(not wrong, "not refused as NotAllowed: " + "; ".join(wrong))
    return passed(f"{len(refused)} requests from COMM_DISABLED refused NotAllowed")


def _accept(ctx: LeggedContext, want: S, then: S | None = None) -> None:
    got = ctx.request(want)
    require(int(got["RequestResult"]) == ACCEPTED and int(got["LastRequest"]) == want,
            f"request {want.name}: {ctx.result_name(got)} (LastRequest {got['LastRequest']})")
    target = then or want
    reached = ctx.wait_state(lambda s: s == target, ctx.settings.transition_timeout)
    require(reached is not None, f"request {want.name} accepted, but no {target.name} within "
            f"{ctx.settings.transition_timeout:g} s (in {_name(ctx.state())})")


def _gains(ctx: LeggedContext, frames: list[tuple[int, bytes]]) -> list[float]:
    """Kp, Kd and Torque of command frames beyond one step of their encoding (0 Nm is
    between two steps of the 12-bit torque)."""
    out = []
    for m, d in frames:
        msg = ctx.commands[m]
        values = msg.decode(d, strict=False)
        out += [float(values[k]) for k in ("Kp", "Kd", "Torque")
                if abs(float(values[k])) > msg.signal(k).scale]
    return out


def check_comm_enabled(ctx: LeggedContext) -> Outcome:
    _accept(ctx, S.COMM_ENABLED)
    with ctx.capturing():
        ctx.wait(SETTLE)
        start = ctx.now()
        ctx.wait(QUIET)
        missing, frames = [], []
        for b in range(N_BUSES):
            for m in COMMAND_MESSAGES:
                got = ctx.commands_of(b, m, start)
                if not got:
                    missing.append(f"{LEGS[b]} {m}")
                frames += [(m, f.data) for f in got if parse_special(f.data) is None]
    require(not missing, f"COMM_ENABLED, but no command to {', '.join(missing)}")
    gains = _gains(ctx, frames)
    if gains:
        return failed("outside motor mode the commands carry gains or torque (largest "
                      f"{max(map(abs, gains)):.3g})")
    return passed(f"COMM_ENABLED; {len(frames)} commands in {QUIET:g} s, zero gains")


def check_motor_ready(ctx: LeggedContext) -> Outcome:
    _accept(ctx, S.MOTOR_READY)
    return passed("MOTOR_READY")


def _specials(ctx: LeggedContext, kind: Special, since: float) -> tuple[list[str], int]:
    """(joints without exactly one ``kind`` frame answered by one reply, frames seen)."""
    bad, seen = [], 0
    for b in range(N_BUSES):
        replies = ctx.replies_of(b, None, since)
        for m in COMMAND_MESSAGES:
            got = [f for f in ctx.commands_of(b, m, since) if parse_special(f.data) is kind]
            seen += len(got)
            answered = [f for f in got if any(r.t >= f.t and r.data[:1] == bytes((m,))
                                              for r in replies)]
            if len(got) != 1 or len(answered) != 1:
                bad.append(f"{LEGS[b]} {m}: {len(got)} sent, {len(answered)} answered")
    return bad, seen


def check_motor_enabled(ctx: LeggedContext) -> Outcome:
    with ctx.capturing():
        start = ctx.now()
        got = ctx.request(S.MOTOR_ENABLED)
        require(int(got["RequestResult"]) == ACCEPTED, f"request MOTOR_ENABLED from "
                f"MOTOR_READY: {ctx.result_name(got)}")
        via = int(got["State"]) == S.MOTOR_COMMUTATION or any(
            int(v["State"]) == S.MOTOR_COMMUTATION for _, v in
            ctx.decoded("LocomotionStatus", start))
        reached = ctx.wait_state(lambda s: s == S.MOTOR_ENABLED,
                                 ctx.settings.transition_timeout)
        ctx.shared["enter"] = _specials(ctx, Special.ENTER_MOTOR_MODE, start)
    require(via, "MOTOR_ENABLED not reached through MOTOR_COMMUTATION")
    require(reached is not None, f"no MOTOR_ENABLED within {ctx.settings.transition_timeout:g}"
            f" s (in {_name(ctx.state())})")
    assert reached is not None
    return passed(f"MOTOR_COMMUTATION, MOTOR_ENABLED after {reached[0] - start:.2f} s")


def check_enter_motor_mode(ctx: LeggedContext) -> Outcome:
    require("enter" in ctx.shared, "no MOTOR_COMMUTATION seen (see locomotion.motor_enabled)")
    bad, seen = ctx.shared["enter"]
    require(not bad, "enter-motor-mode: " + "; ".join(bad), frames=seen)
    return passed("one enter-motor-mode frame to each of the 12 actuators, each answered")


def check_reply_per_command(ctx: LeggedContext) -> Outcome:
    from lowerbase.conformance.legged_frames import observation

    obs = observation(ctx)
    bad, total = [], 0
    for b in range(N_BUSES):
        replies = obs.frames.get((b, 0), [])
        for m in COMMAND_MESSAGES:
            n_cmd = len(obs.frames.get((b, m), []))
            n_rep = sum(r.data[:1] == bytes((m,)) for r in replies)
            total += n_cmd
            if abs(n_cmd - n_rep) > 2:  # a pair may be cut at either edge of the window
                bad.append(f"{LEGS[b]} {m}: {n_cmd} commands, {n_rep} replies")
    require(total > 0, "no actuator commands in the observation window")
    require(not bad, "not one reply per command: " + "; ".join(bad))
    return passed(f"{total} commands, each answered by its actuator", commands=total)


def _upper_command(ctx: LeggedContext, bus: int, motor_id: int) -> bytes:
    """A harmless command (zero gains and torque at the joint's last reported position)."""
    reply = ctx.replies_of(bus, motor_id)
    p = float(ctx.reply.decode(reply[-1].data, strict=False)[
        f"{('Hip', 'Thigh', 'Calf')[motor_id - 1]}Position"]) if reply else 0.0
    return ctx.commands[motor_id].encode({"Position": p, "Velocity": 0.0, "Kp": 0.0,
                                          "Kd": 0.0, "Torque": 0.0})


def _answered(ctx: LeggedContext, bus: int, motor_id: int, data: bytes) -> float | None:
    """Send ``data`` to an actuator; the delay of its reply, or None."""
    t = ctx.now()
    ctx.link.send(bus, motor_id, data)
    ok = ctx.wait_until(lambda: bool(ctx.replies_of(bus, motor_id, t)),
                        ctx.settings.reply_timeout)
    return ctx.replies_of(bus, motor_id, t)[0].t - t if ok else None


def check_test_mode(ctx: LeggedContext) -> Outcome:
    with ctx.capturing():
        ctx.wait(QUIET)  # replies to read the joints' positions from
        _accept(ctx, S.IN_TEST_MODE)
        ctx.wait(SETTLE)
        seen = _traffic(ctx, QUIET)
        require(seen["commands"] == 0, f"IN_TEST_MODE, but the body controller sent "
                f"{seen['commands']} commands in {QUIET:g} s")
        delays, late = [], []
        for b in range(N_BUSES):
            for m in COMMAND_MESSAGES:
                d = _answered(ctx, b, m, _upper_command(ctx, b, m))
                if d is None:
                    late.append(f"{LEGS[b]} {m}")
                else:
                    delays.append(d)
        for kind in (Special.EXIT_MOTOR_MODE, Special.ENTER_MOTOR_MODE):
            if _answered(ctx, 0, 2, special_frame(kind)) is None:
                late.append(f"{kind.name} to {LEGS[0]} 2")
    require(not late, f"IN_TEST_MODE: no reply within {ctx.settings.reply_timeout:g} s to "
            + ", ".join(late))
    _accept(ctx, S.MOTOR_ENABLED)
    return passed(f"silent body controller; 12 upper commands and 2 special frames "
                  f"answered (largest delay {max(delays) * 1e3:.1f} ms); back to MOTOR_ENABLED",
                  max_delay_ms=round(max(delays) * 1e3, 3))


def check_zero_position(ctx: LeggedContext) -> Outcome:
    from lowerbase.conformance.core import CheckSkipped

    if not ctx.settings.zero_position:
        raise CheckSkipped("re-zeroes FR hip: only with --zero-position")
    _accept(ctx, S.IN_TEST_MODE)
    with ctx.capturing():
        ok = _answered(ctx, 0, 1, special_frame(Special.ZERO_POSITION))
        reply = ctx.replies_of(0, 1)
    _accept(ctx, S.MOTOR_ENABLED)
    require(ok is not None and reply, "zero-position: no reply")
    p = float(ctx.reply.decode(reply[-1].data, strict=False)["HipPosition"])
    lsb = ctx.reply.signal("HipPosition").scale
    require(abs(p) <= 2 * lsb, f"after zero-position FR hip reports {p:.4f} rad, not 0")
    return passed(f"FR hip reports {p:.5f} rad after zero-position")


def check_refused(ctx: LeggedContext) -> Outcome:
    require(ctx.state() == S.MOTOR_ENABLED, f"in {_name(ctx.state())}, not MOTOR_ENABLED")
    bus, m, n = 1, 1, 5
    with ctx.capturing():
        ctx.wait(QUIET)
        start = ctx.now()
        data = _upper_command(ctx, bus, m)
        for _ in range(n):
            ctx.link.send(bus, m, data)
            ctx.wait(0.01)
        ctx.wait(QUIET)
        end = ctx.now()
        ctx.link.flush(end)
        n_cmd = len(ctx.commands_of(bus, m, start, end))
        n_rep = len(ctx.replies_of(bus, m, start, end))
    require(abs(n_rep - n_cmd) <= 2, f"{n} upper {COMMAND_MESSAGES[m]}s in MOTOR_ENABLED: "
            f"{n_rep} replies to {n_cmd} body commands (extra answers: obeyed)",
            replies=n_rep, commands=n_cmd)
    return passed(f"{n} upper commands ignored: {n_rep} replies to {n_cmd} body commands")


def _z(ctx: LeggedContext) -> float:
    got = ctx.decoded("BasePosition", ctx.now() - 0.1)
    require(got, "no BasePosition")
    return float(got[-1][1]["Z"])


def check_stand(ctx: LeggedContext) -> Outcome:
    ctx.skip_without_motion()
    z0 = ctx.shared["z_lying"] = _z(ctx)
    got = ctx.request(S.STANDING_MODE)
    require(int(got["RequestResult"]) == ACCEPTED, f"request STANDING_MODE: "
            f"{ctx.result_name(got)}")
    busy = ctx.request(S.IN_CONTROL)
    require(int(busy["RequestResult"]) == RequestResult.BUSY, "IN_CONTROL while standing "
            f"up: {ctx.result_name(busy)}, not Busy")
    ok = ctx.wait_until(lambda: int(ctx.request(S.IN_CONTROL)["RequestResult"]) == ACCEPTED,
                        ctx.settings.transition_timeout)
    require(ok, f"IN_CONTROL not accepted within {ctx.settings.transition_timeout:g} s")
    z = _z(ctx)
    require(z > z0 + 0.05, f"standing: BasePosition Z {z:.3f} m, lying {z0:.3f} m")
    return passed(f"stood up (Z {z0:.3f} -> {z:.3f} m, Busy meanwhile), IN_CONTROL")


def _walk(ctx: LeggedContext, seconds: float, vx: float) -> float:
    """BodyVelocityCommand every 20 ms for ``seconds``; returns the last send time."""
    msg = ctx.codec.message("BodyVelocityCommand")
    period = msg.cycle_time or 0.02
    t, end, counter = ctx.now(), ctx.now() + seconds, 0
    while ctx.now() < end:
        t = ctx.now()
        ctx.link.send(BODY_BUS, msg.frame_id, msg.encode(
            {"Vx": vx, "Vy": 0.0, "YawRate": 0.0, "Counter": counter}))
        counter = (counter + 1) % 16
        ctx.wait(period)
    return t


def check_velocity(ctx: LeggedContext) -> Outcome:
    ctx.skip_without_motion()
    require(ctx.state() == S.IN_CONTROL, f"in {_name(ctx.state())}, not IN_CONTROL")
    v = ctx.settings.speed
    start = ctx.now()
    last = _walk(ctx, 2.0, v)
    ctx.shared["last_command"] = last
    vel = [float(s["Vx"]) for _, s in ctx.decoded("BaseVelocity", start + 1.0, last)]
    pos = [s for _, s in ctx.decoded("BasePosition", start + 1.0, last)]
    require(len(vel) >= 10 and len(pos) >= 10, "too few BaseVelocity/BasePosition frames")
    mean = fmean(vel)
    require(abs(mean - v) <= 0.05 * v + 0.002, f"BaseVelocity Vx {mean:.3f} m/s, commanded "
            f"{v:g}", vx=round(mean, 4))
    # the window's duration on the firmware's time base: BasePosition cycles from its counter
    cycle = ctx.codec.message("BasePosition").cycle_time or 0.02
    steps = sum((int(b["Counter"]) - int(a["Counter"]) - 1) % 16 + 1
                for a, b in itertools.pairwise(pos))
    dx = float(pos[-1]["X"]) - float(pos[0]["X"])
    integral = mean * steps * cycle
    require(abs(dx - integral) <= 0.05 * abs(integral) + 0.003, f"BasePosition X moved "
            f"{dx:.3f} m, BaseVelocity integrates to {integral:.3f} m", dx=dx)
    return passed(f"Vx {mean:.3f} m/s (commanded {v:g}); X +{dx:.3f} m = integral "
                  f"{integral:.3f} m", vx=round(mean, 4), dx=round(dx, 4))


def _stall(vel: list[tuple[float, float]], until: float, cycle: float) -> float:
    """[s] the longest silence of BaseVelocity beyond its cycle from the last command
    (time 0) to ``until``: a stall of the sending or the receiving host."""
    seen = [0.0] + [dt for dt, _ in vel if dt <= until]
    return max(0.0, max((b - a for a, b in itertools.pairwise(seen)), default=0.0) - cycle)


def check_velocity_timeout(ctx: LeggedContext) -> Outcome:
    ctx.skip_without_motion()
    if "last_command" not in ctx.shared:
        return failed("no walk (see body.velocity)")
    last = float(ctx.shared["last_command"])
    s = ctx.settings
    base = s.command_timeout + 0.5 + s.jitter
    cycle = ctx.codec.message("BaseVelocity").cycle_time or 0.02
    # a host stall (BaseVelocity silent for longer than its cycle before the stop) is measured
    # and allowed, not guessed: a chassis that keeps streaming and does not stop in time fails
    stall, vel, stopped = 0.0, [], []
    for _ in range(4):  # wait again only while the measured stall grows
        ctx.wait(max(0.0, last + base + stall + 0.2 - ctx.now()))
        vel = [(t - last, abs(float(v["Vx"]))) for t, v in ctx.decoded("BaseVelocity", last)]
        stopped = [dt for dt, x in vel if x < 0.1 * s.speed]
        grown = _stall(vel, stopped[0] if stopped else base + stall, cycle)
        if grown <= stall + 1e-9:
            break
        stall = grown
    limit = base + stall
    early = [dt for dt, x in vel if dt < s.command_timeout - s.jitter and x < 0.9 * s.speed]
    require(not early, f"slowed {early[0]:.2f} s after the last command (timeout "
            f"{s.command_timeout:g} s)" if early else "")
    require(stopped and stopped[0] <= limit, f"not below {0.1 * s.speed:.3f} m/s within "
            f"{limit:.2f} s of the last BodyVelocityCommand (latest |Vx| "
            f"{vel[-1][1] if vel else float('nan'):.3f} m/s)", stall_s=round(stall, 3))
    state = ctx.state()
    require(state == S.IN_CONTROL, f"after the timeout in {_name(state)}, not IN_CONTROL")
    held = f", a {stall:.2f} s stall of the frames allowed" if stall > 0.0 else ""
    return passed(f"stopped {stopped[0]:.2f} s after the last command (limit {limit:.2f} s"
                  f"{held}), still IN_CONTROL", stop_s=round(stopped[0], 3))


def check_sit(ctx: LeggedContext) -> Outcome:
    ctx.skip_without_motion()
    _accept(ctx, S.STANDING_MODE)
    got = ctx.request(S.SITDOWN_MODE)
    require(int(got["RequestResult"]) == ACCEPTED, f"SITDOWN_MODE: {ctx.result_name(got)}")
    busy = ctx.request(S.STANDING_MODE)
    require(int(busy["RequestResult"]) == RequestResult.BUSY, "STANDING_MODE while sitting "
            f"down: {ctx.result_name(busy)}, not Busy")
    seated = ctx.wait_state(lambda st: st == S.MOTOR_ENABLED, ctx.settings.transition_timeout)
    require(seated is not None, "not back in MOTOR_ENABLED after sitting down")
    z, z0 = _z(ctx), ctx.shared.get("z_lying", 0.0)
    require(abs(z - z0) <= 0.02, f"seated at Z {z:.3f} m, lying was {z0:.3f} m")
    return passed(f"sat down (Busy meanwhile) to Z {z:.3f} m, MOTOR_ENABLED")


def check_exit_motor_mode(ctx: LeggedContext) -> Outcome:
    with ctx.capturing():
        start = ctx.now()
        _accept(ctx, S.MOTOR_DISABLED)
        ctx.wait(QUIET)
        bad, seen = _specials(ctx, Special.EXIT_MOTOR_MODE, start)
    require(not bad, "exit-motor-mode: " + "; ".join(bad), frames=seen)
    return passed("MOTOR_DISABLED: one exit-motor-mode frame to each actuator, each answered")


def check_stop(ctx: LeggedContext) -> Outcome:
    _require_quiet_comm_disabled(ctx)
    return passed("COMM_DISABLED: the actuator traffic stopped")
