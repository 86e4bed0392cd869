"""`lowerbase record`'s live frame count: in place on a terminal, silent otherwise."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import pytest

from lowerbase.cli import main
from lowerbase.cli.record import LiveCount


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_count_is_rewritten_in_place_at_most_twice_a_second() -> None:
    out, clock = Terminal(), Clock()
    live = LiveCount(out, Path("run.blf"), clock=clock)
    for count in range(1, 41):  # 8 frames/s for 5 s, one update per frame
        clock.now += 0.125
        live.update(count)
    live.done()
    text = out.getvalue()
    assert text.count("\rrecording: ") == 10  # every 0.5 s, not every frame
    assert "recording: 1 frame(s)" in text and "recording: 37 frame(s), 8/s -> run.blf" in text
    assert "\n" not in text and text.endswith("\r\x1b[K")  # erased for the final line


def test_nothing_is_written_when_not_a_terminal() -> None:
    out = io.StringIO()
    live = LiveCount(out, Path("run.blf"))
    live.update(5)
    live.done()
    assert out.getvalue() == ""


@pytest.mark.parametrize("tty", [True, False])
def test_record_shows_the_count_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch,
                                                   tmp_path: Path, tty: bool) -> None:
    err = Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    path = tmp_path / "run.log"
    assert main(["record", str(path), "--duration", "0.3", "-i", "virtual",
                 "-c", "record-live-test"]) == 0
    text = err.getvalue()
    assert text.rstrip("\n").endswith(f"lowerbase record: 0 frame(s) written to {path}")
    assert ("\rrecording: 0 frame(s)" in text) is tty
    if not tty:
        assert "\r" not in text and len(text.splitlines()) == 2
