"""lowerbase.errors.count_drop: every dropped input counted, a flood logged a few times."""

from __future__ import annotations

import logging
from collections import Counter

import pytest

from lowerbase.errors import count_drop, worth_logging


def test_a_flood_is_counted_whole_and_logged_at_1_10_100_and_every_1000(
        caplog: pytest.LogCaptureFixture) -> None:
    stats: Counter[str] = Counter()
    log = logging.getLogger("lowerbase.test_drops")
    with caplog.at_level(logging.WARNING, logger=log.name):
        counts = [count_drop(stats, "bad_odom", log, "/odom: NaN in x") for _ in range(2500)]
    assert counts == list(range(1, 2501)) and stats == {"bad_odom": 2500}
    assert [r.getMessage() for r in caplog.records] == [
        f"/odom: NaN in x (dropped; {n} so far)" for n in (1, 10, 100, 1000, 2000)]
    assert [n for n in range(1, 3001) if worth_logging(n)] == [1, 10, 100, 1000, 2000, 3000]
