"""The lowerbase command: help everywhere, the catalog, decoding, one-line errors."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import can
import pytest

from lowerbase.cli import SUBCOMMANDS, build_parser, main
from lowerbase.cli.decode import decode_stream, parse_candump_line
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.docs import render
from lowerbase.protocol.status_codes import render as render_status

ROOT = Path(__file__).resolve().parents[2]


def test_help_for_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    names = [a for a in parser._subparsers._group_actions[0].choices]  # type: ignore[union-attr]
    assert {"emulate", "dbc", "decode", "bms"} <= set(names) <= set(SUBCOMMANDS)
    for name in names:
        with pytest.raises(SystemExit) as info:
            main([name, "--help"])
        assert info.value.code == 0
        assert "usage: lowerbase" in capsys.readouterr().out


def test_python_dash_m_entry_point() -> None:
    out = subprocess.run([sys.executable, "-m", "lowerbase", "--version"], capture_output=True,
                         text=True, check=True).stdout
    assert out.startswith("lowerbase ")


def test_generated_docs_are_current() -> None:
    assert (ROOT / "docs" / "protocol.md").read_text(encoding="utf-8") == render()
    assert (ROOT / "docs" / "status-codes.md").read_text(encoding="utf-8") == render_status()
    assert main(["dbc", "--check-docs", str(ROOT / "docs" / "protocol.md")]) == 0


def test_dbc_lists_the_catalog(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc", "--signals"]) == 0
    out = capsys.readouterr().out
    for m in default_codec():
        assert m.name in out


def test_candump_formats() -> None:
    assert parse_candump_line("(1.5) vcan0 020#F40106FF3100") == (
        1.5, 0x20, bytes.fromhex("F40106FF3100"))
    assert parse_candump_line("  vcan0  100   [2]  01 02") == (None, 0x100, b"\x01\x02")
    assert parse_candump_line("vcan0 7FF#") == (None, 0x7FF, b"")
    assert parse_candump_line("not a frame") is None


def test_decode_counts_unknown_and_malformed() -> None:
    codec = default_codec()
    good = codec.encode("MotionCommand", {"Linear": 0.5, "Angular": -0.25, "Mode": "Smoothed",
                                          "Counter": 3})
    lines = [f"(1.0) vcan0 020#{good.hex()}", "(2.0) vcan0 7AB#0102", "(3.0) vcan0 020#F401",
             "garbage"]
    text = "\n".join(lines) + "\n"
    from lowerbase.cli.decode import _frames_from_text

    out = io.StringIO()
    counts = decode_stream(_frames_from_text(io.StringIO(text)), raw=False, only=None, out=out)
    assert counts == {"frames": 3, "decoded": 1, "unknown_id": 1, "not_catalog": 0,
                      "malformed": 1, "unparsed_lines": 1, "corrupt": 0}
    assert "MotionCommand" in out.getvalue() and "Mode=Smoothed" in out.getvalue()


def test_decode_reads_python_can_log_files(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    codec = default_codec()
    msg = codec.message("Heartbeat")
    data = msg.encode({"Uptime": 12.5, "BootCounter": 3, "Counter": 1,
                       "ProtocolVersion": 1, "Overruns": 0})
    for suffix in (".log", ".asc", ".blf"):
        path = tmp_path / f"run{suffix}"
        with can.Logger(str(path)) as writer:
            writer.on_message_received(can.Message(timestamp=1.0, arbitration_id=msg.frame_id,
                                                    data=data, is_extended_id=False))
        assert main(["decode", str(path)]) == 0
        assert "BootCounter=3" in capsys.readouterr().out


def test_errors_are_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["decode", str(tmp_path / "missing.log")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"lowerbase decode: error: no such file: {tmp_path / 'missing.log'}"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[chassis]\nwheel_perimeter = -1\n")
    assert main(["emulate", "--profile", str(bad), "--simulated", "--duration", "0.1",
                 "-i", "virtual", "-c", "cli-test"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "chassis.wheel_perimeter" in err[0]
