"""The results table: one row per run, as CSV (``results.csv``), and ``runs.jsonl``, the rows
appended as they arrive (what a killed campaign still has)."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from lowerbase.campaign.execute import EXPECT, HEAD
from lowerbase.campaign.spec import Campaign

#: columns that differ between runs of the same run index (left out of comparisons)
WALL = ("wall_s",)


def columns(campaign: Campaign, rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """Fixed columns, the varied keys in file order, the expectations in order of first
    appearance, then the metrics."""
    varied = [v.key for v in campaign.variations]
    expects: list[str] = []
    metrics: list[str] = []
    for row in rows:
        for k in row:
            if k in HEAD or k in varied or k in WALL:
                continue
            target = expects if k.startswith(EXPECT) else metrics
            if k not in target:
                target.append(k)
    return [*HEAD, *varied, *expects, *metrics, *WALL]


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    return v


def write_csv(path: Path, campaign: Campaign, rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """``rows`` sorted by run into ``path``; returns the columns."""
    cols = columns(campaign, rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for row in sorted(rows, key=lambda r: int(r["run"])):
            w.writerow([_cell(row.get(c)) for c in cols])
    return cols


def _parse(text: str) -> Any:
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_csv(path: Path) -> list[dict[str, Any]]:
    """The rows of a results.csv, values typed back (bool, int, float, text, None)."""
    with path.open(newline="", encoding="utf-8") as f:
        return [{k: _parse(v) for k, v in row.items()} for row in csv.DictReader(f)]


class RowLog:
    """``runs.jsonl``: a JSON line per row, flushed as each run finishes."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._f: TextIO = path.open("w", encoding="utf-8")

    def __call__(self, row: Mapping[str, Any]) -> None:
        self._f.write(json.dumps(row, sort_keys=False) + "\n")
        self._f.flush()

    def close(self) -> None:
        self._f.close()
