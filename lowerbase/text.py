"""Short forms of user input for refusal reasons and log lines.

A refusal quotes what it refuses, but never at the size it arrived: :func:`clip` shortens a
string (a 1 MB mark_no is quoted by its first characters and its length), :func:`num` writes a
coordinate compactly (``1e+300``, not 301 digits).
"""

from __future__ import annotations

import math

#: characters of a string a message quotes before it is cut
CLIP = 64
#: numbers at least this large (or non-finite) are written in %g form
LARGE = 1e6


def clip(text: str, limit: int = CLIP) -> str:
    """``text`` quoted (repr), or its first ``limit`` characters and its length when longer:
    ``'abc...' (1048576 chars)``."""
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}... ({len(text)} chars)"


def num(value: float, decimals: int = 2) -> str:
    """A number for a message: ``decimals`` places while it is moderate, else ``%g``
    (``1e+308``, ``inf``, ``nan``)."""
    v = float(value)
    if not math.isfinite(v) or abs(v) >= LARGE:
        return f"{v:g}"
    return f"{v:.{decimals}f}"


def point(*values: float, decimals: int = 2) -> str:
    """``(x, y, ...)`` with :func:`num`."""
    return "(" + ", ".join(num(v, decimals) for v in values) + ")"
