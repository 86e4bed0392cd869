"""`lowerbase decode`: values at their resolution, named StatusCode bits, python-can's printer
format, multiplexed frames, and bad files reported where they are bad, never a traceback."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import can
import pytest

from lowerbase.cli import main
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.status_codes import StatusBit

CODEC = default_codec()


def _message(name: str, values: dict[str, object], t: float = 1.0,
             **flags: bool) -> can.Message:
    msg = CODEC.message(name)
    return can.Message(timestamp=t, arbitration_id=msg.frame_id, data=msg.encode(values),
                       is_extended_id=False, channel="vcan0", **flags)


def _heartbeat(t: float) -> can.Message:
    return _message("Heartbeat", {"Uptime": t, "BootCounter": 3, "Counter": 1,
                                  "ProtocolVersion": 1, "Overruns": 0}, t)


def _decode_stdin(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                  text: str, *args: str) -> tuple[int, str, str]:
    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    code = main(["decode", *args])
    out, err = capsys.readouterr()
    return code, out, err


def _write(path: Path, messages: list[can.Message]) -> Path:
    with can.Logger(str(path)) as writer:
        for m in messages:
            writer.on_message_received(m)
    return path


def test_values_are_printed_at_their_signal_resolution(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    lines = [f"(1.0) vcan0 {m.arbitration_id:03X}#{m.data.hex()}" for m in (
        _message("Odometer", {"Distance": 4108734.457, "Counter": 2}),
        _message("WheelFeedback", {"Wheel": "Left", "LeftCount": -123456, "LeftVelocity": 0.5,
                                   "LeftCurrent": 1.25, "LeftDriverStatus": 0, "Counter": 1}),
    )]
    code, out, _ = _decode_stdin(monkeypatch, capsys, "\n".join(lines) + "\n")
    assert code == 0
    assert "Distance=4108734.457 m" in out  # 0.001 m: 3 decimals, not 4.10873e+06
    assert "LeftVelocity=0.500 m/s" in out and "LeftCurrent=1.25 A" in out
    assert "LeftCount=-123456 pulses" in out


def test_multiplexed_frames_show_only_the_active_signals(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    m = _message("WheelFeedback", {"Wheel": "Right", "RightCount": 7, "RightVelocity": -0.25,
                                   "RightCurrent": 0.5, "RightDriverStatus": 0, "Counter": 1})
    _, out, _ = _decode_stdin(monkeypatch, capsys, f"vcan0 100#{m.data.hex()}\n")
    assert "Wheel=Right" in out and "RightVelocity=-0.250 m/s" in out
    assert "Left" not in out.replace("Wheel=Right", "")


def test_status_code_bits_are_named(monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    code = int(StatusBit.ESTOP_BUTTON | StatusBit.LEFT_MOTOR_STALLED)
    m = _message("StatusCode", {"Code": code})
    _, out, _ = _decode_stdin(monkeypatch, capsys, f"vcan0 080#{m.data.hex()}\n")
    assert f"Code=0x{code:X}[ESTOP_BUTTON,LEFT_MOTOR_STALLED]" in out
    _, raw, _ = _decode_stdin(monkeypatch, capsys, f"vcan0 080#{m.data.hex()}\n", "--raw")
    assert f"Code={code}\n" in raw


def test_python_can_printer_format_on_stdin_and_in_txt_files(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    messages = [_heartbeat(12.5), _heartbeat(13.0)]
    text = "".join(f"{m}\n" for m in messages)  # what `python -m can.logger` prints
    code, out, err = _decode_stdin(monkeypatch, capsys, text)
    assert code == 0 and out.count("BootCounter=3") == 2 and "Uptime=12.500 s" in out
    assert "unparsed" not in err
    _write(tmp_path / "run.txt", messages)  # can.Logger's .txt is the same printer
    assert main(["decode", str(tmp_path / "run.txt")]) == 0
    assert capsys.readouterr().out.count("BootCounter=3") == 2


def test_extended_and_remote_frames_are_not_taken_for_catalog_frames(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    hb = _heartbeat(1.0)
    text = (f"(1.0) vcan0 00000090#{hb.data.hex()}\n(2.0) vcan0 090#R\n"
            f"{can.Message(timestamp=3, arbitration_id=0x90, data=hb.data)}\n")
    code, out, err = _decode_stdin(monkeypatch, capsys, text)
    assert code == 0 and "BootCounter" not in out
    assert out.count("extended frame, not in the catalog") == 2
    assert "remote frame" in out and "3 not catalog" in err


def test_a_malformed_log_line_is_reported_with_file_and_line_and_skipped(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = _write(tmp_path / "run.log", [_heartbeat(1.0), _heartbeat(2.0)])
    good = path.read_text().splitlines()
    path.write_text("\n".join([good[0], "(1.5) vcan0 090#ZZ", good[1]]) + "\n")
    assert main(["decode", str(path)]) == 0
    out, err = capsys.readouterr()
    assert out.count("BootCounter=3") == 2
    assert f"{path}:2: not a frame" in err and "Traceback" not in err


def test_a_corrupt_blf_reports_where_and_exits_1(capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path) -> None:
    path = _write(tmp_path / "run.blf", [_heartbeat(float(t)) for t in range(2000)])
    raw = path.read_bytes()
    half = len(raw) // 2
    path.write_bytes(raw[:half] + bytes(b ^ 0x5A for b in raw[half:half + 64])
                     + raw[half + 64:])
    assert main(["decode", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"lowerbase decode: error: {path}: after frame" in err and "corrupt file" in err
    assert "Traceback" not in err


def test_a_truncated_blf_reports_where_and_exits_1(capsys: pytest.CaptureFixture[str],
                                                   tmp_path: Path) -> None:
    path = _write(tmp_path / "run.blf", [_heartbeat(float(t)) for t in range(2000)])
    raw = path.read_bytes()
    path.write_bytes(raw[:len(raw) // 2])
    assert main(["decode", str(path)]) == 1
    out, err = capsys.readouterr()
    assert "BootCounter=3" in out  # what could be read is shown
    assert "truncated" in err and str(path) in err


def test_a_corrupt_csv_reports_the_frame_it_stopped_after(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = _write(tmp_path / "run.csv", [_heartbeat(1.0), _heartbeat(2.0)])
    path.write_text(path.read_text() + "garbage\n")
    assert main(["decode", str(path)]) == 1
    out, err = capsys.readouterr()
    assert out.count("BootCounter=3") == 2
    assert f"{path}: after frame 2" in err and "Traceback" not in err


def test_a_file_python_can_cannot_open_is_one_line(capsys: pytest.CaptureFixture[str],
                                                   tmp_path: Path) -> None:
    path = tmp_path / "run.blf"
    path.write_bytes(b"not a blf file at all")
    assert main(["decode", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"lowerbase decode: error: cannot read {path}")
