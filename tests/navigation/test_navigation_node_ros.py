"""The navigation node, black-box, on the whole chain: a real rosmaster, `lowerbase emulate
--map empty_room --truth-udp`, `lowerbase driver`, `lowerbase world --ground-truth` and
`lowerbase navigation`, each in a process of its own; actionlib's SimpleActionClient and rospy's
ServiceProxy in a client process (tests/navigation/ros_client.py). The emulator's truth comes
back through the world (with --ground-truth its /amcl_pose is the true pose)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from lowerbase.world.footprint import DEFAULT_POINTS
from lowerbase.world.maps import load_map
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401
from tests.navigation.ros_client import NavClient
from tests.ros_chain import nav_chain, write_crate

START = (5.0, 4.0, 0.0)  # empty_room's place "start"
BOX = (5.0, 6.0)  # a crate the map does not know, 2 m left of the robot
SUCCEEDED, ABORTED, PREEMPTED = 3, 4, 2  # actionlib_msgs/GoalStatus
GLOBAL = "/move_base/global_costmap/costmap"
LOCAL = "/move_base/local_costmap/costmap"
STEP = "woosh_msgs/StepControlAction"
MOVE = "woosh_msgs/MoveBaseAction"


@pytest.fixture(scope="module")
def chain(ros_master: Any, tmp_path_factory: pytest.TempPathFactory  # noqa: F811
          ) -> Iterator[dict[str, Any]]:
    require_ros(("rospy", "actionlib", "tf2_ros", "nav_msgs.srv", "std_srvs.srv"))
    tmp = tmp_path_factory.mktemp("navigation_node")
    room = ["--map", "empty_room", "--obstacles", str(write_crate(tmp / "crate.toml", BOX))]
    topics = ((GLOBAL, "nav_msgs/OccupancyGrid"), (LOCAL, "nav_msgs/OccupancyGrid"),
              ("/amcl_pose", "geometry_msgs/PoseWithCovarianceStamped"),
              ("/odom", "nav_msgs/Odometry"))
    with nav_chain(ros_master.env, tmp, room, "239.74.163.98", topics) as (chain, client):
        yield {"client": client, "nav": chain.procs[-1]}


def truth(client: NavClient) -> tuple[float, float, float]:
    """The robot's true map pose from a fresh /amcl_pose (the world's --ground-truth)."""
    n = client.ask(op="last", topic="/amcl_pose")["count"]
    msg = client.wait_last("/amcl_pose", lambda m: client.ask(op="last", topic="/amcl_pose")
                           ["count"] > n + 1, 10.0, "a fresh /amcl_pose")
    p, q = msg["pose"]["pose"]["position"], msg["pose"]["pose"]["orientation"]
    return p["x"], p["y"], 2.0 * math.atan2(q["z"], q["w"])


def odom_xy(client: NavClient) -> tuple[float, float]:
    """The latest /odom position (to tell odometry error from control error)."""
    p = client.wait_last("/odom", lambda m: True, 10.0, "/odom")["pose"]["pose"]["position"]
    return p["x"], p["y"]


def pose_msg(x: float, y: float, yaw: float) -> dict[str, Any]:
    return {"header": {"frame_id": "map"},
            "pose": {"position": {"x": x, "y": y},
                     "orientation": {"z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}}


def path_xy(reply: dict[str, Any]) -> np.ndarray:
    return np.asarray([(p["pose"]["position"]["x"], p["pose"]["position"]["y"])
                       for p in reply["plan"]["poses"]]).reshape(-1, 2)


def make_plan(client: NavClient, start: Any, goal: Any, tolerance: float) -> dict[str, Any]:
    reply: dict[str, Any] = client.ask(op="call", name="/move_base/make_plan",
                                       type="nav_msgs/GetPlan",
                                       args={"start": pose_msg(*start), "goal": pose_msg(*goal),
                                             "tolerance": tolerance})
    return reply


@pytest.mark.ros
@pytest.mark.process
def test_make_plan_in_the_map_frame_with_tolerance(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    reply = make_plan(client, START, (7.5, 2.5, 0.5), 0.0)
    assert reply["plan"]["header"]["frame_id"] == "map"
    xy = path_xy(reply)
    assert len(xy) > 10
    assert np.hypot(*(xy[0] - START[:2])) < 1e-3 and np.hypot(*(xy[-1] - (7.5, 2.5))) < 1e-3
    last = reply["plan"]["poses"][-1]["pose"]["orientation"]
    assert 2.0 * math.atan2(last["z"], last["w"]) == pytest.approx(0.5, abs=1e-6)
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert steps.max() < 0.08  # resampled every cell
    # a goal in the east wall: no path without tolerance, the nearest free cell with it
    wall = (9.9, 4.0, 0.0)
    assert make_plan(client, START, wall, 0.0)["plan"]["poses"] == []
    xy = path_xy(make_plan(client, START, wall, 1.0))
    assert 0 < np.hypot(*(xy[-1] - wall[:2])) <= 1.0
    # a NaN goal: an empty plan, the node goes on
    assert make_plan(client, START, (math.nan, 1.0, 0.0), 0.0)["plan"]["poses"] == []
    assert chain["nav"].popen.poll() is None


def _inscribed_cells(points: Any, padding: float) -> tuple[np.ndarray, np.ndarray]:
    """The cells the global costmap marks INSCRIBED or LETHAL (99/100) for a footprint, from
    the map file: within the padded footprint's inscribed radius of an occupied cell (a
    regular octagon-ish polygon around base_link: its inscribed radius is the nearest edge)."""
    from lowerbase.navigation.layers import footprint_radii
    from lowerbase.world.footprint import Footprint

    grid = load_map("empty_room")
    inscribed, _ = footprint_radii(Footprint(tuple(points)).padded(padding))
    d = distance_transform_edt(grid.data != 100) * grid.resolution
    return d <= inscribed + 1e-9, np.abs(d - inscribed) < 1e-6


@pytest.mark.ros
@pytest.mark.process
def test_set_footprint_topics_change_the_global_costmap(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    grid = load_map("empty_room")

    def marked(msg: dict[str, Any]) -> np.ndarray:
        info = msg["info"]
        assert (info["width"], info["height"]) == (grid.width, grid.height)
        assert msg["header"]["frame_id"] == "map"
        return np.asarray(msg["data"], np.int8).reshape(grid.height, grid.width) >= 99

    expected, edge = _inscribed_cells(DEFAULT_POINTS, 0.1)
    msg = client.wait_last(GLOBAL, lambda m: True, 20.0, "the global costmap")
    assert np.array_equal(marked(msg)[~edge], expected[~edge])
    bigger = [(1.5 * x, 1.5 * y) for x, y in DEFAULT_POINTS]
    polygon = {"points": [{"x": x, "y": y, "z": 0.0} for x, y in bigger]}
    client.ask(op="pub", topic="/move_base/global_costmap/set_footprint",
               type="geometry_msgs/Polygon", msg=polygon)
    expected_big, edge_big = _inscribed_cells(bigger, 0.1)
    assert expected_big.sum() > expected.sum()
    # waited for by its content: a costmap sampled before the change may still be the latest
    client.wait_last(GLOBAL, lambda m: np.array_equal(marked(m)[~edge_big],
                                                      expected_big[~edge_big]),
                     20.0, "the global costmap inflated by the bigger footprint")
    # the planner keeps the bigger robot off the east wall (its face at x = 9.8): a goal 0.5 m
    # from it, along it, has no path now (inscribed radius 0.55 m), and has one again below
    near = (9.32, 4.0, math.pi / 2)
    assert make_plan(client, START, near, 0.0)["plan"]["poses"] == []
    # a bad polygon (two points) is dropped and changes nothing; the default comes back
    client.ask(op="pub", topic="/move_base/global_costmap/set_footprint",
               type="geometry_msgs/Polygon", msg={"points": polygon["points"][:2]})
    client.ask(op="pub", topic="/move_base/global_costmap/set_footprint",
               type="geometry_msgs/Polygon",
               msg={"points": [{"x": x, "y": y, "z": 0.0} for x, y in DEFAULT_POINTS]})
    client.wait_last(GLOBAL, lambda m: np.array_equal(marked(m)[~edge], expected[~edge]),
                     20.0, "the global costmap back to the default footprint")
    assert make_plan(client, START, near, 0.0)["plan"]["poses"] != []
    assert chain["nav"].popen.poll() is None


def _crate_marks(msg: dict[str, Any]) -> int:
    """LETHAL cells of the local costmap within 0.4 m of the crate."""
    info = msg["info"]
    data = np.asarray(msg["data"], np.int8).reshape(info["height"], info["width"])
    rows, cols = np.nonzero(data == 100)
    x = info["origin"]["position"]["x"] + (cols + 0.5) * info["resolution"]
    y = info["origin"]["position"]["y"] + (rows + 0.5) * info["resolution"]
    return int((np.hypot(x - BOX[0], y - BOX[1]) < 0.4).sum())


@pytest.mark.ros
@pytest.mark.process
def test_enable_and_clear_costmaps(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    client.wait_last(LOCAL, lambda m: _crate_marks(m) > 3, 20.0, "the crate in the local map")
    reply = client.ask(op="call", name="/move_base/enable_costmaps", type="std_srvs/SetBool",
                       args={"data": False})
    assert reply == {"success": True, "message": "costmap updates disabled"}
    assert client.ask(op="call", name="/move_base/clear_costmaps", type="std_srvs/Empty") == {}
    # disabled: the obstacle layer is out of the costs, in every costmap published from now on
    count = client.ask(op="last", topic=LOCAL)["count"]
    msg = client.wait_last(LOCAL, lambda m: client.ask(op="last", topic=LOCAL)["count"] >
                           count + 2, 20.0, "local costmaps while disabled")
    assert _crate_marks(msg) == 0
    reply = client.ask(op="call", name="/move_base/enable_costmaps", type="std_srvs/SetBool",
                       args={"data": True})
    assert reply == {"success": True, "message": "costmap updates enabled"}
    client.wait_last(LOCAL, lambda m: _crate_marks(m) > 3, 20.0, "the crate marked again")


def step_goal(mode: int, steps: list[tuple[int, float, float]]) -> dict[str, Any]:
    return {"mode": mode, "useAvoid": False,
            "stepControl": [{"executeMode": m, "data": d, "speed": s, "angle": 0.0}
                            for m, d, s in steps]}


@pytest.mark.ros
@pytest.mark.process
def test_step_control_straight_half_a_metre_on_the_truth(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    x0, y0, yaw0 = standing(client)  # the test before may have left it still settling
    odom0 = odom_xy(client)
    client.ask(op="send", name="/cmd_vel_control", type=STEP,
               goal=step_goal(1, [(1, 0.5, 0.0)]))
    res = client.ask(op="result", name="/cmd_vel_control", timeout=60.0)
    assert res["state"] == SUCCEEDED, res
    assert res["result"] == {"result": 1, "executeMode": 1, "percent": pytest.approx(100.0)}
    assert res["feedbacks"] > 10
    x1, y1, yaw1 = standing(client)
    target = (x0 + 0.5 * math.cos(yaw0), y0 + 0.5 * math.sin(yaw0))
    assert math.hypot(x1 - target[0], y1 - target[1]) < 0.01, \
        ((x0, y0), (x1, y1), res["text"], odom0, odom_xy(client))
    assert abs(math.remainder(yaw1 - yaw0, math.tau)) < math.radians(0.5)
    # and back, so the other tests find the robot at the start
    client.ask(op="send", name="/cmd_vel_control", type=STEP,
               goal=step_goal(1, [(1, -0.5, 0.0)]))
    assert client.ask(op="result", name="/cmd_vel_control", timeout=60.0)["state"] == SUCCEEDED


def standing(client: NavClient) -> tuple[float, float, float]:
    """The true pose once two fresh readings agree within 0.5 mm (the robot has stopped)."""
    last = truth(client)
    for _ in range(100):
        now = truth(client)
        if math.hypot(now[0] - last[0], now[1] - last[1]) < 5e-4:
            return now
        last = now
    raise AssertionError("the robot did not stop")


@pytest.mark.ros
@pytest.mark.process
def test_step_control_pause_resume_and_cancel(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    x0, y0, yaw0 = standing(client)
    client.ask(op="send", name="/cmd_vel_control", type=STEP,
               goal=step_goal(1, [(1, 0.6, 0.0)]))
    client.wait_last("/amcl_pose", lambda m: (client.ask(op="feedback", name="/cmd_vel_control")
                                              ["last"] or {}).get("percent", 0) > 20,
                     30.0, "20 % of the step")
    client.ask(op="send", name="/cmd_vel_control", type=STEP, goal=step_goal(2, []))
    client.wait_last("/amcl_pose", lambda m: (client.ask(op="feedback", name="/cmd_vel_control")
                                              ["last"] or {}).get("feedback") == 2,
                     30.0, "paused feedback")
    x1, y1, _ = standing(client)
    along = (x1 - x0) * math.cos(yaw0) + (y1 - y0) * math.sin(yaw0)
    assert 0.1 < along < 0.5
    client.ask(op="send", name="/cmd_vel_control", type=STEP, goal=step_goal(3, []))
    res = client.ask(op="result", name="/cmd_vel_control", timeout=60.0)
    assert res["state"] == SUCCEEDED and res["result"]["result"] == 1, res
    x2, y2, _ = standing(client)
    assert math.hypot(x2 - x0 - 0.6 * math.cos(yaw0), y2 - y0 - 0.6 * math.sin(yaw0)) < 0.01
    # an actionlib cancel brakes and ends the list: PREEMPTED, result -2
    client.ask(op="send", name="/cmd_vel_control", type=STEP,
               goal=step_goal(1, [(1, -0.6, 0.0)]))
    client.wait_last("/amcl_pose", lambda m: (client.ask(op="feedback", name="/cmd_vel_control")
                                              ["last"] or {}).get("percent", 0) > 20,
                     30.0, "20 % of the way back")
    client.ask(op="cancel", name="/cmd_vel_control")
    res = client.ask(op="result", name="/cmd_vel_control", timeout=30.0)
    assert res["state"] == PREEMPTED and res["result"]["result"] == -2, res
    x3, y3, _ = standing(client)
    back = (x2 - x3) * math.cos(yaw0) + (y2 - y3) * math.sin(yaw0)
    assert 0.1 < back < 0.55
    # PAUSE with nothing running: refused
    client.ask(op="send", name="/cmd_vel_control", type=STEP, goal=step_goal(2, []))
    res = client.ask(op="result", name="/cmd_vel_control", timeout=30.0)
    assert res["state"] == ABORTED and "no step list is running" in res["text"], res
    # back to the start for the other tests
    client.ask(op="send", name="/cmd_vel_control", type=STEP,
               goal=step_goal(1, [(1, -(x3 - x0) * math.cos(yaw0) - (y3 - y0) * math.sin(yaw0),
                                   0.0)]))
    assert client.ask(op="result", name="/cmd_vel_control", timeout=60.0)["state"] == SUCCEEDED


@pytest.mark.ros
@pytest.mark.process
@pytest.mark.parametrize(("steps", "why"), [
    ([(1, math.nan, 0.0)], "finite"),
    ([(1, 10.5, 0.0)], "beyond"),
    ([(2, 1.0, 50.0)], "outside"),
    ([(3, 0.5, 0.0)], "LATERAL"),
    ([], "empty"),
])
def test_step_control_refuses_bad_data_and_stays_still(
        chain: dict[str, Any], steps: list[tuple[int, float, float]], why: str) -> None:
    client: NavClient = chain["client"]
    before = truth(client)
    client.ask(op="send", name="/cmd_vel_control", type=STEP, goal=step_goal(1, steps))
    res = client.ask(op="result", name="/cmd_vel_control", timeout=30.0)
    assert res["state"] == ABORTED and res["result"]["result"] == -1, res
    assert why in res["text"]
    after = truth(client)
    assert math.hypot(after[0] - before[0], after[1] - before[1]) < 0.002


@pytest.mark.ros
@pytest.mark.process
def test_move_base_succeeds_is_preempted_and_aborts(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    goal = (6.0, 3.2, -math.pi / 2)
    client.ask(op="send", name="/move_base", type=MOVE,
               goal={"target_pose": pose_msg(*goal), "execution_mode": 0})
    res = client.ask(op="result", name="/move_base", timeout=90.0)
    assert res["state"] == SUCCEEDED, res
    assert res["feedbacks"] > 5
    x, y, yaw = truth(client)
    assert math.hypot(x - goal[0], y - goal[1]) < 0.05
    assert abs(math.remainder(yaw - goal[2], math.tau)) < math.radians(2.0)
    # cancelled on the way: PREEMPTED, and the robot stops
    client.ask(op="send", name="/move_base", type=MOVE,
               goal={"target_pose": pose_msg(*START), "execution_mode": 0})
    client.wait_last("/amcl_pose", lambda m: client.ask(op="feedback", name="/move_base")
                     ["count"] > 3, 30.0, "move_base feedback")
    client.ask(op="cancel", name="/move_base")
    res = client.ask(op="result", name="/move_base", timeout=30.0)
    assert res["state"] == PREEMPTED, res
    # unreachable: inside the east wall, and off the map
    for target, why in (((9.9, 4.0, 0.0), "no path"), ((30.0, 4.0, 0.0), "off the map")):
        client.ask(op="send", name="/move_base", type=MOVE,
                   goal={"target_pose": pose_msg(*target), "execution_mode": 0})
        res = client.ask(op="result", name="/move_base", timeout=30.0)
        assert res["state"] == ABORTED and why in res["text"], res


@pytest.mark.ros
@pytest.mark.process
def test_navigation_mode_results(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    kind = "woosh_msgs/NavigationModeAction"
    client.ask(op="send", name="/navigation_mode", type=kind,
               goal={"navigation_mode": 3, "waiting_timeout": -1.0, "max_speed": 0.0})
    res = client.ask(op="result", name="/navigation_mode", timeout=30.0)
    assert res["state"] == SUCCEEDED and res["result"] == {"result": 1}, res
    assert "precise" in res["text"]
    client.ask(op="send", name="/navigation_mode", type=kind, goal={"navigation_mode": 7})
    res = client.ask(op="result", name="/navigation_mode", timeout=30.0)
    assert res["state"] == ABORTED and res["result"] == {"result": 0}, res
    assert "navigation_mode 7" in res["text"]
    client.ask(op="send", name="/navigation_mode", type=kind, goal={"navigation_mode": 1})
    assert client.ask(op="result", name="/navigation_mode")["state"] == SUCCEEDED



def move(client: NavClient, goal: tuple[float, float, float]) -> None:
    client.ask(op="send", name="/move_base", type=MOVE,
               goal={"target_pose": pose_msg(*goal), "execution_mode": 0})


def at(client: NavClient, goal: tuple[float, float, float]) -> None:
    """The robot stands at ``goal`` within move_base's tolerances (5 cm, 2 deg) on the truth."""
    x, y, yaw = standing(client)
    assert math.hypot(x - goal[0], y - goal[1]) < 0.05, ((x, y, yaw), goal)
    assert abs(math.remainder(yaw - goal[2], math.tau)) < math.radians(2.0), ((x, y, yaw), goal)


