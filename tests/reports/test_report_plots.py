"""Report plots: legends never cover data; the SOC plot shows more than the integer SOC."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lowerbase.reports.wheeled import _pyplot, plot_battery, plot_trajectory, plot_velocities
from lowerbase.scenarios.runner import RunResult, run_simulated
from lowerbase.scenarios.wheeled import scenario_from_dict

DRIVE = {
    "scenario": {"name": "drive", "duration": 6.0},
    "timeline": [{"at": 0.5, "action": "twist", "linear": 0.6, "angular": 0.3,
                  "duration": 5.0}],
}


@pytest.fixture(scope="module")
def result() -> RunResult:
    return run_simulated(scenario_from_dict(DRIVE))


def _legends_clear_of_the_axes(fig: Any) -> None:
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        box, area = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
        overlap_w = min(box.x1, area.x1) - max(box.x0, area.x0)
        overlap_h = min(box.y1, area.y1) - max(box.y0, area.y0)
        assert overlap_w <= 0 or overlap_h <= 0, (ax.get_ylabel(), box, area)


@pytest.mark.parametrize("plot", [plot_trajectory, plot_velocities, plot_battery])
def test_legends_do_not_cover_the_plotted_data(result: RunResult, plot: Any) -> None:
    fig = plot(result.trace, result.events, "drive")
    try:
        _legends_clear_of_the_axes(fig)
    finally:
        _pyplot().close(fig)


def test_the_soc_plot_shows_the_fine_soc_beside_the_integer_one(result: RunResult) -> None:
    trace = result.trace
    assert trace.has("capacity_soc")  # BmsCapacity remain/full: also known over a bus
    fine, exact = trace["capacity_soc"], trace["pack_soc"]
    known = np.isfinite(fine)
    assert known.sum() > len(fine) / 2
    # 0.01 Ah steps, sent once a second: within 0.05 % of the model's SOC,
    # where the integer BmsPack Soc is up to 0.5 % off
    assert np.max(np.abs(fine[known] - exact[known])) < 0.05
    soc = trace["soc"][np.isfinite(trace["soc"])]
    assert np.all(soc == np.round(soc))
    fig = plot_battery(trace, result.events, "drive")
    try:
        labels = [line.get_label() for line in fig.axes[0].get_lines()]
        assert "BmsCapacity remain/full" in labels and "pack model (exact)" in labels
    finally:
        _pyplot().close(fig)
