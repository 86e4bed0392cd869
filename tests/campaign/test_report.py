"""The campaign report from rows (no runs): pass rates, failing runs' replay commands, plots."""

from __future__ import annotations

import json
from pathlib import Path

from lowerbase.campaign.report import write_report
from lowerbase.campaign.spec import campaign_from_dict
from lowerbase.campaign.table import read_csv, write_csv


def test_report_and_table_from_rows(tmp_path: Path) -> None:
    c = campaign_from_dict({
        "campaign": {"scenario": "loop", "runs": 12},
        "vary": {"timeline.-1.path": ["raw", "smoothed"], "initial.soc": {"uniform": [10, 90]}},
        "report": {"metric": "odom_error_m", "threshold": 0.5}}, tmp_path / "c.toml")
    rows = [{"run": i, "scenario": "loop", "passed": i % 3 != 0, "error": "",
             "timeline.-1.path": ["raw", "smoothed"][i % 2], "initial.soc": 10.0 * i,
             "expect: /odom near": i % 3 != 0, "odom_error_m": 0.1 * i, "wall_s": 0.2}
            for i in reversed(range(12))]
    summary = write_report(c, rows, tmp_path, campaign_arg="my campaign.toml")
    assert (summary["finished"], summary["passed"], summary["failed"]) == (12, 8, 4)
    assert summary["expectations"] == [{"name": "/odom near", "passed": 8, "scored": 12}]
    assert summary["failing_runs"][1]["replay"] == \
        "lowerbase campaign replay 'my campaign.toml' --run 3"
    assert summary["plots"] == ["vary-0.png", "vary-1.png"]
    page = (tmp_path / "index.html").read_text()
    assert "--run 9" in page and "66.7 %" in page
    assert json.loads((tmp_path / "summary.json").read_text()) == summary
    cols = write_csv(tmp_path / "results.csv", c, rows)
    assert cols[:6] == ["run", "scenario", "passed", "error", "timeline.-1.path", "initial.soc"]
    back = read_csv(tmp_path / "results.csv")
    assert [r["run"] for r in back] == list(range(12))
    assert back[3] == {**rows[8], "error": None}
