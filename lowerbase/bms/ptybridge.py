"""Two pseudo-terminals joined back to back: a null-modem cable in software.

Each end is the slave side of its own pty, so each end is a path (``/dev/pts/N``) that any
program opens like a serial port; a thread copies bytes between the two masters. This is what
``socat pty,raw pty,raw`` does. One end serves the emulated BMS, the other is published (for
instance at a stable symlink) for the firmware under test.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty
from pathlib import Path

from lowerbase.errors import TransportError


class PtyBridge:
    """A pair of linked pseudo-terminals; ``a_path`` and ``b_path`` are the two ends."""

    def __init__(self, link: str | Path | None = None) -> None:
        """Create the pair; when ``link`` is given, make it a symlink to ``b_path``."""
        self._fds: list[int] = []
        try:
            self._a_master, a_slave = os.openpty()
            self._b_master, b_slave = os.openpty()
        except OSError as exc:
            self.close()
            raise TransportError(f"cannot create a pseudo-terminal: {exc.strerror}") from None
        self._fds = [self._a_master, a_slave, self._b_master, b_slave]
        # raw mode: no echo, no line editing, no CR/LF translation on either end. The slave
        # fds stay open so the masters never see EIO while no program has an end open.
        for fd in (a_slave, b_slave):
            tty.setraw(fd)
        self.a_path = os.ttyname(a_slave)
        self.b_path = os.ttyname(b_slave)
        self.link: Path | None = None
        if link is not None:
            self._make_link(Path(link))
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._relay, name="pty-bridge", daemon=True)
        self._thread.start()

    def _make_link(self, link: Path) -> None:
        if link.is_symlink():
            target = os.readlink(link)
            if not target.startswith("/dev/pts/"):
                self.close()
                raise TransportError(f"{link} exists and is not a pseudo-terminal link")
            link.unlink()  # a stale link of an earlier run
        elif link.exists():
            self.close()
            raise TransportError(f"{link} exists and is not a symlink; choose another path")
        try:
            link.symlink_to(self.b_path)
        except OSError as exc:
            self.close()
            raise TransportError(f"cannot create {link}: {exc.strerror}") from None
        self.link = link

    def _relay(self) -> None:
        peer = {self._a_master: self._b_master, self._b_master: self._a_master}
        while True:
            try:
                ready, _, _ = select.select([self._a_master, self._b_master, self._stop_r], [], [])
            except (OSError, ValueError):
                return
            if self._stop_r in ready:
                return
            for fd in ready:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    continue
                view = memoryview(data)
                while view:
                    try:
                        n = os.write(peer[fd], view)
                    except OSError:
                        break
                    view = view[n:]

    def close(self) -> None:
        """Stop the relay, close both ptys and remove the symlink. Idempotent."""
        thread = getattr(self, "_thread", None)
        if thread is not None and thread.is_alive():
            os.write(self._stop_w, b"x")
            thread.join(2.0)
        for fd in [*self._fds, getattr(self, "_stop_r", -1), getattr(self, "_stop_w", -1)]:
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._fds = []
        self._stop_r = self._stop_w = -1
        link = getattr(self, "link", None)
        if link is not None:
            with contextlib.suppress(OSError):
                if link.is_symlink():
                    link.unlink()
            self.link = None

    def __enter__(self) -> PtyBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
