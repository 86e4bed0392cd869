"""The Foxglove layout (lowerbase/recording/foxglove-layout.json, package data): valid JSON,
every panel placed, and every topic and message path it names is a channel a run publishes,
with fields its ROS1 type or decoded CAN message really has."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

from lowerbase.protocol.codec import default_codec
from lowerbase.recording.publisher import DECODED_PREFIX
from lowerbase.recording.ros1_types import ros1_types
from tests.recording.conftest import record_drive, record_tasks, record_world

RPY = {"roll", "pitch", "yaw"}


def _layout() -> dict[str, Any]:
    text = resources.files("lowerbase.recording").joinpath("foxglove-layout.json").read_text(
        encoding="utf-8")
    data = json.loads(text)
    assert isinstance(data, dict)
    return data


def _strings(node: Any) -> Iterator[str]:
    """Every string value and key that names a topic (starts with '/')."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key.startswith("/"):
                yield key
            yield from _strings(value)
    elif isinstance(node, list):
        for value in node:
            yield from _strings(value)
    elif isinstance(node, str) and node.startswith("/"):
        yield node


def _panels(tree: Any) -> Iterator[str]:
    if isinstance(tree, str):
        yield tree
    else:
        assert tree["direction"] in ("row", "column")
        yield from _panels(tree["first"])
        yield from _panels(tree["second"])


@pytest.fixture(scope="module")
def published(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """topic -> ROS1 type or 'json', of a real recorded drive, a world run and a task run."""
    from mcap.reader import make_reader

    out: dict[str, str] = {}
    for name, record in (("run", record_drive), ("world", record_world),
                         ("tasks", record_tasks)):
        path = Path(tmp_path_factory.mktemp("layout")) / f"{name}.mcap"
        record(path)
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None
        out.update({ch.topic: (summary.schemas[ch.schema_id].name
                               if ch.message_encoding == "ros1" else "json")
                    for ch in summary.channels.values()})
    return out


def _check_ros1(type_name: str, fields: list[str], path: str) -> None:
    store = ros1_types().store
    current = type_name.replace("/", "/msg/") if "/msg/" not in type_name else type_name
    rest = list(fields)
    while rest:
        name = rest.pop(0)
        if name == "@rpy":
            assert current == "geometry_msgs/msg/Quaternion", f"{path}: @rpy of {current}"
            assert len(rest) == 1 and rest[0] in RPY, path
            return
        if name.startswith("@"):
            continue  # a value modifier (@degrees, ...)
        defs = dict(store.fielddefs[current][1])
        assert name in defs, f"{path}: {current} has no field {name!r}"
        kind, detail = defs[name]
        if kind.name == "NAME":
            current = detail
        else:
            assert not rest, f"{path}: {name} is a {detail}, not a message"


def test_layout_panels_and_topics(published: dict[str, str]) -> None:
    layout = _layout()
    configs = layout["configById"]
    placed = list(_panels(layout["layout"]))
    assert sorted(placed) == sorted(configs)  # every panel configured is shown, and back
    kinds = {p.split("!")[0] for p in placed}
    assert {"3D", "Plot", "StateTransitions", "RawMessages"} <= kinds
    codec = default_codec()
    named = set()
    for text in _strings(configs):
        topic = max((t for t in published if text == t or text.startswith(t + ".")),
                    key=len, default=None)
        assert topic is not None, f"layout names {text!r}: no such channel in a run"
        named.add(topic)
        fields = re.split(r"\.", text[len(topic) + 1:]) if text != topic else []
        if published[topic] == "json":
            signals = {s.name for s in codec.message(topic[len(DECODED_PREFIX):]).signals}
            assert len(fields) <= 1 and set(fields) <= signals, text
        else:
            _check_ros1(published[topic], fields, text)
    # what the panels are for: odometry against the truth, battery, status bits
    assert {"/odom", "/ground_truth/odom", "/battery", "/status_code",
            DECODED_PREFIX + "SystemStatus"} <= named
    # and the world: the map, the scan, the estimate against the true pose, in frame map
    assert {"/map", "/scan", "/amcl_pose", "/ground_truth/pose"} <= named
    assert configs["3D!map"]["followTf"] == "base_link"
    assert configs["3D!map"]["transforms"]["frame:map"]["visible"]
    # and the tasks: robot_status as state bands and raw, the navigator's plan on the map
    assert {"/robot_status", "/move_base/NavfnROS/plan"} <= named
    bands = {p["value"] for p in configs["StateTransitions!tasks"]["paths"]}
    assert {"/robot_status.task_state", "/robot_status.robot_state"} <= bands
    assert configs["RawMessages!robot_status"]["topicPath"] == "/robot_status"
    assert configs["3D!map"]["topics"]["/move_base/NavfnROS/plan"]["visible"]


def test_checker_refuses_what_a_run_does_not_publish(published: dict[str, str]) -> None:
    """The field walk above fails on a wrong field (it is not vacuous)."""
    with pytest.raises(AssertionError, match="no field"):
        _check_ros1(published["/odom"], ["pose", "pose", "positon", "x"], "/odom.typo")
    with pytest.raises(AssertionError):
        _check_ros1(published["/battery"], ["batteryPercentage", "@rpy", "yaw"], "/battery")
    with pytest.raises(AssertionError, match="no field"):
        _check_ros1(published["/robot_status"], ["state"], "/robot_status.state")
