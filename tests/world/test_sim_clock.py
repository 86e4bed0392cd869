"""``lowerbase world --publish-clock`` without ROS: the /clock time of each truth sample (its
``t``, never backwards, a restarted emulator continued with an offset) and ClockedTruth, which
publishes one time per sample from its own thread while the world reads the same stream."""

from __future__ import annotations

import itertools
import threading
import time

import pytest

from lowerbase.world.sim_clock import ClockedTruth, TruthTime
from lowerbase.world.truth_stream import TruthReceiver, TruthSample, TruthSender


def _s(t: float, seq: int = 0, boot: int = 1) -> TruthSample:
    return TruthSample(t, 0.0, 0.0, 0.0, 0.0, 0.0, seq=seq, boot=boot)


def test_the_clock_is_the_truths_time() -> None:
    tt = TruthTime()
    ts = [0.02 * k + 0.013 for k in range(50)]
    assert [tt.clock(_s(t)) for t in ts] == ts
    assert tt.stats["restarts"] == 0


def test_a_restarted_emulator_continues_the_clock_instead_of_going_back() -> None:
    tt = TruthTime()
    first = [tt.clock(_s(t)) for t in (10.0, 10.02, 10.04)]
    again = [tt.clock(_s(t)) for t in (0.01, 0.03, 1.01)]  # a new emulator: t from ~0
    assert first == [10.0, 10.02, 10.04]
    assert again == pytest.approx([10.04, 10.06, 11.04])
    assert tt.stats["restarts"] == 1
    clocks = first + again
    assert all(b >= a for a, b in itertools.pairwise(clocks))


def _wait(condition: object, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:  # type: ignore[operator]
        time.sleep(0.01)


def test_clocked_truth_publishes_every_sample_in_order_from_its_own_thread() -> None:
    with TruthReceiver("127.0.0.1", 0) as rx:
        clocked = ClockedTruth(rx)
        got: list[tuple[float, str]] = []
        clocked.start(lambda t: got.append((t, threading.current_thread().name)))
        sender = TruthSender("127.0.0.1", rx.address[1])
        ts = [5.0 + 0.02 * k for k in range(100)]
        for k, t in enumerate(ts):
            sender.send(_s(t, seq=k))
            if k % 10 == 0:  # the world's loop reads the same stream meanwhile
                clocked.sample()
        _wait(lambda: len(got) == len(ts))
        clocked.close()
        sender.close()
        assert [t for t, _ in got] == ts
        # every sample was published, whoever drained it; the latest is what the world sees
        assert clocked.published == len(ts)
        assert clocked.sample() == _s(ts[-1], seq=len(ts) - 1)
        assert {name for _, name in got} <= {"world-clock", threading.current_thread().name}
        assert rx.on_sample is None  # close() unhooked it


def test_malformed_datagrams_do_not_reach_the_clock() -> None:
    import socket

    with TruthReceiver("127.0.0.1", 0) as rx:
        clocked = ClockedTruth(rx)
        got: list[float] = []
        clocked.start(got.append)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"garbage", rx.address)
        sender = TruthSender("127.0.0.1", rx.address[1])
        sender.send(_s(1.5, seq=0))
        _wait(lambda: got == [1.5])
        clocked.close()
        sender.close()
        assert got == [1.5] and rx.stats["bad_size"] == 1


def test_an_emulator_restarted_with_the_same_boot_number_keeps_the_clock_going() -> None:
    """A second `lowerbase emulate` without --params is boot #1 again, its seq and t from 0:
    the receiver takes it (a late datagram of the first run is still stale), and /clock goes
    on from where the first run left it."""
    with TruthReceiver("127.0.0.1", 0) as rx:
        clocked = ClockedTruth(rx)
        got: list[float] = []
        clocked.start(got.append)
        sender = TruthSender("127.0.0.1", rx.address[1])
        for k in range(300):
            sender.send(_s(0.02 * k, seq=k))
            if k % 50 == 49:  # in batches a socket buffer holds
                _wait(lambda k=k: len(got) == k + 1)
        sender.send(_s(0.02 * 250, seq=250))  # late: stale
        _wait(lambda: rx.stats["stale"] == 1)
        for k in range(50):  # the new emulator
            sender.send(_s(0.02 * k, seq=k))
        _wait(lambda: len(got) == 350)
        clocked.close()
        sender.close()
        assert rx.stats["stale"] == 1 and clocked.time.stats["restarts"] == 1
        assert got[:300] == [0.02 * k for k in range(300)]
        assert got[300:] == pytest.approx([0.02 * 299 + 0.02 * k for k in range(50)])
        assert all(b >= a for a, b in itertools.pairwise(got))
