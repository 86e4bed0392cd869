"""Run N of a campaign: its base scenario, its values and seeds, the varied scenario (TOML
data) and profile; and the scenario object built from them."""

from __future__ import annotations

import copy
import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lowerbase.campaign.spec import Campaign, campaign_from_dict
from lowerbase.errors import CampaignError, ConfigError
from lowerbase.files import read_toml

PROFILE = "profile."
#: profile (section, key) pairs that ``reseed`` draws per run (wheeled robots)
SEEDS = (("imu", "seed"), ("truth", "seed"))


@dataclass(frozen=True)
class RunSpec:
    """Everything a worker needs for one run (picklable; no file of the campaign needed)."""

    index: int
    scenario: str  #: the base scenario as the campaign names it
    kind: str
    path: str  #: the base scenario's file (its folder resolves relative paths)
    data: dict[str, Any]  #: the varied scenario TOML
    profile: dict[str, Any] | None  #: the varied profile TOML (None: the scenario's own)
    values: dict[str, Any]  #: varied key -> value of this run
    seeds: dict[str, int]  #: simulation seeds drawn for this run


def _locate(index: int, campaign: Campaign) -> tuple[int, tuple[Any, ...]]:
    """(base scenario index, grid values) of run ``index``."""
    if not 0 <= index < campaign.total:
        raise CampaignError(f"run {index}: this campaign has runs 0..{campaign.total - 1}")
    s, rest = divmod(index, campaign.per_scenario)
    g = rest // campaign.runs
    points = itertools.islice(itertools.product(*(v.values for v in campaign.axes)), g, None)
    return s, next(points)


def _set(doc: Any, key: str, value: Any, where: str) -> None:
    """Set ``doc``'s dotted ``key`` (integers index arrays, -1 the last; missing tables
    are created: the scenario's own validation names a misspelt key)."""
    parts = key.split(".")
    node = doc
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, list):
            try:
                j = int(part)
                node[j]
            except (ValueError, IndexError):
                raise CampaignError(f"{where}: {'.'.join(parts[:i]) or key} has "
                                    f"{len(node)} item(s); {part!r} is not one of them "
                                    "(0.., or -1 for the last)") from None
            if last:
                node[j] = value
            else:
                node = node[j]
        elif isinstance(node, dict):
            if last:
                node[part] = value
            else:
                node = node.setdefault(part, {})
        else:
            raise CampaignError(f"{where}: {'.'.join(parts[:i])} is a value, not a table")


def base_profile(campaign: Campaign, s: int) -> dict[str, Any] | None:
    """The profile TOML a wheeled or legged base scenario names (its packaged default)."""
    base = campaign.scenarios[s]
    if base.kind not in ("wheeled", "legged"):
        return None
    head = base.data.get("scenario", {})
    ref = head.get("profile", "default") if isinstance(head, Mapping) else "default"
    if ref == "default":
        if base.kind == "legged":
            from lowerbase.legged.profile import legged_profile_path

            return read_toml(legged_profile_path(), "profile")
        from lowerbase.firmware_model.profile import default_profile_path

        return read_toml(default_profile_path(), "profile")
    return read_toml(base.path.parent / str(ref), "profile")


