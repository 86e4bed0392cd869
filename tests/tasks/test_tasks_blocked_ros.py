""""path blocked" over ROS, black-box, on the whole chain and a real rosmaster (emulate, driver,
world --ground-truth, navigation and tasks, each a process, as tests/tasks/test_tasks_node_ros.py):
the navigation node shows its blocked path in the ACTIVE /move_base goal's status text
(/move_base/status, as move_base users read it), and the tasks node turns it into robot_status
WARNING "path blocked: ..." after blocked_delay, as TaskSim does (tests/tasks/test_blocked.py),
and back to executing once the path is free.

A crate the map does not know stands 3.3 m ahead of the robot (out of the costmaps' 2.5 m reach
when the path is planned, so the plan runs through it, as in the navigation node's mode-2 test).
In navigation mode 2 (stop and wait) the robot waits in front of it: blocked for as long as the
test likes, so nothing here depends on timing. Mode 1 then replans around it: free again."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest

from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.navigation.ros_client import NavClient
from tests.ros_chain import nav_chain, write_crate

EXEC = "woosh_msgs/ExecTask"
MODE = "woosh_msgs/NavigationModeAction"
START = (5.0, 2.5, math.pi / 2)  # facing the crate
CRATE = (5.0, 6.0)
GOAL = (5.0, 7.0, math.pi / 2)  # behind the crate (its faces at y 5.8 and 6.2)
#: the navigator's reason while it waits (lowerbase.navigation.navigator), as TaskSim shows it
BLOCKED_MSG = "path blocked: waiting: an obstacle blocks the path"
EXECUTING, COMPLETED = 3, 7  # task_state
A_EXECUTING, A_WARNING = 1, 2  # action_state
IDLE, PARKING, WARNING = 2, 3, 5  # robot_state


@pytest.fixture(scope="module")
def chain(ros_master: Any, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
          ) -> Iterator[dict[str, Any]]:
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv"))
    tmp = tmp_path_factory.mktemp("tasks_blocked")
    room = ["--map", "empty_room", "--obstacles", str(write_crate(tmp / "crate.toml", CRATE)),
            "--initial-pose", ",".join(str(v) for v in START)]
    topics = (("/robot_status", "woosh_msgs/RobotStatus"),
              ("/move_base/status", "actionlib_msgs/GoalStatusArray"))
    with nav_chain(ros_master.env, tmp, room, "239.74.163.99", topics, tasks=[]) as (_, client):
        yield {"client": client}


def set_mode(client: NavClient, goal: dict[str, Any]) -> None:
    client.ask(op="send", name="/navigation_mode", type=MODE, goal=goal)
    assert client.ask(op="result", name="/navigation_mode")["state"] == 3  # SUCCEEDED


def stamped(pose: tuple[float, float, float]) -> dict[str, Any]:
    return {"header": {"frame_id": "map"},
            "pose": {"position": {"x": pose[0], "y": pose[1]},
                     "orientation": {"z": math.sin(pose[2] / 2), "w": math.cos(pose[2] / 2)}}}


@pytest.mark.ros
@pytest.mark.process
def test_a_blocked_path_is_path_blocked_on_robot_status_and_clears(
        chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    set_mode(client, {"navigation_mode": 2})  # stop and wait in front of an obstacle
    res = client.ask(op="call", name="/exec_task", type=EXEC,
                     args={"task_exect": 1, "task_id": 21, "task_type": 2,
                           "poses": [stamped(GOAL)]})
    assert res["success"], res

    def status(cond: Any, what: str) -> Any:
        return client.wait_last("/robot_status", lambda m: m["task_id"] == 21 and cond(m),
                                120.0, what)

    status(lambda m: m["robot_state"] == PARKING, "parking")
    warned = status(lambda m: m["action_state"] == A_WARNING, "the path-blocked warning")
    assert (warned["task_state"], warned["action_state"], warned["robot_state"],
            warned["msg"]) == (EXECUTING, A_WARNING, WARNING, BLOCKED_MSG), warned
    # the channel: the ACTIVE goal's text in /move_base/status
    client.wait_last("/move_base/status", lambda m: any(
        s["status"] == 1 and s["text"] == BLOCKED_MSG for s in m["status_list"]), 30.0,
        "the blocked text in /move_base/status")
    # precise avoidance (permitted_passage: False in an unset message): replanned around it
    set_mode(client, {"navigation_mode": 1, "permitted_passage": True})
    free = status(lambda m: m["action_state"] != A_WARNING, "the warning cleared")
    assert free["task_state"] in (EXECUTING, COMPLETED), free
    if free["task_state"] == EXECUTING:
        assert (free["action_state"], free["robot_state"], free["msg"]) == (
            A_EXECUTING, PARKING, ""), free
    done = status(lambda m: m["task_state"] == COMPLETED, "the task completed")
    assert done["robot_state"] == IDLE, done
