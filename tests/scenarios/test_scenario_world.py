"""Scenarios with a [world]: parsing (one-line errors), the trace columns, and the two library
scenarios run on the simulated clock against the emulator's ground truth."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from lowerbase.errors import ConfigError
from lowerbase.scenarios.catalog import find_scenario
from lowerbase.scenarios.runner import run_simulated
from lowerbase.scenarios.wheeled import load_scenario, scenario_from_dict


def doc(world: dict[str, Any], expect: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    return {"scenario": {"name": "w", "duration": 3.0}, "world": world,
            "expect": expect or []}


@pytest.mark.parametrize(("world", "text"), [
    ({"map": "nowhere"}, "unknown map 'nowhere'"),
    ({"start": [8.5, 4.0, 0.0]}, "would touch wall"),
    ({"start": [1.0, "a", 0.0]}, "start must be"),
    ({"start": "Z9-99"}, "unknown place"),
    ({"localization": "psychic"}, "not known"),
    ({"colour": "red"}, "unknown key"),
    ({"obstacles": [{"kind": "crate", "name": "c"}]}, "kind must be box or person"),
])
def test_bad_world_tables_are_one_line(world: dict[str, Any], text: str) -> None:
    with pytest.raises(ConfigError, match=text) as info:
        scenario_from_dict(doc(world), source="w.toml")
    assert "\n" not in str(info.value) and str(info.value).startswith("w.toml: ")


def test_world_expectations_need_a_world_and_known_names() -> None:
    with pytest.raises(ConfigError, match="needs a \\[world\\]"):
        scenario_from_dict({"scenario": {"duration": 1.0},
                            "expect": [{"kind": "contact"}]})
    with pytest.raises(ConfigError, match="with = 'crate' is not known"):
        scenario_from_dict(doc({}, [{"kind": "contact", "with": "crate"}]))
    with pytest.raises(ConfigError, match="within"):
        scenario_from_dict(doc({}, [{"kind": "localization"}]))


def test_a_world_scenario_is_in_process_only() -> None:
    sc = scenario_from_dict(doc({"start": [4.0, 2.0, 0.0]}))
    assert any("[world]" in need for need in sc.in_process_only())


def test_contact_scenario_stops_at_the_pallet() -> None:
    sc = load_scenario(find_scenario("contact"))
    result = run_simulated(sc)
    assert result.passed, [o.detail for _, o in result.outcomes]
    tr = result.trace
    bits = tr["contact"].astype(int)
    pallet = 1 << sc.world.contact_names.index("pallet")
    first = int(np.argmax(bits & pallet))
    # the truth (emulator frame, started at map (4, 2, 0)) reaches the pallet's face at
    # x = 6.6 - 0.4 on the map: 2.2 m from the start
    assert tr["truth_x"][first] == pytest.approx(2.2, abs=0.05)
    assert tr["truth_x"][-1] <= 2.2 + 0.02
    assert math.isnan(tr["amcl_error"][-1])  # localization off


def test_localization_scenario_tracks_and_the_trace_has_amcl() -> None:
    sc = load_scenario(find_scenario("warehouse_localization"))
    result = run_simulated(sc)
    assert result.passed, [o.detail for _, o in result.outcomes]
    tr = result.trace
    # the amcl columns are the map pose: the truth placed at the start (4, 2, 0) plus the error
    i = len(tr) - 1
    assert math.hypot(tr["amcl_x"][i] - (4.0 + tr["truth_x"][i]),
                      tr["amcl_y"][i] - (2.0 + tr["truth_y"][i])) == pytest.approx(
        tr["amcl_error"][i], abs=1e-9)
    # a failing bound fails: the same trace against 1 mm
    strict = scenario_from_dict(doc({"start": [4.0, 2.0, 0.0]}, [
        {"kind": "localization", "within": 0.001, "during": [0.0, 3.0]}]))
    outcome = strict.expectations[0].evaluate(tr)
    assert outcome.status == "failed"
