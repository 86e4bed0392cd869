"""A campaign's run of every scenario kind, in this process: tasks, trace, legged, world."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.campaign.execute import EXPECT, run_one
from lowerbase.campaign.plan import load_campaign, plan_run
from lowerbase.campaign.spec import METRICS

CASES = {
    "tasks/parking": ('"initial.soc" = { uniform = [60, 90] }',
                      ("localization_error_p95_m", "soc_final", "task_time_s")),
    "trace/diagram": ('"trace.speed" = [400, 500]', ("sim_s",)),
    "legged_stand_walk_sit": ('"initial.soc" = [70]', ("position_error_p95_m", "voltage_final")),
    "warehouse_localization": ('"profile.truth.track_error" = { uniform = [-0.01, 0.01] }',
                               ("odom_error_p95_m",)),
}


@pytest.mark.parametrize("scenario", sorted(CASES))
def test_one_run_of_each_kind(tmp_path: Path, scenario: str) -> None:
    vary, metrics = CASES[scenario]
    path = tmp_path / "c.toml"
    path.write_text(f"[campaign]\nscenario = {scenario!r}\nruns = 2\nseed = 5\n"
                    f"[vary]\n{vary}\n", encoding="utf-8")
    c = load_campaign(path)
    row = run_one(plan_run(c, 1))
    assert row["error"] == "", row["error"]
    assert any(k.startswith(EXPECT) for k in row)
    assert set(metrics) <= set(row), row
    # every metric a row has is one [report] metric accepts for its kind
    fixed = {"run", "scenario", "passed", "error", "wall_s", *plan_run(c, 1).values}
    others = {k for k in row if not k.startswith(EXPECT) and k not in fixed}
    assert others <= set(METRICS[c.scenarios[0].kind]), others
    assert row == {**run_one(plan_run(c, 1)), "wall_s": row["wall_s"]}  # the same again
