"""The task report (lowerbase/reports/tasks.py) on the demo (scenarios/tasks/demo.toml),
run once: the files exist, and summary.json says what the run did, checked against the
emulator's ground truth, the BMS's pack model, the map's places and the samples taken
independently of the published robot_status."""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lowerbase.bms.config import BatteryConfig
from lowerbase.reports.tasks import FILES, PLOTS, write_tasks_report
from lowerbase.scenarios.tasks import FIELDS, library_tasks, load_tasks_scenario
from lowerbase.scenarios.tasks_run import SAMPLE_COLUMNS, TasksResult, report, run_tasks_scenario


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[TasksResult, dict[str, Any], Path]:
    out = tmp_path_factory.mktemp("demo-report")
    result = run_tasks_scenario(load_tasks_scenario(library_tasks()["demo"]))
    summary = write_tasks_report(result, out)
    return result, summary, out


def test_the_demo_passes_and_does_what_the_issue_says(demo: Any) -> None:
    result, summary, _ = demo
    assert result.passed, report(result)
    timeline = summary["timeline"]
    transport = [e for e in timeline if e["task_id"] == 1]
    assert transport[0]["task_type"] == "transporting" and transport[-1]["task_state"] == \
        "completed"
    assert "warning" in {e["robot_state"] for e in transport}  # the battery turned low
    charge = [e for e in timeline if e["task_id"] == 0 and e["task_type"] == "charging"]
    assert charge[0]["t"] >= transport[-1]["t"] and charge[-1]["task_state"] == "completed"
    assert summary["battery"]["soc_min"] < 20.0 < summary["battery"]["soc_end"]
    # the crate stands by the route: the robot passes near it (the planner keeps the inflation's
    # clearance, docs/navigation.md), never touching it
    c = np.array(result.samples)
    crate = result.scenario.world.obstacles[0]["center"]
    gap = np.hypot(c[:, 1] - crate[0], c[:, 2] - crate[1]).min()
    assert gap < 1.3 and result.sim.navsim.contacts == 0


def test_the_files_exist(demo: Any) -> None:
    result, summary, out = demo
    assert set(summary["files"]) == set(FILES)
    for name in FILES:
        assert (out / name).is_file(), name
    for name in PLOTS:
        assert (out / name).stat().st_size > 10_000, name
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("tests") == str(len(result.outcomes))
    assert suite.get("failures") == "0"
    page = (out / "index.html").read_text()
    assert all(f"src='{p}'" in page for p in PLOTS)
    assert page.count("<tr>") == len(summary["timeline"]) + 1  # the status table, + head


def test_the_path_ends_where_the_truth_does(demo: Any) -> None:
    result, summary, out = demo
    world = result.sim.world
    truth, est = world.true_pose(), world.amcl_pose()
    final = summary["final"]
    assert [final["truth"][k] for k in ("x", "y", "yaw")] == pytest.approx(truth, abs=1e-4)
    assert [final["estimate"][k] for k in ("x", "y", "yaw")] == pytest.approx(est, abs=1e-4)
    assert final["estimate_error_m"] == pytest.approx(
        math.hypot(est[0] - truth[0], est[1] - truth[1]), abs=1e-4)
    with (out / "trace.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(SAMPLE_COLUMNS)
    xy = np.array([[float(r["truth_x"]), float(r["truth_y"])] for r in rows])
    assert xy[-1] == pytest.approx(truth[:2], abs=1e-4)
    assert summary["driven_m"] == pytest.approx(np.hypot(*np.diff(xy, axis=0).T).sum(), rel=1e-3)


def test_the_plans_go_to_the_mark_then_the_charger(demo: Any) -> None:
    result, summary, _ = demo
    places = result.sim.places
    plans = summary["plans"]
    assert len(plans) >= 2
    assert plans[0]["end"][:2] == pytest.approx(places.storage["B1-01"][:2], abs=1e-6)
    assert plans[-1]["end"][:2] == pytest.approx(places.charger.approach[:2], abs=1e-6)
    for plan in plans:
        straight = math.dist(plan["start"][:2], plan["end"][:2])
        assert straight - 1e-6 <= plan["length_m"] < 2 * straight


def test_the_timeline_is_the_published_robot_status(demo: Any) -> None:
    result, summary, _ = demo
    published = [(round(t, 3), s.task_id, *(FIELDS[f](getattr(s, f)).name.lower()
                                            for f in FIELDS)) for t, s in result.history]
    assert [(e["t"], e["task_id"], *(e[f] for f in FIELDS)) for e in summary["timeline"]] == \
        published
    # the machine's status sampled on its own (not through on_status) is, at every sample,
    # the last one published before it
    times = [t for t, _ in result.history]
    col = {n: i for i, n in enumerate(SAMPLE_COLUMNS)}
    checked = 0
    for row in result.samples:
        t = row[col["t"]]
        if any(abs(t - h) < 1e-6 for h in times):
            continue  # published in the tick that starts at this sample: after it
        last = [s for h, s in result.history if h < t][-1]
        assert [row[col[f]] for f in ("task_id", *FIELDS)] == \
            [last.task_id, *(int(getattr(last, f)) for f in FIELDS)], t
        checked += 1
    assert checked > 0.9 * len(result.samples)


def test_the_battery_is_the_pack_and_its_charger(demo: Any) -> None:
    result, summary, _ = demo
    b = summary["battery"]
    pack = result.sim.world.loop.mcu.bms.device.pack
    assert b["soc_start"] == pytest.approx(result.scenario.soc, abs=1e-3)
    assert b["soc_end"] == pytest.approx(pack.soc, abs=1e-3)
    assert b["max_charge_current_a"] == pytest.approx(BatteryConfig().charge_current_a, abs=0.1)
    # charging (current > 0) as long as robot_state said charging, to a sample or two
    states = [(e["t"], e["robot_state"]) for e in summary["timeline"]]
    start = next(t for t, s in states if s == "charging")
    end = next(t for t, s in states if t > start and s != "charging")
    assert b["charging_s"] == pytest.approx(end - start, abs=1.0)
