"""The emulator's ground truth across processes: versioned UDP datagrams on loopback.

``lowerbase emulate --truth-udp [HOST:]PORT`` runs in a process of its own; the world
(``lowerbase world``) needs the robot's true pose to cast its sensors. :class:`TruthSender` is
an ``on_step`` hook of the MCU runner that sends one datagram every ``period`` (20 ms: 50 Hz)
of the emulator's clock; :class:`TruthReceiver` binds a UDP socket (loopback by default),
checks every datagram and keeps the newest sample. Nothing here imports ROS.

Datagram (little-endian, 62 bytes, :data:`FORMAT`)::

    magic  4s  b"LBTR"
    version B  1 (a receiver drops other versions, counted)
    flags   B  bit 0: the footprint is in contact with a wall or an obstacle
    seq     I  sample number, +1 per datagram (a receiver drops older ones: reordering)
    t       d  [s] emulator time since its first boot
    x, y    d  [m] true position (the emulator's start pose is the origin)
    yaw     d  [rad] true heading, unwrapped (may exceed pi)
    v, w    d  [m/s], [rad/s] true twist
    boot    I  the emulator's boot counter (a restart shows as a new boot)

A datagram of the wrong size, magic or version, or with a non-finite number, is dropped and
counted in :attr:`TruthReceiver.stats` (logged once per kind), never raised.
"""

from __future__ import annotations

import logging
import math
import select
import socket
import struct
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.simloop.truth import TruthHook

log = logging.getLogger(__name__)

MAGIC = b"LBTR"
VERSION = 1
FORMAT = struct.Struct("<4sBBIddddddI")
#: the documented default: ``--truth-udp`` without a value sends to / listens on this
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 43213
DEFAULT_PERIOD = 0.02  # [s]: 50 Hz
FLAG_CONTACT = 0x01
#: a sequence number this far behind the latest, with an earlier t, is a new emulator process
#: whose boot counter started over (no --params), not a late datagram: accepted
RESTART_GAP = 100


@dataclass(frozen=True)
class TruthSample:
    """One ground-truth sample: time [s], pose [m, m, rad], twist [m/s, rad/s], contact."""

    t: float
    x: float
    y: float
    yaw: float
    v: float
    w: float
    contact: bool = False
    seq: int = 0
    boot: int = 0

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.x, self.y, self.yaw


def encode(sample: TruthSample) -> bytes:
    """The datagram of ``sample``."""
    return FORMAT.pack(MAGIC, VERSION, FLAG_CONTACT if sample.contact else 0,
                       sample.seq & 0xFFFFFFFF, sample.t, sample.x, sample.y, sample.yaw,
                       sample.v, sample.w, sample.boot & 0xFFFFFFFF)


class MalformedTruth(ValueError):
    """A datagram that is not a truth sample; ``kind`` is the stats key it is counted under."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(detail)
        self.kind = kind


def decode(data: bytes) -> TruthSample:
    """The sample in ``data``; :class:`MalformedTruth` if it is not a valid datagram."""
    if len(data) != FORMAT.size:
        raise MalformedTruth("bad_size", f"{len(data)} bytes, expected {FORMAT.size}")
    magic, version, flags, seq, t, x, y, yaw, v, w, boot = FORMAT.unpack(data)
    if magic != MAGIC:
        raise MalformedTruth("bad_magic", f"magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise MalformedTruth("bad_version", f"version {version}, this reader takes {VERSION}")
    if not all(math.isfinite(value) for value in (t, x, y, yaw, v, w)):
        raise MalformedTruth("not_finite", f"non-finite value in {(t, x, y, yaw, v, w)}")
    return TruthSample(t, x, y, yaw, v, w, bool(flags & FLAG_CONTACT), seq, boot)


def parse_address(text: str | None) -> tuple[str, int]:
    """``[HOST:]PORT`` (or None / "" for the default) -> (host, port); ConfigError if bad."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]") or DEFAULT_HOST
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 1 <= port <= 65535:
        raise ConfigError(f"--truth-udp {text!r}: expected [HOST:]PORT with a port 1..65535, "
                          f"e.g. {DEFAULT_HOST}:{DEFAULT_PORT}")
    return host, port


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET


