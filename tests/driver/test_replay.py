"""Replaying a recording that starts after the driver's parameter exchange (issue 9 item 18)."""

from __future__ import annotations

import threading
from pathlib import Path

import can
import pytest

from lowerbase.clock import SimClock
from lowerbase.driver.core import DriverCore, LinkState
from lowerbase.driver.links import ReplayLink
from lowerbase.firmware_model.profile import load_profile
from lowerbase.protocol.codec import default_codec
from lowerbase.simloop.loop import SimLoop

PARAMETERS = load_profile().chassis.as_wire_dict()


def record(path: Path, start: float) -> None:
    """A run (2 s standing, 2 s at 0.5 m/s), recorded from ``start`` [s] of the run on."""
    with can.Logger(str(path)) as logger:
        def tap(t: float, side: str, frame_id: int, data: bytes) -> None:
            if t >= start:
                logger.on_message_received(can.Message(
                    timestamp=1000.0 + t, arbitration_id=frame_id, data=data,
                    is_extended_id=False, is_rx=side == "lower"))

        loop = SimLoop(tap=tap)
        loop.run(2.0)
        loop.drive(0.5, 0.0, 2.0)
        assert loop.driver.state == LinkState.READY  # the recorded driver was configured


def replay(link: ReplayLink, clock: SimClock) -> DriverCore:
    core = DriverCore(link.send, clock)

    def on_frame(frame_id: int, data: bytes) -> None:
        core.on_frame(frame_id, data)
        core.tick()

    link.run_reader(on_frame, threading.Event())
    return core