@pytest.mark.ros
@pytest.mark.process
def test_a_newer_move_base_goal_preempts_the_running_one(chain: dict[str, Any]) -> None:
    client: NavClient = chain["client"]
    client.ask(op="sub", topic="/move_base/result", type="woosh_msgs/MoveBaseActionResult")
    ended = client.ask(op="last", topic="/move_base/result")["count"]
    move(client, (7.5, 2.5, 0.0))
    client.wait_last("/amcl_pose", lambda m: client.ask(op="feedback", name="/move_base")
                     ["count"] > 3, 30.0, "move_base feedback")
    second = (5.0, 2.5, math.pi / 2)
    move(client, second)  # the same SimpleActionClient: a new goal, the first is preempted
    first = client.wait_last("/move_base/result", lambda m: client.ask(
        op="last", topic="/move_base/result")["count"] > ended, 30.0, "the first goal's end")
    assert first["status"]["status"] == PREEMPTED, first["status"]
    assert "newer goal" in first["status"]["text"]
    res = client.ask(op="result", name="/move_base", timeout=90.0)
    assert res["state"] == SUCCEEDED, res
    last = client.ask(op="last", topic="/move_base/result")
    assert last["count"] == ended + 2
    assert last["msg"]["status"]["goal_id"]["id"] != first["status"]["goal_id"]["id"]
    at(client, second)


