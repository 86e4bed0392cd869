"""The campaign file, run planning and the TOML writer (no Dask)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.campaign.plan import load_campaign, plan_run
from lowerbase.campaign.toml_out import dumps
from lowerbase.errors import CampaignError, ConfigError
from lowerbase.files import read_toml, tomllib
from lowerbase.firmware_model.profile import default_profile_path

ROOT = Path(__file__).resolve().parents[2]


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text, encoding="utf-8")
    return p


GRID = """
[campaign]
scenario = "wheel_slip"
grid = true
runs = 2
seed = 7
[vary]
"initial.soc" = [30, 60, 90]
"timeline.1.fraction" = [0.2, 0.6]
"profile.truth.track_error" = { uniform = [-0.01, 0.01] }
"""


def test_grid_counts_and_points(tmp_path: Path) -> None:
    c = load_campaign(write(tmp_path, GRID))
    assert (c.grid_size, c.total) == (6, 12)
    runs = [plan_run(c, i) for i in range(c.total)]
    points = [(r.values["initial.soc"], r.values["timeline.1.fraction"]) for r in runs]
    assert points[::2] == [(30, 0.2), (30, 0.6), (60, 0.2), (60, 0.6), (90, 0.2), (90, 0.6)]
    assert points[0] == points[1]  # two repetitions of a grid point ...
    assert runs[0].values["profile.truth.track_error"] != \
        runs[1].values["profile.truth.track_error"]  # ... with their own draws and seeds
    assert runs[0].seeds != runs[1].seeds
    assert runs[3].data["timeline"][1]["fraction"] == 0.6
    assert runs[3].profile is not None and runs[3].profile["truth"]["track_error"] == \
        runs[3].values["profile.truth.track_error"]


def test_a_run_is_the_same_whenever_it_is_planned(tmp_path: Path) -> None:
    a = load_campaign(ROOT / "campaigns" / "wheel_tolerance.toml")
    b = load_campaign(ROOT / "campaigns" / "wheel_tolerance.toml")
    assert a.total == 100
    assert plan_run(a, 57) == plan_run(b, 57)
    assert plan_run(a, 57).values != plan_run(a, 58).values
    with pytest.raises(CampaignError, match=r"runs 0\.\.99"):
        plan_run(a, 100)


@pytest.mark.parametrize(("text", "message"), [
    ("[campaign]\nscenario = 'loop'\nrun = 3\n", "did you mean 'runs'"),
    ("[campaign]\nscenario = 'lop'\nruns = 3\n", "did you mean loop"),
    ("[campaign]\nscenario = 'loop'\n", "runs must be an integer"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\nx = { uniform = [2, 1] }\n",
     "low <= high"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\nx = { gauss = [0, 1] }\n",
     "exactly one of"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\n'timeline.40.at' = [1]\n",
     "7 item"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\n'intial.soc' = [1]\n",
     "intial"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\n'profile.imu.gyro_nois' = [1]\n",
     "gyro_nois"),
    ("[campaign]\nscenario = 'loop'\nruns = 2\n[vary]\n'initial.soc' = [150]\n",
     "outside"),
    ("[campaign]\nscenario = 'tasks/parking'\nruns = 2\n[vary]\n'profile.imu.seed' = [1]\n",
     "no profile"),
])
def test_mistakes_are_one_clear_line(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(CampaignError, match=message) as info:
        load_campaign(path)
    assert str(info.value).startswith(str(path))
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ConfigError)


def test_toml_writer_round_trips_the_default_profile() -> None:
    profile = read_toml(default_profile_path())
    assert tomllib.loads(dumps(profile)) == profile
    odd = {"a b": {"x": [1, 2.5, "q\"r"], "t": {"inf": float("inf")}}, "c": [{"k": True}]}
    assert tomllib.loads(dumps(odd)) == odd


def test_a_misspelt_report_metric_is_refused_with_a_hint(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text('[campaign]\nscenario = "loop"\nruns = 2\n[report]\n'
                    'metric = "odom_eror_m"\n', encoding="utf-8")
    with pytest.raises(CampaignError, match=r"\[report\]: metric 'odom_eror_m' is not a column "
                       r"of these runs; did you mean 'odom_error_m'\?"):
        load_campaign(path)
    path.write_text('[campaign]\nscenario = "legged_stand_walk_sit"\nruns = 2\n[report]\n'
                    'metric = "odom_error_m"\n', encoding="utf-8")  # not a legged run's
    with pytest.raises(CampaignError, match="metric 'odom_error_m' is not a column"):
        load_campaign(path)


def test_a_bad_varied_profile_key_names_the_run_not_a_temporary_file(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text('[campaign]\nscenario = "loop"\nruns = 2\n[vary]\n'
                    '"profile.truth.slip_rate_per_kmh" = [1.0]\n', encoding="utf-8")
    with pytest.raises(CampaignError) as e:
        load_campaign(path)
    assert str(e.value) == (f"{path}: run 0's profile ([vary] \"profile.*\" keys): unknown key "
                            "truth.slip_rate_per_kmh; did you mean truth.slip_rate_per_km?")
