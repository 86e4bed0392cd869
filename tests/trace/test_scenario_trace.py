"""The trace scenario runner (lowerbase.scenarios.trace) and the library's diagram."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.errors import ConfigError
from lowerbase.scenarios import trace as st

SHORT = """
[scenario]
duration = {duration}
[world]
map = "warehouse"
start = [6.0, 1.2, 0.0]
localization = "truth"
[trace]
blocked_timeout = 2.0
route = {route}
[[expect]]
topic = "msg_trace_navigate_status"
sequence = ["RUNNING", "FINISHED"]
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def test_the_library_diagram_runs_every_step() -> None:
    sc = st.load_trace_scenario(st.library_trace()["diagram"])
    assert sc.params["blocked_timeout"] == 60.0  # the seed's wait, on the simulated clock
    result = st.run_trace_scenario(sc)
    assert result.passed, st.report(result)
    assert result.seen[st.STATUS] == ["RUNNING", "BLOCKED", "RUNNING", "FINISHED"]
    assert result.sim_time > 60.0


def test_a_short_route_passes_and_an_unmet_expectation_fails(tmp_path: Path) -> None:
    ok = st.run_trace_scenario(st.load_trace_scenario(_write(tmp_path, SHORT.format(
        duration=20.0, route="[[6.0, 1.2], [7.0, 1.2]]"))))
    assert ok.passed and ok.seen[st.STATUS] == ["RUNNING", "FINISHED"]
    cut = st.run_trace_scenario(st.load_trace_scenario(_write(tmp_path, SHORT.format(
        duration=1.0, route="[[6.0, 1.2], [9.0, 1.2]]"))))
    assert not cut.passed and "seen RUNNING" in st.report(cut)


@pytest.mark.parametrize(("text", "what"), [
    (SHORT.format(duration=5.0, route="[[6.0, 1.2]]"), "at least two"),
    (SHORT.format(duration=5.0, route="[[6.0, 1.2], [6.0, 1.2]]"), "length"),
    (SHORT.format(duration=5.0, route="[[6.0, 1.2], [7.0, 1.2]]") + "[nope]\n", "nope"),
    (SHORT.format(duration=5.0, route="[[6.0, 1.2], [7.0, 1.2]]").replace(
        "blocked_timeout = 2.0", "blocked_timeout = -1.0"), "blocked_timeout"),
    (SHORT.format(duration=5.0, route="[[6.0, 1.2], [7.0, 1.2]]").replace(
        '"FINISHED"]', '"DONE"]'), "sequence"),
])
def test_bad_files_are_one_line(tmp_path: Path, text: str, what: str) -> None:
    with pytest.raises(ConfigError, match=what):
        st.load_trace_scenario(_write(tmp_path, text))


def test_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert st.main(["no_such_scenario"]) == 2
    assert "no trace scenario 'no_such_scenario'" in capsys.readouterr().err
