"""`lowerbase record`'s live frame count: in place on a terminal, silent otherwise."""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path
from typing import Any

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


SETUP = 0.9  #: [s] of the fake clock that opening the file's writer takes


@pytest.mark.parametrize("suffix", [".mcap", ".log", ".blf"])
def test_duration_counts_from_when_frames_start_to_be_recorded(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, suffix: str) -> None:
    """`record --duration D` ends D after the bus opened (from then frames queue for the
    file), however long the file's writer takes to set up (the MCAP writer's imports took 4-7 s
    on a loaded host and the recording then held 14-17 s for 10); the frames that queued
    meanwhile are recorded. The writer's set-up is made to take SETUP = 0.9 s of a fake clock
    more than it really does: a recording counted from after the set-up would stop 1 s after the
    writer was ready or later, one counted from the bus stops 1 s after the bus opened (0.1 s
    after the writer was ready at the latest) plus however late the host wakes the loop; the
    real time the set-up took is on both sides. The time is taken when the recording stops,
    before the file is closed."""
    import types

    import can

    from lowerbase import transport
    from lowerbase.cli import record

    offset = [0.0]
    fake_time = types.SimpleNamespace(monotonic=lambda: time.monotonic() + offset[0],
                                      time=time.time)
    monkeypatch.setattr(record, "time", fake_time)
    channel = f"record-duration-{suffix[1:]}"
    real_open_writer = record.open_writer

    def slow_open_writer(path: Path) -> Any:
        writer = real_open_writer(path)
        with can.Bus(interface="virtual", channel=channel) as peer:  # queued while setting up
            for i in range(3):
                peer.send(can.Message(arbitration_id=0x90, data=bytes([i] * 8),
                                      is_extended_id=False))
        offset[0] += SETUP
        ready.append(fake_time.monotonic())
        real_stop = writer.stop

        def stop() -> None:
            stopped.append(fake_time.monotonic())
            real_stop()

        writer.stop = stop
        return writer

    opened: list[float] = []
    stopped: list[float] = []
    ready: list[float] = []  # when the writer was set up (the real time it took included)
    real_open_bus = transport.open_bus

    def open_bus(config: Any) -> Any:
        bus = real_open_bus(config)
        opened.append(fake_time.monotonic())
        return bus

    monkeypatch.setattr(record, "open_writer", slow_open_writer)
    monkeypatch.setattr(transport, "open_bus", open_bus)
    path = tmp_path / f"run{suffix}"
    assert main(["record", str(path), "--duration", "1", "-i", "virtual", "-c", channel]) == 0
    elapsed = stopped[0] - opened[0]  # from the bus open to the end of the recording
    assert elapsed >= 1.0, f"recorded for {elapsed:.2f} s of --duration 1"
    # counted from after the set-up it would stop 1 s after the writer was ready, at least
    assert stopped[0] < ready[0] + 1.0, f"stopped {stopped[0] - ready[0]:.2f} s after the set-up"
    if suffix == ".mcap":
        from mcap.reader import make_reader

        with path.open("rb") as f:
            topics = [ch.topic for _, ch, _ in make_reader(f).iter_messages()]
        assert topics.count("/can/frames") == 3
    else:
        with can.LogReader(str(path)) as reader:
            assert [bytes(m.data) for m in reader] == [bytes([i] * 8) for i in range(3)]


def test_the_end_of_a_recording_writes_what_queued_before_it_and_nothing_after() -> None:
    import can

    from lowerbase.cli.record import drain

    now = time.time()
    queued = [can.Message(arbitration_id=0x90, data=bytes([i]), timestamp=now - 0.5 + i * 0.1)
              for i in range(3)]
    later = can.Message(arbitration_id=0x90, data=b"\x09", timestamp=now + 60.0)
    inbox = [*queued, later, *queued]

    class Bus:
        def recv(self, timeout: float) -> can.Message | None:
            assert timeout == 0.0  # draining never waits
            return inbox.pop(0) if inbox else None

    written: list[can.Message] = []
    assert drain(Bus(), lambda m: written.append(m) or 1) == 3
    assert written == queued  # the frame received after the end stopped it, unwritten
