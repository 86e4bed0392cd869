"""The tasks node, black-box, on the whole chain and a real rosmaster: `lowerbase emulate --map
empty_room --truth-udp`, `lowerbase driver`, `lowerbase world --ground-truth` (its /amcl_pose is
the emulator's true pose), `lowerbase navigation` and `lowerbase tasks`, each a process. A
user's rospy script that only knows the seed's interface (examples/transport_task.py: exec_task
and robot_status) runs a transport task end to end; refusals are checked with rospy's
ServiceProxy in a client process (tests/navigation/ros_client.py)."""

from __future__ import annotations

import itertools
import json
import math
import os
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from lowerbase.world.maps import load_map
from lowerbase.world.places import load_places
from tests.conftest import ROOT
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.navigation.ros_client import NavClient
from tests.ros_chain import nav_chain

EXEC = "woosh_msgs/ExecTask"
MARK = "R1"


@pytest.fixture(scope="module")
def chain(ros_master: Any, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
          ) -> Iterator[dict[str, Any]]:
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv"))
    tmp = tmp_path_factory.mktemp("tasks_node")
    env = ros_master.env
    topics = (("/amcl_pose", "geometry_msgs/PoseWithCovarianceStamped"),
              ("/robot_status", "woosh_msgs/RobotStatus"))
    with nav_chain(env, tmp, ["--map", "empty_room"], "239.74.163.97", topics,
                   tasks=["--unload-time", "2"]) as (chain, client):
        yield {"client": client, "tasks": chain.procs[-1], "env": env}


def truth(client: NavClient) -> tuple[float, float, float]:
    """The robot's true map pose from a fresh /amcl_pose (the world's --ground-truth)."""
    n = client.ask(op="last", topic="/amcl_pose")["count"]
    msg = client.wait_last("/amcl_pose", lambda m: client.ask(op="last", topic="/amcl_pose")
                           ["count"] > n + 1, 10.0, "a fresh /amcl_pose")
    p, q = msg["pose"]["pose"]["position"], msg["pose"]["pose"]["orientation"]
    return p["x"], p["y"], 2.0 * math.atan2(q["z"], q["w"])


@pytest.mark.ros
@pytest.mark.process
def test_a_users_script_runs_a_transport_task_to_the_mark(chain: dict[str, Any]) -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "transport_task.py"), "--mark", MARK,
         "--task-id", "7", "--direction", "2", "--timeout", "240"],
        capture_output=True, text=True, env={**os.environ, **chain["env"]}, timeout=300)
    assert out.returncode == 0, (out.stdout[-3000:], out.stderr[-3000:])
    lines = out.stdout.splitlines()
    answer = json.loads(next(x for x in lines if x.startswith("exec_task "))[10:])
    assert answer["success"] and "accepted" in answer["message"], answer
    seq = [json.loads(x[13:]) for x in lines if x.startswith("robot_status ")]
    mine = [(s["task_state"], s["action_type"], s["action_state"]) for s in seq
            if s["task_id"] == 7]
    # executing: navigation, then the timed unloading; then completed
    assert mine[0] == (3, 1, 1), mine
    assert (3, 5, 1) in mine and mine.index((3, 5, 1)) > 0, mine
    assert mine[-1] == (7, 5, 4), mine
    assert all(s["dest"] == MARK and s["task_type"] == 4 for s in seq if s["task_id"] == 7)
    assert seq[-1]["robot_state"] == 2  # idle again
    # published only on change: no two consecutive statuses equal but for time
    plain = [{k: v for k, v in s.items() if k != "time"} for s in seq]
    assert all(a != b for a, b in itertools.pairwise(plain))
    # the robot truly stands on the mark
    mark = load_places("empty_room", load_map("empty_room")).named()[MARK]
    x, y, yaw = truth(chain["client"])
    assert math.hypot(x - mark[0], y - mark[1]) < 0.15, (x, y, mark)
    assert abs(math.remainder(yaw - mark[2], math.tau)) < 0.15


@pytest.mark.ros
@pytest.mark.process
def test_refused_requests_say_why_and_change_nothing(chain: dict[str, Any]) -> None:
    client = chain["client"]
    before = client.ask(op="last", topic="/robot_status")
    for args, text in (
            ({"task_exect": 1, "task_id": 9, "task_type": 4, "mark_no": "nowhere"},
             "unknown mark_no 'nowhere'"),
            ({"task_exect": 1, "task_id": 0, "task_type": 2, "mark_no": MARK}, "task_id"),
            ({"task_exect": 2, "task_id": 9}, "no task is running"),
            ({"task_exect": 5, "task_id": 9}, "unknown task_exect 5"),
            ({"task_exect": 1, "task_id": 9, "task_type": 2,
              "poses": [{"header": {"frame_id": "odom"}}]}, "frame 'odom'"),
            ({"task_exect": 1, "task_id": 9, "task_type": 2,
              "poses": [{"header": {"frame_id": "map"}}]}, "unit quaternion")):
        res = client.ask(op="call", name="/exec_task", type=EXEC, args=args)
        assert res["success"] is False and text in res["message"], (args, res)
        assert res["statusCode"] == 2  # idle
    after = client.ask(op="last", topic="/robot_status")
    assert after["count"] == before["count"]  # nothing was published


@pytest.mark.ros
@pytest.mark.process
def test_pause_continue_and_cancel_over_ros(chain: dict[str, Any]) -> None:
    client = chain["client"]
    start = truth(client)
    res = client.ask(op="call", name="/exec_task", type=EXEC,
                     args={"task_exect": 1, "task_id": 11, "task_type": 2, "mark_no": "R2"})
    assert res["success"], res

    def status(cond: Any, what: str) -> Any:
        return client.wait_last("/robot_status", cond, 60.0, what)

    status(lambda m: m["task_id"] == 11 and m["robot_state"] == 3, "parking")
    client.wait_last("/amcl_pose", lambda m: math.hypot(
        m["pose"]["pose"]["position"]["x"] - start[0],
        m["pose"]["pose"]["position"]["y"] - start[1]) > 0.3, 60.0, "the robot on its way")
    res = client.ask(op="call", name="/exec_task", type=EXEC,
                     args={"task_exect": 2, "task_id": 11})
    assert res["success"], res
    status(lambda m: m["task_state"] == 4 and m["action_state"] == 10, "paused")
    # paused: the robot comes to a stop and stays
    a, b = truth(client), truth(client)
    for _ in range(100):
        if math.hypot(a[0] - b[0], a[1] - b[1]) < 0.002:
            break
        a, b = b, truth(client)
    for _ in range(5):
        b = truth(client)
    assert math.hypot(a[0] - b[0], a[1] - b[1]) < 0.01, (a, b)
    res = client.ask(op="call", name="/exec_task", type=EXEC,
                     args={"task_exect": 3, "task_id": 11})
    assert res["success"], res
    status(lambda m: m["task_state"] == 3, "executing again")
    res = client.ask(op="call", name="/exec_task", type=EXEC,
                     args={"task_exect": 4, "task_id": 11})
    assert res["success"] and res["statusCode"] == 2, res
    status(lambda m: m["task_id"] == 11 and m["task_state"] == 8, "cancelled")
