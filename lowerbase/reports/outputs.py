"""Where a run's files go: its log (``run.log``) and its MCAP (``run.mcap`` by default)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def log_to_file(path: Path, *, echo: bool = False) -> Iterator[None]:
    """lowerbase's log records go to ``path`` (and to stderr only with ``echo``)."""
    logger = logging.getLogger("lowerbase")
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, mode="w", encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    saved = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG if echo else logging.INFO)
    logger.propagate = echo
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(saved[0])
        logger.propagate = saved[1]
        handler.close()


def mcap_path(out: Path, mcap: str | Path | bool | None) -> Path | None:
    """Where ``execute`` writes the MCAP: ``out/run.mcap`` (True), none (False/None) or the
    given path (ConfigError unless it ends in .mcap)."""
    from lowerbase.errors import ConfigError

    if mcap is True:
        return out / "run.mcap"
    if mcap is None or mcap is False:
        return None
    path = Path(mcap)
    if path.suffix.lower() != ".mcap":
        raise ConfigError(f"--mcap {path}: the file name must end in .mcap")
    return path
