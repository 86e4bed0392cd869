"""Finding scenarios: the library (the repository's scenarios/ and the packaged copy in
lowerbase/scenarios/library/) by name, and loading a file of any kind (wheeled, legged, tasks)."""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import TYPE_CHECKING

from lowerbase.errors import ConfigError
from lowerbase.files import read_toml
from lowerbase.scenarios.wheeled import Scenario, robot_of, scenario_from_dict

if TYPE_CHECKING:
    from lowerbase.scenarios.legged import LeggedScenario
    from lowerbase.scenarios.tasks import TasksScenario


def load_any_scenario(path: str | Path) -> Scenario | LeggedScenario | TasksScenario:
    """A wheeled, a legged (``robot = "legged"``) or a task (a ``[tasks]`` table,
    scenario_tasks.py) scenario file."""
    p = Path(path)
    data = read_toml(p, "scenario")
    if "tasks" in data:
        from lowerbase.scenarios.tasks import load_tasks_scenario

        try:
            return load_tasks_scenario(p)
        except ConfigError as e:
            raise ConfigError(str(e) if str(e).startswith(str(p)) else f"{p}: {e}") from None
    if robot_of(data) == "legged":
        from lowerbase.scenarios.legged import legged_scenario_from_dict

        return legged_scenario_from_dict(data, source=str(p), base=p.parent)
    return scenario_from_dict(data, source=str(p), base=p.parent)


# -- the library -------------------------------------------------------------------------------


def library_dirs() -> list[Path]:
    """Where library scenarios live: the repository's scenarios/ (a checkout or an editable
    install), then the copy packaged in lowerbase/scenarios/library/."""
    here = Path(__file__).resolve()
    dirs = [here.parents[2] / "scenarios", here.parent / "library"]
    return [d for d in dirs if d.is_dir()]


#: sub-libraries (scenarios/NAME/*.toml, named "NAME/STEM") that `library("all")` includes
SUBLIBRARIES = ("tasks",)


def library(robot: str = "wheeled") -> dict[str, Path]:
    """Library scenarios of ``robot`` ("wheeled", "legged" or "all") by name (file stem); the
    repository's copy wins. "all" also has the sub-libraries' scenarios, as "tasks/STEM"."""
    found: dict[str, Path] = {}
    for d in reversed(library_dirs()):
        for p in sorted(d.glob("*.toml")):
            found[p.stem] = p
        if robot == "all":
            for sub in SUBLIBRARIES:
                for p in sorted((d / sub).glob("*.toml")):
                    found[f"{sub}/{p.stem}"] = p
    if robot != "all":
        found = {k: p for k, p in found.items() if _robot_of_file(p) == robot}
    return dict(sorted(found.items()))


def _robot_of_file(path: Path) -> str:
    try:
        return robot_of(read_toml(path, "scenario"))
    except ConfigError:
        return "wheeled"  # loading it says what is wrong


def find_scenario(name_or_path: str) -> Path:
    """A scenario file by path, or a library scenario by name."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    lib = library("all")
    if name_or_path in lib:
        return lib[name_or_path]
    if p.suffix or "/" in name_or_path:
        raise ConfigError(f"no such scenario file: {p}")
    close = difflib.get_close_matches(name_or_path, list(lib), n=1)
    hint = f"did you mean {close[0]}?" if close else f"library: {', '.join(lib) or 'empty'}"
    raise ConfigError(f"no scenario file or library scenario {name_or_path!r}; {hint}")