class TruthSender(TruthHook):
    """MCU runner ``on_step`` hook: the ground truth as one datagram every ``period`` [s].

    ``contact(mcu)`` says whether the footprint touches something (default: the truth's
    ``blocked``, set when installed Surroundings refused the last move). Send errors
    (nobody listening gives ECONNREFUSED on some systems) are counted in ``errors``.
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 period: float = DEFAULT_PERIOD,
                 contact: Callable[[Any], bool] | None = None) -> None:
        super().__init__(period)
        self.address = (host, port)
        self.contact = contact
        self.sent = 0
        self.errors = 0
        self._sock = socket.socket(_family(host), socket.SOCK_DGRAM)

    def emit(self, mcu: Any, t: float) -> None:
        tr = mcu.truth
        touching = bool(self.contact(mcu) if self.contact is not None
                        else getattr(tr, "blocked", False))
        sample = TruthSample(t, tr.x, tr.y, tr.yaw, tr.v, tr.w, touching,
                             self.sent, int(getattr(mcu, "boot_counter", 0)))
        self.send(sample)

    def send(self, sample: TruthSample) -> None:
        try:
            self._sock.sendto(encode(sample), self.address)
        except OSError as exc:
            self.errors += 1
            if self.errors == 1:
                log.warning("truth stream to %s:%d: %s (counted from now on)", *self.address,
                            exc)
            return
        self.sent += 1

    def close(self) -> None:
        self._sock.close()


class TruthReceiver:
    """Listens for truth datagrams on ``host:port`` (loopback by default).

    :meth:`drain` takes whatever has arrived without blocking, :meth:`wait` blocks until a
    sample arrives or the timeout passes; :attr:`latest` is the newest valid sample and
    :attr:`received_at` the ``time.monotonic()`` it came. ``stats`` counts ``received``
    (valid), each malformed kind (``bad_size``, ``bad_magic``, ``bad_version``,
    ``not_finite``) and ``stale`` (a sequence number not newer than the latest of its boot, unless
it is :data:`RESTART_GAP` behind with an earlier ``t``: an emulator restarted from boot 1).
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 on_sample: Callable[[TruthSample], None] | None = None) -> None:
        self.on_sample = on_sample  #: called with every valid new sample, in order
        self._sock = socket.socket(_family(host), socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise ConfigError(f"cannot listen for the ground truth on {host}:{port}: "
                              f"{exc.strerror or exc} (another lowerbase world running? "
                              f"choose another port with --truth-udp)") from None
        self._sock.setblocking(False)
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        self.latest: TruthSample | None = None
        self.received_at = -math.inf
        self.stats: Counter[str] = Counter()

    def fileno(self) -> int:
        return self._sock.fileno()

    def sample(self) -> TruthSample | None:
        """:class:`lowerbase.world.truth.TruthSource`: the newest sample after reading what
        has arrived (None before the first)."""
        self.drain()
        return self.latest

    def pose(self) -> tuple[float, float, float] | None:
        """The newest true pose (x, y, yaw), or None before the first sample."""
        return self.latest.pose if self.latest is not None else None

    def age(self) -> float:
        """Seconds (monotonic) since the newest sample arrived (inf before the first)."""
        return time.monotonic() - self.received_at

    def drain(self) -> int:
        """Read every datagram waiting; the number of valid new samples."""
        got = 0
        while True:
            try:
                data = self._sock.recv(2048)
            except (BlockingIOError, InterruptedError):
                return got
            except OSError as exc:  # e.g. ICMP errors reported on the socket: not fatal
                self.stats["socket_errors"] += 1
                log.debug("truth socket: %s", exc)
                return got
            got += self._accept(data)

    def wait(self, timeout: float) -> bool:
        """Block up to ``timeout`` [s] for a new valid sample; True if one came."""
        deadline = time.monotonic() + timeout
        while True:
            if self.drain():
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            select.select([self._sock], [], [], remaining)

    def _accept(self, data: bytes) -> int:
        try:
            sample = decode(data)
        except MalformedTruth as exc:
            self.stats[exc.kind] += 1
            if self.stats[exc.kind] == 1:
                log.warning("truth stream: malformed datagram dropped (%s); further ones are "
                            "counted", exc)
            return 0
        last = self.latest
        if last is not None and sample.boot == last.boot and sample.seq <= last.seq and (
                last.seq - sample.seq < RESTART_GAP or sample.t >= last.t):
            self.stats["stale"] += 1
            return 0
        self.latest = sample
        self.received_at = time.monotonic()
        self.stats["received"] += 1
        if self.on_sample is not None:
            self.on_sample(sample)
        return 1

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> TruthReceiver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
