"""Reading the user's TOML files and writing files that must survive a crash mid-write."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found,unused-ignore]


def read_toml(path: str | Path, what: str = "file") -> dict[str, Any]:
    """The TOML document at ``path``; one-line :class:`ConfigError` when unreadable."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(f"{p}: cannot read {what}: {e.strerror or e}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"{p}: invalid TOML: {e}") from None


def write_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` so that readers, and a crash mid-write, only ever see a whole file.

    A temporary file in the same folder is written and fsynced, then renamed over ``path``
    (atomic on POSIX), then the folder is fsynced so the rename itself is durable.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    with contextlib.suppress(OSError):
        dir_fd = os.open(p.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def remove_stale_temps(path: str | Path) -> list[Path]:
    """Remove what a crash in :func:`write_atomic` left beside ``path`` (its temporary files,
    ``.<name>.*.tmp``); call at start, before any write. Returns the files removed."""
    p = Path(path)
    removed = []
    with contextlib.suppress(OSError):
        for tmp in p.parent.glob(f".{p.name}.*.tmp"):
            with contextlib.suppress(OSError):
                tmp.unlink()
                removed.append(tmp)
    return removed
