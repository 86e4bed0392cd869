"""The navigation node's local costmap update (``update_rate_hz``, move_base's local
``update_frequency``): each update marks the newest scan /odom and TF have reached, as
costmap_2d's observation buffers with ``observation_keep_time`` 0; the scans before it since
the last update are dropped unread (a lazy one is never cast) and counted."""

from __future__ import annotations

from typing import Any

import pytest

from lowerbase.errors import ConfigError
from lowerbase.navigation import node
from lowerbase.world.lazy_scan import LazyScan
from lowerbase.world.maps import load_map
from lowerbase.world.stamped import PoseHistory, StampedSensors


class Navigator:
    def __init__(self) -> None:
        self.updates: list[list[Any]] = []

    def update_observations(self, items: list[Any]) -> None:
        self.updates.append(list(items))


def bare_node(setup: Any) -> Any:
    n = node.NavigationNode.__new__(node.NavigationNode)  # no ROS: only the update's parts
    history = PoseHistory()
    n.sensors = StampedSensors(history, lambda stamp: (0.0, 0.0, 0.0))
    n.navigator, n.stats = Navigator(), {"superseded": 0, "bad_scan": 0}
    n._update_every = max(1, round(setup.rate_hz / setup.update_rate_hz))
    return n, history


def test_an_update_marks_the_newest_scan_only_and_never_casts_the_others() -> None:
    setup = node.NavigationSetup(grid=load_map("empty_room"))
    n, history = bare_node(setup)
    assert n._update_every == 4  # 20 Hz ticks, 5 Hz updates
    def made(k: int) -> Any:
        return lambda: f"scan {k}"  # stands for the cast scan

    scans = [LazyScan("base_link", 0.04 * k, made(k)) for k in range(5)]
    for k, s in enumerate(scans):
        history.add(0.04 * k, (0.1 * k, 0.0, 0.0))
        n.sensors.add("scan", 0.04 * k, s)
    n._update_costmap()
    [[(pose, scan, cloud)]] = n.navigator.updates
    assert scan == "scan 4" and cloud is None and pose == pytest.approx((0.4, 0.0, 0.0))
    assert [s.cast for s in scans] == [False] * 4 + [True]
    assert n.stats["superseded"] == 4
    n._update_costmap()  # nothing new: an update with nothing to mark
    assert n.navigator.updates[-1] == []


def test_the_update_rate_is_checked() -> None:
    with pytest.raises(ConfigError, match="update_rate_hz"):
        node.NavigationSetup(grid=load_map("empty_room"), update_rate_hz=0.0)


def test_the_node_takes_move_bases_recovery_behaviors_parameter() -> None:
    from lowerbase.navigation.goals import NavigationError
    from lowerbase.navigation.navigator import Navigator

    setup = node.NavigationSetup(grid=load_map("empty_room"))
    params: dict[str, Any] = {}
    same = node.with_params(setup, lambda name, default: params.get(name, default))
    assert same is setup  # not set: move_base's defaults
    params["~recovery_behaviors"] = ["rotate", "clear_aggressive"]
    got = node.with_params(setup, lambda name, default: params.get(name, default))
    assert got.navigator.recovery_behaviors == ("rotate", "clear_aggressive")
    nav = Navigator(got.grid, got.navigator)
    assert nav.config.recovery_behaviors == ("rotate", "clear_aggressive")
    params["~recovery_behaviors"] = [{"name": "back_off", "type": "x/BackOff"}, "rotate"]
    got = node.with_params(setup, lambda name, default: params.get(name, default))
    assert got.navigator.recovery_behaviors == ("back_off", "rotate")
    for bad, why in (("rotate", "must be a list"), (["spin"], "unknown 'spin'"), ([], "non-empty")):
        params["~recovery_behaviors"] = bad
        with pytest.raises(NavigationError, match=why):
            node.with_params(setup, lambda name, default: params.get(name, default))


def test_the_lockstep_robot_reads_recovery_behaviors_where_move_base_has_them() -> None:
    """`lowerbase robot` is one node; its navigation reads /move_base/recovery_behaviors."""
    from lowerbase.robot.lockstep import move_base_params

    server: dict[str, Any] = {"/move_base/recovery_behaviors": ["back_off", "rotate"],
                              "/lowerbase_robot/recovery_behaviors": ["clear_aggressive"]}

    class Side:
        def param(self, name: str, default: Any = None) -> Any:
            return server.get(name, default)

    setup = node.NavigationSetup(grid=load_map("empty_room"))
    got = node.with_params(setup, move_base_params(Side()))
    assert got.navigator is not None and got.navigator.recovery_behaviors == ("back_off",
                                                                              "rotate")
    server.clear()
    assert node.with_params(setup, move_base_params(Side())) is setup
