"""``lowerbase conformance`` run in process, its report read back (the conformance tests')."""

from __future__ import annotations

from collections.abc import Collection

import pytest

from lowerbase.cli import main


def run_conformance(capsys: pytest.CaptureFixture[str], ids: Collection[str], *argv: str
                    ) -> tuple[int, dict[str, str], str]:
    """``lowerbase conformance *argv``: (exit code, check id -> its result word, stdout);
    a result is a report line that starts with one of ``ids``."""
    code = main(["conformance", *argv])
    out = capsys.readouterr().out
    results = {}
    for line in out.splitlines():
        parts = line.split(maxsplit=2)
        if len(parts) >= 2 and parts[0] in ids:
            results[parts[0]] = parts[1]
    return code, results, out
