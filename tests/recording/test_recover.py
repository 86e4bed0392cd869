"""``lowerbase mcap recover``: a recording cut short (a recorder killed before its footer)
becomes a whole MCAP file with every message that was written in a finished chunk."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from lowerbase.errors import ConfigError
from lowerbase.recording.convert import mcap_summary, recover_mcap
from tests.conftest import ROOT


def _record(path: Path, messages: int) -> None:
    from mcap.writer import Writer

    with path.open("wb") as f:
        w = Writer(f, chunk_size=4096)
        w.start(profile="ros1", library="test")
        schema = w.register_schema("std_msgs/String", "ros1msg", b"string data")
        channels = [w.register_channel(t, "ros1", schema) for t in ("/a", "/b")]
        for i in range(messages):
            data = f"message {i:05d}".encode()
            w.add_message(channels[i % 2], i * 1_000_000, len(data).to_bytes(4, "little")
                          + data, i * 1_000_000)
        w.finish()


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        return [(c.topic, m.log_time, m.data)
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def test_a_file_cut_before_its_footer_is_recovered_up_to_its_last_whole_chunk(
        tmp_path: Path) -> None:
    whole, cut, out = tmp_path / "whole.mcap", tmp_path / "cut.mcap", tmp_path / "out.mcap"
    _record(whole, 2000)
    data = whole.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.7)])  # killed: no summary, no footer
    with pytest.raises(ConfigError):
        mcap_summary(cut)
    done = recover_mcap(cut, out)
    assert done.damage
    got = _messages(out)
    expected = _messages(whole)
    assert 0.5 * len(expected) < len(got) < len(expected)
    assert got == expected[: len(got)]  # the same messages, in order, none made up
    assert done.messages == len(got) and set(done.topics) == {"/a", "/b"}
    assert mcap_summary(out)[0].startswith(f"{out}: {len(got)} message(s)")


def test_a_whole_file_is_copied_whole_and_the_command_says_so(tmp_path: Path) -> None:
    whole, out = tmp_path / "whole.mcap", tmp_path / "out.mcap"
    _record(whole, 100)
    run = subprocess.run([sys.executable, "-m", "lowerbase", "mcap", "recover", str(whole),
                          str(out)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "100 message(s) on 2 topic(s)" in run.stdout and "the file was whole" in run.stdout
    assert _messages(out) == _messages(whole)


def test_not_an_mcap_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    run = subprocess.run([sys.executable, "-m", "lowerbase", "mcap", "recover", str(bad),
                          str(tmp_path / "out.mcap")], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    lines = [x for x in (run.stdout + run.stderr).splitlines() if x.strip()]
    assert run.returncode != 0 and not (tmp_path / "out.mcap").exists()
    assert len(lines) == 1 and "is it an MCAP file?" in lines[0], run.stderr
