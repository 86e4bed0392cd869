"""Folders and files a user names for output (``--out``, ``--log-dir``, ``--mcap``, ``--record``,
``--truth``, ``--junit``, ...): made when missing, and when they cannot be written, one line
saying so before anything runs (:mod:`lowerbase.files`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.files import output_dir, output_file

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGN = str(ROOT / "campaigns" / "wheel_tolerance.toml")


@pytest.fixture
def blocker(tmp_path: Path) -> Path:
    """A plain file where a folder would have to be."""
    path = tmp_path / "afile"
    path.write_text("in the way\n", encoding="utf-8")
    return path


def test_output_dir_is_checked_and_left_to_its_writer(tmp_path: Path) -> None:
    """Made to be checked, then removed again (a run that stops before it writes leaves no
    empty folder); with ``make``, kept."""
    assert output_dir(tmp_path / "a" / "b", "--out") == tmp_path / "a" / "b"
    assert not any(tmp_path.iterdir())
    made = output_dir(tmp_path / "a" / "b", "--log-dir", make=True)
    assert made.is_dir() and not any(made.iterdir())  # the scratch file is gone


def test_output_file_makes_its_folder_not_the_file(tmp_path: Path) -> None:
    file = output_file(tmp_path / "rec" / "run.mcap", "--mcap")
    assert file.parent.is_dir() and not file.exists() and not any(file.parent.iterdir())


@pytest.mark.parametrize(("call", "text"), [
    (lambda b: output_dir(b, "--out"), "--out {b}: a file, not a folder; give a folder"),
    (lambda b: output_dir(b / "sub", "--log-dir"),
     "--log-dir {b}/sub: a file is in the way of its folder; give a folder you can write to"),
    (lambda b: output_dir(b / "sub"), "{b}/sub: a file is in the way of its folder"),
    (lambda b: output_file(b.parent, "--mcap"), "--mcap {p}: a folder, not a file; give a file"),
    (lambda b: output_file(b / "x.log", "--record"),
     "--record {b}/x.log: a file is in the way of its folder; give a file in a folder you can "
     "write to"),
])
def test_unusable_outputs_are_one_line(blocker: Path, call: object, text: str) -> None:
    with pytest.raises(ConfigError) as info:
        call(blocker)  # type: ignore[operator]
    message = str(info.value)
    assert message.startswith(text.format(b=blocker, p=blocker.parent)), message
    assert "\n" not in message and "Errno" not in message


@pytest.mark.parametrize("argv", [
    ["scenario", "run", "loop", "--out", "{b}"],
    ["scenario", "run", "loop", "--out", "{b}/sub"],
    ["scenario", "run", "loop", "--mcap", "{b}/sub/run.mcap"],
    ["scenario", "run", "loop", "--record", "{b}/sub/run.log"],
    ["scenario", "replay", "{log}", "--out", "{b}/sub"],
    ["campaign", "run", CAMPAIGN, "--runs", "0-0", "--workers", "1", "--out", "{b}"],
    ["campaign", "replay", CAMPAIGN, "--run", "0", "--out", "{b}/sub"],
    ["demo", "--out", "{b}"],
    ["demo", "--fast", "--chassis", "--out", "{b}/sub"],
    ["robot", "--sim-time", "--log-dir", "{b}/sub"],
    ["robot", "--sim-time", "--mcap", "{b}/sub/r.mcap"],
    ["robot", "--sim-time", "--truth", "{b}/sub/t.csv"],
    ["emulate", "--simulated", "--duration", "1", "--truth", "{b}/sub/t.csv"],
    ["record", "{b}/sub/frames.log", "--duration", "1"],
    ["conformance", "--junit", "{b}/sub/junit.xml"],
    ["dbc", "--export-docs", "{b}/sub/protocol.md"],
    ["mcap", "recover", "{log}", "{b}/sub/out.mcap"],
])
def test_commands_refuse_unwritable_outputs_before_they_start(
        argv: list[str], blocker: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Each command stops in one line naming the option and its value, before it runs (no
    output of a run, no report folder, nothing started)."""
    log = tmp_path / "frames.log"
    log.write_text("", encoding="utf-8")
    args = [a.format(b=blocker, log=log) for a in argv]
    assert main(args) == 1
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"lowerbase {argv[0]}: error: "), lines
    assert str(blocker) in lines[0] and "Errno" not in lines[0], lines
    assert captured.out == "" and sorted(tmp_path.iterdir()) == sorted([blocker, log])
