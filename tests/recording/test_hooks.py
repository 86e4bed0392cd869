"""`lowerbase scenario run` writes run.mcap (or --mcap FILE, or none with --no-mcap) that
agrees with the run's trace; `lowerbase record FILE.mcap` writes frames and decoded signals."""

from __future__ import annotations

import json
from pathlib import Path

import can
import numpy as np
import pytest
from mcap.reader import make_reader

from lowerbase.cli import main
from lowerbase.cli.record import McapFrames
from lowerbase.cli.scenario import execute
from lowerbase.protocol.codec import default_codec
from lowerbase.recording.ros1_types import ros1_types
from lowerbase.scenarios.wheeled import load_scenario

SCENARIO = """
[scenario]
name = "mcap-drive"
duration = 4.0
[[timeline]]
at = 1.0
action = "twist"
linear = 0.5
angular = 0.3
duration = 2.0
"""


def topics(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    with path.open("rb") as f:
        for _, c, m in make_reader(f).iter_messages():
            out.setdefault(c.topic, []).append((m.log_time, m.data))
    return out


def test_scenario_mcap_agrees_with_the_trace(tmp_path: Path) -> None:
    src = tmp_path / "s.toml"
    src.write_text(SCENARIO)
    result, _ = execute(load_scenario(src), tmp_path / "report")
    got = topics(tmp_path / "report" / "run.mcap")
    types = ros1_types()
    odom = [(t / 1e9, types.deserialize(d, "nav_msgs/Odometry")) for t, d in got["/odom"]]
    truth = [(t / 1e9, types.deserialize(d, "nav_msgs/Odometry"))
             for t, d in got["/ground_truth/odom"]]
    trace = result.trace
    times = [t for t, _ in odom]
    checked = 0
    for i in np.flatnonzero(np.isfinite(trace["ekf_x"])):
        s = float(trace["t"][i])
        k = int(np.searchsorted(times, s - 1e-9)) - 1  # the last /odom before the sample
        if k < 0:
            continue
        p = odom[k][1].pose.pose.position
        assert (p.x, p.y) == (trace["ekf_x"][i], trace["ekf_y"][i]), s
        checked += 1
    assert checked > 40 and trace["ekf_x"][-1] > 0.5
    assert len(truth) == len(odom)  # values: test_mcap_writer, against mcu.truth


def test_scenario_run_cli_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "s.toml"
    src.write_text(SCENARIO.replace("4.0", "1.5"))
    assert main(["scenario", "run", str(src), "--out", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "run.mcap").is_file()
    assert f"mcap: {tmp_path / 'a' / 'run.mcap'}" in capsys.readouterr().out
    assert main(["scenario", "run", str(src), "--out", str(tmp_path / "b"), "--mcap",
                 str(tmp_path / "other.mcap")]) == 0
    assert (tmp_path / "other.mcap").is_file() and not (tmp_path / "b" / "run.mcap").exists()
    assert main(["scenario", "run", str(src), "--out", str(tmp_path / "c"), "--no-mcap"]) == 0
    assert not (tmp_path / "c" / "run.mcap").exists()
    capsys.readouterr()
    assert main(["scenario", "run", str(src), "--out", str(tmp_path / "d"), "--mcap",
                 str(tmp_path / "x.bag")]) == 1
    assert "must end in .mcap" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_record_mcap_writer(tmp_path: Path) -> None:
    codec = default_codec()
    hb = codec.message("Heartbeat")
    data = hb.encode({"Uptime": 12.5, "BootCounter": 3, "Counter": 1,
                      "ProtocolVersion": 1, "Overruns": 0})
    path = tmp_path / "live.mcap"
    writer = McapFrames(path)
    writer.on_message_received(can.Message(timestamp=1700000000.25, arbitration_id=hb.frame_id,
                                           data=data, is_extended_id=False))
    writer.on_message_received(can.Message(timestamp=1700000000.5, arbitration_id=0x7F0,
                                           data=b"\x01\x02", is_extended_id=False))
    writer.stop()
    got = topics(path)
    frames = [ros1_types().deserialize(d, "can_msgs/Frame") for _, d in got["/can/frames"]]
    assert [f.id for f in frames] == [hb.frame_id, 0x7F0]
    assert bytes(frames[1].data[:frames[1].dlc]) == b"\x01\x02"
    assert got["/can/frames"][0][0] == 1_700_000_000_250_000_000
    assert [json.loads(d) for _, d in got["/can/decoded/Heartbeat"]] == [hb.decode(data)]
    assert set(got) == {"/can/frames", "/can/decoded/Heartbeat"}  # 0x7F0: raw only


def test_record_cli_writes_mcap(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    assert main(["record", str(path), "--duration", "0.2", "-i", "virtual",
                 "-c", "record-mcap-test"]) == 0
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 0  # a valid, finished, empty recording