def plan_run(campaign: Campaign, index: int) -> RunSpec:
    """Run ``index``: drawn from SeedSequence([seed, index]) alone, so it is the same run
    wherever and whenever it is built."""
    s, point = _locate(index, campaign)
    base = campaign.scenarios[s]
    seq = np.random.SeedSequence([campaign.seed, index])
    rng = np.random.default_rng(seq)
    sim_seeds = [int(x) for x in seq.generate_state(len(SEEDS), dtype=np.uint32)]
    grid_values = iter(point)
    values: dict[str, Any] = {}
    for v in campaign.variations:
        values[v.key] = next(grid_values) if v.is_axis(campaign.grid) else v.sample(rng)
    data = copy.deepcopy(dict(base.data))
    if campaign.timeline:
        data["timeline"] = [*data.get("timeline", []), *copy.deepcopy(campaign.timeline)]
    if campaign.expect or not campaign.keep_expect:
        kept = data.get("expect", []) if campaign.keep_expect else []
        data["expect"] = [*kept, *copy.deepcopy(campaign.expect)]
    seeds: dict[str, int] = {}
    profile_keys = [k for k in values if k.startswith(PROFILE)]
    profile: dict[str, Any] | None = None
    if profile_keys or (campaign.reseed and base.kind == "wheeled"):
        profile = base_profile(campaign, s)
        if profile is None:
            raise CampaignError(f"[vary] {profile_keys[0]!r}: a {base.kind} scenario "
                                f"({base.ref}) has no profile to vary")
        if campaign.reseed and base.kind == "wheeled":
            for (section, key), seed in zip(SEEDS, sim_seeds, strict=True):
                seeds[f"{PROFILE}{section}.{key}"] = seed
                _set(profile, f"{section}.{key}", seed, "reseed")
    where = f"{base.ref} run {index}"
    for key, value in values.items():
        if key.startswith(PROFILE):
            assert profile is not None
            _set(profile, key[len(PROFILE):], value, f"[vary] {key!r} ({where})")
        else:
            _set(data, key, value, f"[vary] {key!r} ({where})")
    return RunSpec(index=index, scenario=base.ref, kind=base.kind, path=str(base.path),
                   data=data, profile=profile, values=values, seeds=seeds)


def build_scenario(spec: RunSpec, workdir: Path) -> Any:
    """The scenario object of ``spec`` (its profile written to ``workdir/profile.toml``)."""
    from lowerbase.campaign.toml_out import dumps

    data = copy.deepcopy(spec.data)
    path = Path(spec.path)
    profile: Path | None = None
    if spec.profile is not None:
        workdir.mkdir(parents=True, exist_ok=True)
        profile = workdir / "profile.toml"
        profile.write_text(dumps(spec.profile), encoding="utf-8")
        head = data.setdefault("scenario", {})
        if isinstance(head, dict):
            head["profile"] = str(profile.resolve())
    source = f"{spec.scenario} run {spec.index}"
    try:
        if spec.kind == "tasks":
            from lowerbase.scenarios.tasks import tasks_scenario_from_dict

            return tasks_scenario_from_dict(data, source, path.parent)
        if spec.kind == "trace":
            from lowerbase.scenarios.trace import trace_scenario_from_dict

            return trace_scenario_from_dict(data, source, path.parent)
        if spec.kind == "legged":
            from lowerbase.scenarios.legged import legged_scenario_from_dict

            sc: Any = legged_scenario_from_dict(data, source=source, base=path.parent)
            from lowerbase.legged.profile import load_legged_profile

            load_legged_profile(sc.profile)
            return sc
        from lowerbase.firmware_model.profile import load_profile
        from lowerbase.scenarios.wheeled import scenario_from_dict

        sc = scenario_from_dict(data, source=source, base=path.parent)
        load_profile(sc.profile)  # a bad varied profile value fails here, not in the run
        return sc
    except ConfigError as e:
        text = str(e)
        if profile is not None and str(profile.resolve()) in text:  # not a file of the user's
            raise CampaignError(text.replace(str(profile.resolve()), f"run {spec.index}'s "
                                             "profile ([vary] \"profile.*\" keys)")) from None
        raise CampaignError(f"{text} (check the campaign's [vary], [[timeline]] and "
                            "[[expect]])") from None


def check_campaign(campaign: Campaign) -> None:
    """Build (not run) the first run of every base scenario: a misspelt key, an index
    past a timeline's end or a value out of range is reported before any run starts."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="lowerbase-campaign-") as tmp:
        for s in range(len(campaign.scenarios)):
            index = s * campaign.per_scenario
            build_scenario(plan_run(campaign, index), Path(tmp) / str(index))


def load_campaign(path: str | Path) -> Campaign:
    """Read and validate a campaign file; every mistake is one CampaignError line naming the
    file. Run 0 of every base scenario is built (not run) to check the varied keys."""
    p = Path(path)
    try:
        campaign = campaign_from_dict(read_toml(p, "campaign"), p)
        check_campaign(campaign)
    except ConfigError as e:
        text = str(e)
        raise CampaignError(text if text.startswith(str(p)) else f"{p}: {text}") from None
    return campaign
