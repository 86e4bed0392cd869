"""Let Foxglove WebSocket clients that offer only ``foxglove.websocket.v1`` in.

foxglove-sdk's server accepts the subprotocol ``foxglove.sdk.v1`` only (the same protocol
under its new name) and answers HTTP 400 to a client that offers only the old name, which
Foxglove and Lichtblick releases do. :class:`SubprotocolGate` listens where the user asked and
hands every connection to the SDK's server on a loopback port of its own. A client that
offers ``foxglove.sdk.v1`` passes unchanged; for one that offers only the old name the
handshake request is passed on naming the new one, and the server's answer names the old one
back (a client refuses a subprotocol it did not offer). ``Sec-WebSocket-Accept`` depends only
on the client's key, so it stays valid. After the handshake the bytes are copied unchanged
both ways (two threads a connection: a live view has a client or two).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading

log = logging.getLogger(__name__)

OLD, NEW = b"foxglove.websocket.v1", b"foxglove.sdk.v1"
_HEADER = b"sec-websocket-protocol"
_END = b"\r\n\r\n"
MAX_HEAD = 64 * 1024  #: [bytes] a longer handshake is not one: the connection is closed
HANDSHAKE_TIMEOUT = 10.0  #: [s] for a client to send its handshake request
_CHUNK = 1 << 16


def _protocol_values(lines: list[bytes]) -> list[bytes]:
    out = []
    for line in lines[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == _HEADER:
            out += [v.strip() for v in value.split(b",")]
    return out


def rewrite_request(head: bytes) -> tuple[bytes, bool]:
    """The handshake request ``head`` (ending in a blank line) to pass on, and whether the
    client offered the old name only (then the request names the new one instead)."""
    lines = head[: -len(_END)].split(b"\r\n")
    offered = _protocol_values(lines)
    if NEW in offered or OLD not in offered:
        return head, False
    kept = [line for line in lines[1:]
            if line.partition(b":")[0].strip().lower() != _HEADER]
    return b"\r\n".join([lines[0], b"Sec-WebSocket-Protocol: " + NEW, *kept]) + _END, True


def rewrite_response(head: bytes) -> bytes:
    """The server's answer ``head`` with the subprotocol it agreed to named by its old name."""
    lines = head[: -len(_END)].split(b"\r\n")
    for i, line in enumerate(lines[1:], 1):
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == _HEADER and value.strip() == NEW:
            lines[i] = name + b": " + OLD
    return b"\r\n".join(lines) + _END


def _read_head(sock: socket.socket) -> tuple[bytes, bytes] | None:
    """(the HTTP head up to its blank line, the bytes after it); None: closed or too long."""
    buf = b""
    while _END not in buf:
        if len(buf) > MAX_HEAD:
            return None
        data = sock.recv(_CHUNK)
        if not data:
            return None
        buf += data
    end = buf.index(_END) + len(_END)
    return buf[:end], buf[end:]


def _pump(src: socket.socket, dst: socket.socket) -> None:
    with contextlib.suppress(OSError):
        while data := src.recv(_CHUNK):
            dst.sendall(data)
    with contextlib.suppress(OSError):
        dst.shutdown(socket.SHUT_WR)


class SubprotocolGate:
    """Listens on ``host:port`` (0: a free port, then :attr:`port`) and passes every
    connection to ``127.0.0.1:backend_port``. Raises ``OSError`` when it cannot listen."""

    def __init__(self, host: str, port: int, backend_port: int) -> None:
        self.backend = ("127.0.0.1", backend_port)
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
        self._listener = socket.socket(family, kind, proto)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind(address)
            self._listener.listen(16)
        except OSError:
            self._listener.close()
            raise
        self.port = int(self._listener.getsockname()[1])
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._closed = False
        self._thread = threading.Thread(target=self._accept, name="foxglove-gate", daemon=True)
        self._thread.start()

    def _track(self, sock: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._open.add(sock)
            return True

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:  # closed
                return
            if not self._track(client):
                client.close()
                return
            threading.Thread(target=self._serve, args=(client,), name="foxglove-gate-conn",
                             daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        backend: socket.socket | None = None
        upstream: threading.Thread | None = None
        try:
            client.settimeout(HANDSHAKE_TIMEOUT)
            got = _read_head(client)
            if got is None:
                return
            client.settimeout(None)
            head, rest = got
            head, legacy = rewrite_request(head)
            backend = socket.create_connection(self.backend, timeout=HANDSHAKE_TIMEOUT)
            if not self._track(backend):
                return
            backend.sendall(head + rest)
            if legacy:
                answer = _read_head(backend)
                if answer is None:
                    return
                client.sendall(rewrite_response(answer[0]) + answer[1])
            backend.settimeout(None)
            upstream = threading.Thread(target=_pump, args=(client, backend),
                                        name="foxglove-gate-up", daemon=True)
            upstream.start()
            _pump(backend, client)
            upstream.join(HANDSHAKE_TIMEOUT)  # the client closes when the server has
        except OSError as error:
            log.debug("live view connection ended: %s", error)
        finally:
            for sock in (client, backend):
                if sock is not None:
                    self._drop(sock)

    def _drop(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.discard(sock)
        with contextlib.suppress(OSError):
            sock.shutdown(socket.SHUT_RDWR)  # wakes a thread blocked in recv on it
        sock.close()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            socks = list(self._open)
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)  # wakes accept()
        self._listener.close()
        for sock in socks:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
        self._thread.join(HANDSHAKE_TIMEOUT)
