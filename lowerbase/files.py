"""Reading the user's TOML files, checking the folders and files a user names for output
(``--out``, ``--log-dir``, ``--mcap``, ``--record``) before any work starts, and writing files
that must survive a crash mid-write."""

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


def _check_writable(folder: Path, named: str, what: str, keep: bool) -> None:
    """Make ``folder`` (with its parents) and write a scratch file in it, or one line; unless
    ``keep``, the folders made here are removed again (the writer makes them)."""
    made = []  #: the folders missing, deepest first
    missing = folder
    while not missing.exists() and missing != missing.parent:
        made.append(missing)
        missing = missing.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as e:
        if isinstance(e, (FileExistsError, NotADirectoryError)):
            why = "a file is in the way of its folder"
        else:
            why = e.strerror or str(e)
        raise ConfigError(f"{named}: {why}; give {what}") from None
    finally:
        if not keep:
            for d in made:
                with contextlib.suppress(OSError):
                    d.rmdir()


def output_dir(path: str | Path, flag: str | None = None, *, make: bool = False) -> Path:
    """A folder the user named for output (``--out DIR``, ``--log-dir DIR``; ``flag`` names it
    in the error, None for a default folder): checked writable (by making it and writing a
    scratch file there), or a one-line :class:`ConfigError` before anything runs. Unless
    ``make``, nothing is left behind: a run that stops before it writes leaves no empty
    folder."""
    folder = Path(path)
    named = f"{flag} {path}" if flag else str(path)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{named}: a file, not a folder; give a folder (it is made if "
                          "missing)")
    _check_writable(folder, named, "a folder you can write to (it is made if missing)", make)
    return folder


def output_file(path: str | Path, flag: str | None = None) -> Path:
    """A file the user named for output (``--mcap FILE``, ``--record FILE``; ``flag`` names it
    in the error, None for a positional argument): not a folder, and its folder made if
    missing and checked writable, or a one-line :class:`ConfigError` before anything runs.
    The file itself is left to its writer."""
    file = Path(path)
    named = f"{flag} {path}" if flag else str(path)
    if file.is_dir():
        raise ConfigError(f"{named}: a folder, not a file; give a file name")
    _check_writable(file.parent, named,
                    "a file in a folder you can write to (the folder is made if missing)", True)
    return file


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
