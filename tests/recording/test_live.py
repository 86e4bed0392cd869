"""The live view (--foxglove): a WebSocket client subscribes and decodes what it receives.

The client (tests/recording/foxglove_client.py) speaks the public protocol with the
``websockets`` package; ROS1 payloads are decoded with rosbags' own ROS1 store, decoded-signal
JSON compared with the codec's values for the same frame; poses with the driver's state and
the emulator's truth at the same stamp. All on the simulated clock: the client waits for the
server's messages, never for a time.
"""

from __future__ import annotations

import json
import math
import socket
import struct
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from lowerbase.cli import main
from lowerbase.clock import SimClock
from lowerbase.errors import ConfigError
from lowerbase.firmware_model.mcu import Mcu
from lowerbase.firmware_model.profile import load_profile
from lowerbase.firmware_model.runner import run as run_mcu
from lowerbase.protocol.codec import default_codec
from lowerbase.recording.live import EmulatorFeed, FoxgloveSink, parse_address, start_live
from lowerbase.recording.mcap_writer import McapRecorder
from lowerbase.recording.messages import to_ns
from lowerbase.simloop.loop import SimLoop
from tests.recording.foxglove_client import LEGACY_SUBPROTOCOL, SUBPROTOCOL, FoxgloveClient

ROS1 = get_typestore(Stores.ROS1_NOETIC)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _wait(condition: Any, what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"never happened: {what}"
        time.sleep(0.005)


@pytest.fixture
def live() -> Iterator[FoxgloveSink]:
    sink = FoxgloveSink("127.0.0.1", 0)
    yield sink
    sink.close()


def test_live_channels_match_mcap_odom_and_signals_decode(tmp_path: Path,
                                                          live: FoxgloveSink) -> None:
    path = tmp_path / "run.mcap"
    rec = McapRecorder(path, extra=(live,))
    frames: dict[tuple[int, int], bytes] = {}

    def tap(t: float, direction: str, frame_id: int, data: bytes) -> None:
        frames[(to_ns(t), frame_id)] = data
        rec(t, direction, frame_id, data)

    loop = SimLoop(tap=tap)
    tr = loop.mcu.truth
    rec.attach(loop.driver, loop.clock.now, lambda: (tr.x, tr.y, tr.yaw, tr.v, tr.w))
    poses: dict[int, tuple[tuple[float, ...], tuple[float, ...]]] = {}

    def after(what: str, core: Any) -> None:
        if what == "odometry":
            poses[to_ns(loop.now)] = (tuple(core.ekf.pose), (tr.x, tr.y, tr.yaw))

    loop.driver.listeners.append(after)
    loop.run(1.5)  # every periodic message and a BMS burst: their channels exist now

    client = FoxgloveClient(live.url)
    try:
        wanted = ("/odom", "/ground_truth/odom", "/can/decoded/MotionState", "/status_code")
        client.pump_until(lambda: all(t in client.channels for t in wanted))
        client.subscribe(*wanted)
        _wait(lambda: all(live.subscribed(t) for t in wanted), "the subscriptions")
        before = dict(rec.counts)
        loop.drive(0.6, 0.4, 2.0)
        sent = {t: rec.counts[t] - before.get(t, 0) for t in wanted}
        assert all(n > 0 for n in sent.values())
        client.pump_until(lambda: all(len(client.messages.get(t, [])) == n
                                      for t, n in sent.items()))
        rec.close()
        client.pump_until(lambda: True)
    finally:
        client.close()
        rec.close()

    # /odom: ROS1 bytes -> the driver's EKF pose at that stamp; the truth likewise
    moved = 0.0
    for topic, index in (("/odom", 0), ("/ground_truth/odom", 1)):
        for ns, payload in client.messages[topic]:
            msg = ROS1.deserialize_ros1(payload, "nav_msgs/msg/Odometry")
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == ns
            x, y, yaw = poses[ns][index]
            p = msg.pose.pose.position
            assert (p.x, p.y) == pytest.approx((x, y), abs=1e-12)
            assert _yaw(msg.pose.pose.orientation) == pytest.approx(yaw, abs=1e-9)
            moved = max(moved, math.hypot(x, y))
    assert moved > 0.5  # the drive moved the robot: the poses compared are not all zero
    # a decoded-signal channel carries the codec's values of the frame sent at that time
    codec = default_codec()
    motion_id = codec.message("MotionState").frame_id
    for ns, payload in client.messages["/can/decoded/MotionState"]:
        _, expected = codec.decode(motion_id, frames[(ns, motion_id)], strict=False)
        assert json.loads(payload) == pytest.approx(expected)
    linear = [json.loads(p)["Linear"] for _, p in client.messages["/can/decoded/MotionState"]]
    assert max(linear) == pytest.approx(0.6, abs=0.05)
    status = [ROS1.deserialize_ros1(p, "std_msgs/msg/UInt64").data
              for _, p in client.messages["/status_code"]]
    assert status and all(isinstance(s, int) for s in status)

    # the advertised channels are the MCAP's: topics, encodings, schemas, md5sums
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    in_mcap = {}
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        in_mcap[ch.topic] = (ch.message_encoding, schema.name, schema.encoding,
                             schema.data.decode(), ch.metadata)
    advertised = {t: (c["encoding"], c["schemaName"], c["schemaEncoding"], c["schema"],
                      c.get("metadata", {})) for t, c in client.channels.items()}
    assert set(advertised) == set(in_mcap)
    assert advertised == in_mcap
    assert {"/odom", "/odom_raw", "/tf", "/imu/data_raw", "/status_code", "/battery",
            "/driver_base/bms", "/ground_truth/odom", "/can/frames"} <= set(advertised)


def test_nobody_subscribed_nothing_is_built(tmp_path: Path, live: FoxgloveSink) -> None:
    """Without a subscriber the live-only publisher serialises nothing (counts stay 0), and
    header seq still counts as a rospy publisher's does."""
    from lowerbase.recording.publisher import RunPublisher

    seqs = []
    for sinks in ([live], []):  # the same run twice: live only, then nothing but counting
        pub = RunPublisher(sinks) if sinks else McapRecorder(tmp_path / "same.mcap")
        loop = SimLoop(tap=pub)
        pub.attach(loop.driver, loop.clock.now)
        loop.drive(0.3, 0.1, 1.5)
        pub.close()
        seqs.append(dict(pub._seq))
        if sinks:
            assert sum(pub.counts.values()) == 0
        else:
            assert pub.counts["/odom"] > 40
    assert "/odom" in live.topics and "/can/decoded/WheelFeedback" in live.topics
    # every wheel sample is a published /odom, subscribed or not
    assert seqs[0]["/odom"] == seqs[1]["/odom"] > 40
    assert seqs[0] == seqs[1]


@pytest.mark.parametrize("offered", [(SUBPROTOCOL,), (LEGACY_SUBPROTOCOL,),
                                     (LEGACY_SUBPROTOCOL, SUBPROTOCOL)])
def test_emulator_feed_streams_truth_and_frames(live: FoxgloveSink,
                                                offered: tuple[str, ...]) -> None:
    """`lowerbase emulate --foxglove`: the truth at 50 Hz and every frame sent, decoded; to a
    client that offers the protocol's new name, the old one only (Foxglove and Lichtblick
    releases), or both."""
    clock = SimClock()
    bus = can.Bus(interface="virtual", channel="lowerbase-test-live", receive_own_messages=False)
    feed = EmulatorFeed([live], clock)
    sent: dict[tuple[int, int], list[bytes]] = {}  #: (ns, id) -> frames in order
    truths: dict[int, tuple[float, float, float]] = {}

    def send(frame_id: int, data: bytes) -> None:
        sent.setdefault((to_ns(clock.now() - mcu.boot_time), frame_id), []).append(data)
        feed.frame("tx", frame_id, data)

    mcu = Mcu(load_profile(None), clock, send)
    feed.bind(mcu)

    def step(m: Mcu) -> None:
        feed(m)
        tr = m.truth
        truths[to_ns(clock.now() - m.boot_time)] = (tr.x, tr.y, tr.yaw)

    run_mcu(mcu, bus, clock, duration=0.3, on_step=step)  # channels exist
    client: FoxgloveClient | None = None
    try:
        client = FoxgloveClient(live.url, offered)
        # the server agrees to what the client offered (the new name when it offers both)
        assert client.ws.subprotocol == (SUBPROTOCOL if SUBPROTOCOL in offered
                                         else LEGACY_SUBPROTOCOL)
        topics = ("/ground_truth/odom", "/can/decoded/WheelFeedback", "/can/frames")
        client.pump_until(lambda: all(t in client.channels for t in topics))
        client.subscribe(*topics)
        _wait(lambda: all(live.subscribed(t) for t in topics), "the subscriptions")
        before = dict(feed.publisher.counts)
        run_mcu(mcu, bus, clock, duration=1.0, on_step=step)
        n = {t: feed.publisher.counts[t] - before.get(t, 0) for t in topics}
        assert n["/ground_truth/odom"] == 50
        client.pump_until(lambda: all(len(client.messages.get(t, [])) == k
                                      for t, k in n.items()))
    finally:
        if client is not None:
            client.close()
        feed.close()
        bus.shutdown()
    for ns, payload in client.messages["/ground_truth/odom"]:
        msg = ROS1.deserialize_ros1(payload, "nav_msgs/msg/Odometry")
        assert (msg.pose.pose.position.x, msg.pose.pose.position.y,
                _yaw(msg.pose.pose.orientation)) == pytest.approx(truths[ns], abs=1e-9)
    codec = default_codec()
    wheel = codec.message("WheelFeedback").frame_id
    decoded = {key: [codec.decode(wheel, d, strict=False)[1] for d in frames]
               for key, frames in sent.items() if key[1] == wheel}
    for ns, payload in client.messages["/can/decoded/WheelFeedback"]:  # left, right in order
        assert json.loads(payload) == pytest.approx(decoded[(ns, wheel)].pop(0))
    for ns, payload in client.messages["/can/frames"]:  # can_msgs/Frame, unpacked by hand
        _seq, sec, nsec, n_frame = struct.unpack_from("<IIII", payload)
        assert sec * 10**9 + nsec == ns
        assert payload[16:16 + n_frame] == b"can0"
        frame_id, rtr, ext, err, dlc = struct.unpack_from("<IBBBB", payload, 16 + n_frame)
        data = payload[24 + n_frame:]
        assert len(data) == 8 and (rtr, ext, err) == (0, 0, 0)
        assert data[:dlc] in sent[(ns, frame_id)]


def _listening(port: int) -> list[str]:
    """Local addresses of the TCP sockets listening on ``port`` (/proc/net/tcp and tcp6)."""
    found = []
    for name in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(name).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, _, port_hex = local.partition(":")
            if state == "0A" and int(port_hex, 16) == port:
                found.append(addr)
    return found


def test_default_server_binds_loopback_only() -> None:
    sink = start_live(":0")  # the default host, a free port
    assert sink is not None
    try:
        assert (sink.host, parse_address("")) == ("127.0.0.1", ("127.0.0.1", 8765))
        assert _listening(sink.port) == ["0100007F"]  # 127.0.0.1, nothing else
    finally:
        sink.close()


@pytest.mark.parametrize("text", ["host:port", "1:99999", "::1", "[::1", "a b:1"])
def test_bad_address_is_a_config_error(text: str) -> None:
    with pytest.raises(ConfigError, match="--foxglove"):
        parse_address(text)


def _one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The command fails with one error line (after at most its usual start line)."""
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) <= 2 and "error:" not in " ".join(err[:-1]), err
    assert err[-1].startswith(f"lowerbase {argv[0]}: error: "), err
    return err[-1]


def test_cli_bad_value_and_busy_port_are_one_line(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    line = _one_line(["scenario", "run", "demo", "--out", str(out), "--foxglove", "x:y"], capsys)
    assert line.startswith("lowerbase scenario: error: --foxglove 'x:y': the port")
    assert not out.exists()  # refused before anything ran or was written
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        line = _one_line(["scenario", "run", "demo", "--out", str(out), "--foxglove",
                          f"127.0.0.1:{port}"], capsys)
        assert f"--foxglove 127.0.0.1:{port}: cannot listen" in line
        assert "in use" in line and not out.exists()
        line = _one_line(["emulate", "--simulated", "--duration", "1", "-i", "virtual",
                          "--foxglove", f":{port}"], capsys)
        assert "cannot listen" in line
    line = _one_line(["emulate", "--simulated", "--duration", "1", "-i", "virtual",
                      "--foxglove", "[::1"], capsys)
    assert "IPv6" in line


def test_the_gate_renames_only_the_subprotocol() -> None:
    """A request that offers only the old name is passed on with the new one (header names in
    any case, several headers); the answer names the old one back. Anything else passes."""
    from lowerbase.recording.wsgate import rewrite_request, rewrite_response

    head = (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nsec-websocket-protocol: x.v1, "
            b"foxglove.websocket.v1\r\nSec-WebSocket-Protocol: y.v1\r\nSec-WebSocket-Key: "
            b"k==\r\n\r\n")
    out, legacy = rewrite_request(head)
    assert legacy and out == (b"GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"
                              b"Host: 127.0.0.1\r\nSec-WebSocket-Key: k==\r\n\r\n")
    both = head.replace(b"y.v1", b"foxglove.sdk.v1")
    assert rewrite_request(both) == (both, False)
    neither = head.replace(b"foxglove.websocket.v1", b"z.v1")
    assert rewrite_request(neither) == (neither, False)
    answer = (b"HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Accept: a=\r\n"
              b"sec-websocket-protocol: foxglove.sdk.v1\r\n\r\n")
    assert rewrite_response(answer) == answer.replace(b": foxglove.sdk.v1",
                                                      b": foxglove.websocket.v1")


def test_closing_the_sink_ends_its_connections() -> None:
    """A connected client (through the gate) is disconnected when the run ends; a client that
    offers neither name is refused by the server, as before."""
    from websockets.exceptions import ConnectionClosed, InvalidStatus
    from websockets.sync.client import connect

    sink = FoxgloveSink("127.0.0.1", 0)
    try:
        with pytest.raises(InvalidStatus, match="400"):
            connect(sink.url, subprotocols=["other.v1"], open_timeout=10)  # type: ignore[list-item]
        client = FoxgloveClient(sink.url, (LEGACY_SUBPROTOCOL,))
        client.pump_until(lambda: bool(client.server_info))
    finally:
        sink.close()
    try:
        with pytest.raises(ConnectionClosed):
            while True:
                client.ws.recv(timeout=10)
    finally:
        client.close()