@pytest.fixture(scope="module")
def late(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "late.log"
    record(path, start=1.5)  # the exchange is over after about 0.1 s
    return path


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "whole.log"
    record(path, start=0.0)
    return path


def test_a_late_recording_is_named_and_the_way_out_offered(late: Path) -> None:
    clock = SimClock()
    link = ReplayLink(late, clock=clock)
    assert not link.has_parameter_exchange and not link.answering
    assert link.advice is not None
    assert "starts after the driver's parameter exchange" in link.advice
    assert "--replay-profile" in link.advice and "--replay-param" in link.advice
    core = replay(link, clock)
    assert core.state == LinkState.CONFIGURING  # what the advice warns about
    assert core.odometry is None


def test_a_late_recording_replays_with_given_parameters(late: Path) -> None:
    clock = SimClock()
    link = ReplayLink(late, parameters=PARAMETERS, clock=clock)
    assert link.answering and link.advice is not None and "answered" in link.advice
    core = replay(link, clock)
    assert link.answered == len(PARAMETERS)  # each read once, as the lower computer would
    assert core.state == LinkState.READY
    assert core.parameters == pytest.approx(PARAMETERS, rel=1e-6)  # float32 on the wire
    assert core.odometry is not None
    assert 0.7 < core.odometry.x < 1.1  # most of the 1 m driven after the first Heartbeat


def test_a_whole_recording_uses_its_own_parameters(whole: Path) -> None:
    clock = SimClock()
    wrong = {**PARAMETERS, "wheelPerimeter": 2 * PARAMETERS["wheelPerimeter"]}
    link = ReplayLink(whole, parameters=wrong, clock=clock)
    assert link.has_parameter_exchange and not link.answering
    assert link.advice is not None and "ignored" in link.advice
    core = replay(link, clock)
    assert link.answered == 0
    assert core.state == LinkState.READY
    assert core.parameters["wheelPerimeter"] == pytest.approx(PARAMETERS["wheelPerimeter"])
    assert core.odometry is not None and 0.8 < core.odometry.x < 1.1
    assert ReplayLink(whole).advice is None  # nothing to say about an ordinary recording


# -- lowerbase driver --replay FILE --replay-profile/--replay-param --------------------------


@pytest.mark.parametrize(("argv", "says"), [
    (["--replay-param", "wheelPerimeter=0.7"], "go with --replay FILE"),
    (["REPLAY", "--replay-param", "wheelPerimeter"], "expected NAME=VALUE"),
    (["REPLAY", "--replay-param", "wheelPerimeter=fast"], "expected NAME=VALUE"),
    (["REPLAY", "--replay-param", "wheelSize=0.7"], "unknown chassis parameter"),
    (["REPLAY", "--replay-param", "wheelPerimeter=-1"], "wheel_perimeter"),
    (["REPLAY", "--replay-profile", "missing.toml"], "missing.toml"),
])
def test_cli_replay_parameters_errors_are_one_line(
        argv: list[str], says: str, late: Path, capsys: pytest.CaptureFixture[str],
        woosh_msgs: object) -> None:
    from lowerbase.cli import main

    argv = ["--replay", str(late), *argv[1:]] if argv[0] == "REPLAY" else argv
    assert main(["driver", *argv]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("lowerbase driver: error: ") and "\n" not in err
    assert says in err


def _run_cli(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> ReplayLink:
    from lowerbase.cli import main
    from lowerbase.driver import node

    links: list[ReplayLink] = []

    def fake_run(link_factory: object, ros_args: object) -> int:  # no rospy needed
        links.append(link_factory(lambda: None))  # type: ignore[operator]
        return 0

    monkeypatch.setattr(node, "run", fake_run)
    assert main(["driver", *argv]) == 0
    return links[0]


def test_cli_says_when_a_recording_starts_late_and_replays_it_with_parameters(
        late: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        woosh_msgs: object) -> None:
    link = _run_cli(["--replay", str(late)], monkeypatch)
    err = capsys.readouterr().err
    assert "lowerbase driver: late.log starts after the driver's parameter exchange" in err
    assert "--replay-profile FILE" in err and not link.answering

    link = _run_cli(["--replay", str(late), "--replay-profile", "default",
                     "--replay-param", "wheelPerimeter=0.7"], monkeypatch)
    assert "answered with the given parameters" in capsys.readouterr().err
    assert link.answering and link.finished is not None
    assert link.parameters == {**PARAMETERS, "wheelPerimeter": 0.7}


# -- bad files: read as `lowerbase decode` reads them -----------------------------------------


def _heartbeats(path: Path, n: int) -> Path:
    """``n`` Heartbeats, all stamped at one instant (a replay of them does not wait)."""
    hb = default_codec().message("Heartbeat")
    with can.Logger(str(path)) as logger:
        for k in range(n):
            logger.on_message_received(can.Message(
                timestamp=1000.0, arbitration_id=hb.frame_id, is_extended_id=False,
                data=hb.encode({"Uptime": float(k), "BootCounter": 3, "Counter": k & 0xF,
                                "ProtocolVersion": 1, "Overruns": 0})))
    return path


def test_a_log_with_a_non_utf8_line_skips_that_line_only(whole: Path, tmp_path: Path) -> None:
    lines = whole.read_bytes().splitlines(keepends=True)
    bad = tmp_path / "bad.log"
    bad.write_bytes(b"".join(lines[:50]) + b"(1000.5) vcan0 \xff\xfe#00\n" + b"".join(lines[50:]))
    clock = SimClock()
    link = ReplayLink(bad, clock=clock)
    assert link.scan_error is None and link.has_parameter_exchange
    core = replay(link, clock)
    assert link.skipped_lines == 1 and link.error is None
    clean_clock = SimClock()
    clean = ReplayLink(whole, clock=clean_clock)
    replay(clean, clean_clock)
    assert link.frames == clean.frames > 1000
    assert core.state == LinkState.READY


def corrupt(path: Path) -> Path:
    raw = path.read_bytes()
    half = len(raw) // 2
    path.write_bytes(raw[:half] + bytes(b ^ 0x5A for b in raw[half:half + 64])
                     + raw[half + 64:])
    return path


def truncate(path: Path) -> Path:
    path.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])
    return path


@pytest.mark.parametrize("spoil, says", [(corrupt, "corrupt file"), (truncate, "truncated")])
def test_a_bad_blf_is_named_not_mistaken_for_a_late_recording_and_stops_with_an_error(
        spoil: object, says: str, tmp_path: Path) -> None:
    path = spoil(_heartbeats(tmp_path / "run.blf", 2000))  # type: ignore[operator]
    clock = SimClock()
    link = ReplayLink(path, clock=clock)
    assert link.advice is not None and says in link.advice
    assert "parameter exchange" not in link.advice  # that is not what is wrong with it
    replay(link, clock)
    assert link.error is not None and says in link.error and "after frame" in link.error
    assert link.frames < 2000  # what comes before the damage (a whole BLF container)


def _run_cli_to_the_end(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> int:
    from lowerbase.cli import main
    from lowerbase.driver import node

    def fake_run(link_factory: object, ros_args: object) -> int:  # the reader, no rospy
        link = link_factory(lambda: None)  # type: ignore[operator]
        link.clock = SimClock()
        link.run_reader(lambda frame_id, data: None, threading.Event())
        return 0

    monkeypatch.setattr(node, "run", fake_run)
    return main(["driver", *argv])


@pytest.mark.parametrize("spoil, says", [(corrupt, "corrupt file"), (truncate, "truncated")])
def test_cli_exits_non_zero_on_a_bad_blf(
        spoil: object, says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, woosh_msgs: object) -> None:
    path = spoil(_heartbeats(tmp_path / "run.blf", 2000))  # type: ignore[operator]
    assert _run_cli_to_the_end(["--replay", str(path)], monkeypatch) == 1
    err = capsys.readouterr().err
    assert "starts after the driver's parameter exchange" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"lowerbase driver: error: {path}: after frame") and says in last
    assert "Traceback" not in err


def test_cli_reports_skipped_lines_and_exits_0(
        whole: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, woosh_msgs: object) -> None:
    bad = tmp_path / "bad.log"
    bad.write_bytes(whole.read_bytes() + b"\xff not a frame\n")
    assert _run_cli_to_the_end(["--replay", str(bad)], monkeypatch) == 0
    assert "1 line(s) of bad.log were not frames" in capsys.readouterr().err
