"""Open-circuit voltage per cell as a function of state of charge, per chemistry.

Tables from ``physical-data.md`` section 2.1 (25 degC, pseudo-OCV from slow cycling):
LFP is table A (LithiumWerks APR18650M1B, C/32), whose end points are the 2.0 V / 3.6 V
cut-offs; NMC is the mean of the four INR cells (the 5 % and 95 % points are the mean of the
four rows as well). Interpolation is linear on the 5/10 % grid.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence
from enum import Enum


class Chemistry(str, Enum):
    """Cell chemistry of the pack."""

    LFP = "LFP"
    NMC = "NMC"


#: SOC grid [%] shared by both tables
SOC_GRID: tuple[float, ...] = (0, 5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 95, 100)

#: OCV per cell [V] on :data:`SOC_GRID`
OCV_TABLES: dict[Chemistry, tuple[float, ...]] = {
    Chemistry.LFP: (
        2.010, 3.072, 3.203, 3.241, 3.278, 3.295, 3.299, 3.303, 3.316, 3.337, 3.341, 3.343, 3.598,
    ),
    Chemistry.NMC: (
        2.557, 3.179, 3.336, 3.479, 3.583, 3.652, 3.733, 3.835, 3.922, 4.025, 4.085, 4.108, 4.194,
    ),
}

_LFP = OCV_TABLES[Chemistry.LFP]


def interpolate(x: float, xs: Sequence[float], ys: Sequence[float]) -> float:
    """Piecewise-linear interpolation of ``ys(xs)`` at ``x``, clamped at both ends."""
    if x <= xs[0]:
        return float(ys[0])
    if x >= xs[-1]:
        return float(ys[-1])
    i = bisect_right(xs, x) - 1
    x0, x1 = xs[i], xs[i + 1]
    y0, y1 = ys[i], ys[i + 1]
    return float(y0 + (y1 - y0) * (x - x0) / (x1 - x0))


def cell_ocv(chemistry: Chemistry, soc_percent: float) -> float:
    """Open-circuit voltage of one cell [V] at ``soc_percent`` [%] (clamped to 0-100)."""
    table = _LFP if chemistry is Chemistry.LFP else OCV_TABLES[chemistry]  # no Enum hash
    return interpolate(soc_percent, SOC_GRID, table)


def soc_from_ocv(chemistry: Chemistry, ocv_v: float) -> float:
    """Inverse of :func:`cell_ocv` [%] (the tables increase strictly, so this is unique)."""
    return interpolate(ocv_v, OCV_TABLES[chemistry], SOC_GRID)