@pytest.mark.ros
@pytest.mark.process
def test_stop_and_wait_waits_in_front_of_the_crate_then_precise_avoids_it(
        chain: dict[str, Any]) -> None:
    """From (5, 2.5) facing the crate 3.3 m ahead (out of the costmaps' 2.5 m reach when the
    path is planned, so the plan runs through it): mode 2 stops in front of it and waits, the
    goal still ACTIVE; switched to mode 1 while waiting, the robot goes around and arrives."""
    client: NavClient = chain["client"]
    kind = "woosh_msgs/NavigationModeAction"
    start = (5.0, 2.5, math.pi / 2)
    move(client, start)
    assert client.ask(op="result", name="/move_base", timeout=90.0)["state"] == SUCCEEDED
    assert client.ask(op="call", name="/move_base/clear_costmaps", type="std_srvs/Empty") == {}
    client.ask(op="send", name="/navigation_mode", type=kind, goal={"navigation_mode": 2})
    assert client.ask(op="result", name="/navigation_mode")["state"] == SUCCEEDED
    goal = (5.0, 7.0, math.pi / 2)  # behind the crate (its faces at y 5.8 and 6.2)
    move(client, goal)
    try:
        client.wait_last("/amcl_pose", lambda m: m["pose"]["pose"]["position"]["y"] > 4.5,
                         60.0, "the robot on its way to the crate")
    except AssertionError as exc:
        raise AssertionError(f"{exc}; move_base: "
                             f"{client.ask(op='state', name='/move_base')}") from None
    x, y, _ = standing(client)
    assert 4.5 < y < BOX[1] - 0.2 - 0.4 and abs(x - BOX[0]) < 0.1  # in front of it, on the line
    time.sleep(3.0)  # waiting, seconds later: still ACTIVE, not aborted (no "stuck")
    res = client.ask(op="state", name="/move_base")
    assert res["state"] == 1, res
    x2, y2, _ = standing(client)
    assert math.hypot(x2 - x, y2 - y) < 0.002
    # precise avoidance; permitted_passage (False in an unset message) allows a changed path
    client.ask(op="send", name="/navigation_mode", type=kind,
               goal={"navigation_mode": 1, "permitted_passage": True})
    assert client.ask(op="result", name="/navigation_mode")["state"] == SUCCEEDED
    res = client.ask(op="result", name="/move_base", timeout=60.0)
    assert res["state"] == SUCCEEDED, res
    at(client, goal)
